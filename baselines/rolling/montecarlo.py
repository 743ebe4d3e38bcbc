"""The Monte Carlo of a platform self-calibration scenario (``experiment = "platform-rolling"``, seed 002 (Ding,
rolling-platform self-calibration)).

A scenario's ``[platform]`` table describes a rolling scheme, the distribution of the true error
coefficients and initial attitude, and the sensor noise (:func:`baselines.rolling.spec.parse_platform`). For each
Monte Carlo run k the true coefficients and angles are drawn from that distribution with a generator
seeded by (seed, k) only, the platform is simulated (:func:`baselines.rolling.simulator.simulate`) and every
calibration method estimates the 42 coefficients and the attitude from the accelerometer outputs.
The methods follow :class:`baselines.rolling.protocol.Calibrator` (entry-point group ``fusionbench.calibrators``
or ``module:Class``); of their :class:`~baselines.rolling.protocol.CalibrationResult` the Monte Carlo reads
``t``, ``x``, ``sigma``, ``final(readout_s)`` and, where given, ``figures``, ``first_pass`` and ``bound()``.

metrics.json keeps the contract's shape (docs/contract.md): per method ``final_error_arcmin`` is the misalignment of the
estimated platform attitude against truth at the end (E, N, U, arcmin) and ``settling_time_s`` that of
its azimuth (for a method that reprocesses the data, e.g. the two-pass ``rolling-ekf``, the settling of
its causal first pass, ``result.first_pass``; ``first_pass`` then also reports that pass's final errors and
group maxima); ``limits_arcmin`` are 0 (the coefficients, biases included, are estimated, so the
stationary-alignment limits do not apply). Per method, ``coefficients`` holds per coefficient the
estimation error mean and standard deviation over runs and the mean predicted sigma, in the customary
unit named beside them (and ``bound``, the information bound of the run's outputs, when the method
gives one: ``result.bound()``), and ``groups`` the largest abs(mean error) of each group.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from joblib import Parallel, delayed

from fusionbench.files.progress import bar as progress_bar
from fusionbench.scoring import metrics
from fusionbench.simulation import units

from . import angles, model
from .simulator import simulate
from .spec import draw_truth

#: Coefficient groups: name, slice and the paper's accuracy claim (customary units; seeds README).
GROUPS = (("gyro bias", model.D0, 1e-3), ("gyro g-sensitive", model.D1, 0.01), ("gyro g^2", model.D2, 0.005),
          ("gyro axis angles", model.GYRO_MOUNT, None), ("accel bias", model.K0, 1.0),
          ("accel scale", model.K1, 1.0), ("accel quadratic", model.K2, None),
          ("accel axis angles", model.ACCEL_MOUNT, None), ("torquer scale", model.KT, 5.0))


def _one_run(scn, spec, method_names, k, seed):
    """Simulate run k and calibrate it with every method."""
    nc = model.N_COEFFS
    c, a = draw_truth(spec, seed, k)
    run = simulate(spec.scheme, c, angles.angles_to_dcm(a), scn.site.lat, scn.site.h, spec.gyro_noise,
                      spec.accel_noise, seed=int(np.random.SeedSequence([int(seed), int(k), 2]).generate_state(1)[0]))
    truth = run.states[0]
    out = {}
    for name in method_names:
        method = scn.method(name)
        t0 = time.perf_counter()
        res = method.calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat, scn.site.h)
        wall = time.perf_counter() - t0
        # a multi-pass method's first pass is its causal filter: its attitude history gives the settling time
        causal = getattr(res, "first_pass", None) or res
        phi, phi_causal = (metrics.misalignment_history(angles.angles_to_dcm(r.x[:, model.ANGLES])[None], run.C_pn[0])[0]
                           for r in (res, causal))  # (M, 3) rad, ENU
        settle = metrics.settling_time(run.t, phi_causal[None, :, 2] / units.ARCMIN, scn.settling_band_arcmin)[0]
        first = causal.final(spec.readout_s)[:nc] - truth[-1, :nc]
        est = np.asarray(res.final(spec.readout_s))
        bound = res.bound() if hasattr(res, "bound") else None
        # the histories go back as squares only, summed over runs by the caller (memory independent of runs)
        out[name] = {"err": est[:nc] - truth[-1, :nc], "sigma": res.sigma[-1, :nc],
                     "bound": None if bound is None else bound[:nc],
                     "phi2": phi ** 2, "phi2_causal": phi_causal ** 2, "phi_end": phi[-1], "phi_end_causal": phi_causal[-1],
                     "settle": settle, "err_causal": first, "has_first_pass": causal is not res,
                     "wall": wall, "figures": dict(getattr(res, "figures", {}) or {}),
                     "x": res.x if k == 0 else None, "sig_hist": res.sigma if k == 0 else None,
                     "x_causal": causal.x if k == 0 and causal is not res else None,
                     "sig_causal": causal.sigma if k == 0 and causal is not res else None,
                     "truth": truth[:, :nc] if k == 0 else None}
    return out


@dataclass
class CalibrationOutput:
    """A finished calibration scenario: ``metrics`` (the metrics.json mapping), the filter times ``t`` (M,)
    and per method in ``outcomes``: per run (leading axis) ``err``, ``sigma``, ``bound`` (coefficients, SI),
    ``phi_end`` (3, rad, ENU) and ``settle`` (s), the same ``_causal`` for the first pass; over runs the rms
    misalignment histories ``phi_rms`` and ``phi_rms_causal`` (M, 3) rad; run 0's estimate histories
    ``x``, ``sig_hist`` (and ``x_causal``, ``sig_causal``) and true coefficients ``truth`` for figures.
    Memory does not grow with the number of runs beyond a few hundred numbers per run."""

    scenario: object
    metrics: dict
    t: np.ndarray
    outcomes: dict


def run_calibration(scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None):
    """Monte Carlo of a platform-rolling scenario (see the module notes); returns a CalibrationOutput.
    ``progress``: a bar over runs (:func:`fusionbench.files.progress.bar`: None shows one on a terminal)."""
    methods = list(methods or scn.methods)
    for m in methods:
        scn.method(m)
    duration, default_runs = scn.sized(quick)
    runs = default_runs if runs is None else int(runs)
    if runs < 1:
        raise ValueError(f"runs: expected a positive number of Monte Carlo runs, found {runs}")
    spec = scn.platform.scaled(duration)
    if n_jobs == 1 or runs == 1:
        done = (_one_run(scn, spec, methods, k, seed) for k in range(runs))
    else:  # in run order whatever the worker that finished first
        done = Parallel(n_jobs=n_jobs, return_as="generator")(
            delayed(_one_run)(scn, spec, methods, k, seed) for k in range(runs))
    acc = {name: {} for name in methods}
    pbar = progress_bar(progress, runs, scn.name)
    for r in done:
        for name in methods:
            _accumulate(acc[name], r[name])
        pbar.update(1)
    pbar.close()
    total = sum(s.duration for s in spec.scheme.segments)
    t = np.arange(1, int(round(total / spec.scheme.filter_s)) + 1) * spec.scheme.filter_s  # the filter times
    outcomes = {}
    for name, a in acc.items():
        oc = {key: (None if v[0] is None else np.stack(v)) for key, v in a["per_run"].items()}
        oc.update({key: v for key, v in a.items() if key != "per_run"})
        oc["phi_rms"] = np.sqrt(oc.pop("phi2") / runs)
        oc["phi_rms_causal"] = np.sqrt(oc.pop("phi2_causal") / runs)
        outcomes[name] = oc
    return CalibrationOutput(scn, _metrics(scn, spec, outcomes, t, runs, seed, quick, total), t, outcomes)


_PER_RUN = ("err", "err_causal", "sigma", "bound", "phi_end", "phi_end_causal", "settle")
_RUN0 = ("has_first_pass", "figures", "x", "sig_hist", "x_causal", "sig_causal", "truth")


def _accumulate(a, r):
    """Fold one run's outcome ``r`` (from :func:`_one_run`) into the method's accumulator ``a``: per-run
    figures listed, squared attitude histories summed, wall times summed, run 0's histories kept."""
    if not a:
        a.update({key: r[key] for key in _RUN0})
        a.update(per_run={key: [] for key in _PER_RUN}, phi2=0.0, phi2_causal=0.0, wall=0.0)
    for key in _PER_RUN:
        a["per_run"][key].append(r[key])
    a["phi2"] = a["phi2"] + r["phi2"]
    a["phi2_causal"] = a["phi2_causal"] + r["phi2_causal"]
    a["wall"] += r["wall"]


def _metrics(scn, spec, outcomes, t, runs, seed, quick, duration):
    band = scn.settling_band_arcmin
    out = {"scenario": scn.name, "runs": runs, "seed": int(seed), "duration_s": float(duration), "quick": bool(quick),
           "limits_arcmin": {"E": 0.0, "N": 0.0, "U": 0.0}, "methods": {}}
    for name, oc in outcomes.items():
        phi_end = oc["phi_end"] / units.ARCMIN
        err = model.to_customary(oc["err"])
        sig = model.to_customary(oc["sigma"])
        coeffs = {n: {"unit": u, "error_mean": float(err[:, i].mean()), "error_std": float(err[:, i].std()),
                      "sigma_mean": float(sig[:, i].mean())}
                  for i, (n, u) in enumerate(zip(model.COEFF_NAMES, model.COEFF_CUSTOMARY_UNITS))}
        if oc.get("bound") is not None:  # the information bound of each coefficient (mean over runs)
            bnd = model.to_customary(oc["bound"]).mean(axis=0)
            for i, n in enumerate(model.COEFF_NAMES):
                coeffs[n]["bound"] = float(bnd[i])
        entry = {
            "final_error_arcmin": {ax: metrics.stats(phi_end[:, i]) for i, ax in enumerate("ENU")},
            "settling_time_s": {"U": metrics.stats(oc["settle"]), "band_arcmin": band},
            "wall_s": float(oc["wall"]),
            "coefficients": coeffs,
            "groups": {g: {"max_abs_error_mean": float(np.abs(err[:, sl].mean(axis=0)).max()),
                           "unit": model.COEFF_CUSTOMARY_UNITS[sl.start], "paper_below": claim}
                       for g, sl, claim in GROUPS},
        }
        if oc["has_first_pass"]:  # what the causal first pass alone reaches
            ec = model.to_customary(oc["err_causal"])
            entry["first_pass"] = {
                "final_error_arcmin": {ax: metrics.stats(oc["phi_end_causal"][:, i] / units.ARCMIN)
                                       for i, ax in enumerate("ENU")},
                "groups": {g: {"max_abs_error_mean": float(np.abs(ec[:, sl].mean(axis=0)).max())} for g, sl, _ in GROUPS}}
        if oc.get("bound") is not None:
            for g, sl, _ in GROUPS:
                entry["groups"][g]["bound_max"] = float(bnd[sl].max())
        entry.update(oc["figures"])
        out["methods"][name] = entry
        for key in ("information_rank",):
            if key in oc["figures"] and key not in out:
                out[key] = oc["figures"][key]
    return out
