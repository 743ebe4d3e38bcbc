"""Platform self-calibration experiments (scenario ``experiment = "platform-rolling"``, seed 002).

A scenario's ``[platform]`` table describes a rolling scheme, the distribution of the true error
coefficients and initial attitude, and the sensor noise (format in :func:`parse_platform`). For each
Monte Carlo run k the true coefficients and angles are drawn from that distribution with a generator
seeded by (seed, k) only, the platform is simulated (:func:`fusionbench.platform.simulate`) and every
calibration method estimates the 42 coefficients and the attitude from the accelerometer outputs.
Methods are found in the entry-point group ``fusionbench.calibrators`` (or as ``module:Class``): a
class with ``name``, ``description`` and ``calibrate(t, y, w_cmd, lat, h) -> result`` where the result
has ``t`` (M,), ``x`` (M, 45) estimates, ``sigma`` (M, 45) and ``final(readout_s)`` (45,), and
optionally ``figures`` (scalars it reports about itself, e.g. ``information_rank``) and
``report_figures(folder, scheme, lat)``.

metrics.json keeps the contract's shape (docs/contract.md): per method ``final_error_arcmin`` is the misalignment of the
estimated platform attitude against truth at the end (E, N, U, arcmin) and ``settling_time_s`` that of
its azimuth (for a method that reprocesses the data, e.g. the two-pass ``rolling-ekf``, the settling of
its causal first pass, ``result.first_pass``; ``first_pass`` then also reports that pass's final errors and
group maxima); ``limits_arcmin`` are 0 (the coefficients, biases included, are estimated, so the
stationary-alignment limits do not apply). Per method, ``coefficients`` holds per coefficient the
estimation error mean and standard deviation over runs and the mean predicted sigma, in the customary
unit named beside them (and ``bound``, the information bound of the run's outputs, when the method
gives one: ``result.bound()``), and ``groups`` the largest |mean error| of each group.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from importlib.metadata import entry_points

import numpy as np
from joblib import Parallel, delayed

from . import metrics, units
from .aligner import load_entry
from .progress import bar as progress_bar
from . import platform as pf

GROUP = "fusionbench.calibrators"
#: Coefficient groups: name, slice and the paper's accuracy claim (customary units; seeds README).
GROUPS = (("gyro bias", pf.D0, 1e-3), ("gyro g-sensitive", pf.D1, 0.01), ("gyro g^2", pf.D2, 0.005),
          ("gyro axis angles", pf.GYRO_MOUNT, None), ("accel bias", pf.K0, 1.0), ("accel scale", pf.K1, 1.0),
          ("accel quadratic", pf.K2, None), ("accel axis angles", pf.ACCEL_MOUNT, None), ("torquer scale", pf.KT, 5.0))
_GROUP_KEYS = {"D0": pf.D0, "D1": pf.D1, "D2": pf.D2, "GYRO_MOUNT": pf.GYRO_MOUNT, "K0": pf.K0, "K1": pf.K1,
               "K2": pf.K2, "ACCEL_MOUNT": pf.ACCEL_MOUNT, "KT": pf.KT}
_AXES = {"east": (1.0, 0.0, 0.0), "west": (-1.0, 0.0, 0.0), "north": (0.0, 1.0, 0.0), "south": (0.0, -1.0, 0.0),
         "up": (0.0, 0.0, 1.0), "down": (0.0, 0.0, -1.0)}
PLATFORM_KEYS = {"scheme", "initial_angles_deg", "initial_angles_sigma_deg", "coeff_mean", "coeff_sigma",
                 "gyro_noise_dph", "accel_noise_ug", "readout_s"}


@dataclass(frozen=True)
class PlatformSpec:
    """A validated ``[platform]`` table (SI inside).

    Attributes
    ----------
    scheme : fusionbench.platform.Scheme
    angles_mean, angles_sigma : ndarray, shape (3,)
        Initial attitude angles [phi, theta, psi] (rad) and their spread.
    coeff_mean, coeff_sigma : ndarray, shape (42,)
        True-coefficient distribution, SI.
    gyro_noise, accel_noise : float
        Gyro white drift per 2-ms sample (rad/s) and accelerometer noise per output (m/s^2).
    readout_s : float
        The estimate is averaged over the last ``readout_s`` seconds (the paper: 100 s).
    """

    scheme: pf.Scheme
    angles_mean: np.ndarray
    angles_sigma: np.ndarray
    coeff_mean: np.ndarray
    coeff_sigma: np.ndarray
    gyro_noise: float
    accel_noise: float
    readout_s: float = 100.0
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    def scaled(self, duration):
        """The same spec with the scheme's segments shortened in proportion to last ``duration`` s
        (whole command periods; for ``--quick``)."""
        full = sum(s.duration for s in self.scheme.segments)
        if duration >= full:
            return self
        per = self.scheme.command_period_s
        segs = tuple(pf.Segment(s.axis, s.rate, max(per, round(s.duration * duration / full / per) * per))
                     for s in self.scheme.segments)
        sch = pf.Scheme(segs, self.scheme.command_period_s, self.scheme.sample_s, self.scheme.filter_s)
        return PlatformSpec(sch, self.angles_mean, self.angles_sigma, self.coeff_mean, self.coeff_sigma,
                            self.gyro_noise, self.accel_noise, min(self.readout_s, duration / 10), self.raw)


def parse_platform(d, where):
    """Validate a ``[platform]`` table; ScenarioError-style ValueError naming ``where`` and the field.

    Format (customary units)::

        [platform]
        scheme = [{axis = "south", rate_dps = 0.1, duration_s = 1800.0}, ...]   # axis: a name or [E, N, U]
        initial_angles_deg = [2.0, 3.0, 5.0]          # [phi, theta, psi] of fusionbench.platform
        initial_angles_sigma_deg = [0.1, 0.1, 0.1]
        coeff_mean = {D0 = 1.0, GYRO_MOUNT = 120.0, K0 = 400.0, ...}   # per group (or a list per coefficient)
        coeff_sigma = {D0 = 0.2, ...}
        gyro_noise_dph = 0.05
        accel_noise_ug = 1.0
        readout_s = 100.0
    """
    def err(key, expected, found):
        return ValueError(f"{where}: field 'platform.{key}': expected {expected}, found {found!r}")

    bad = set(d) - PLATFORM_KEYS
    if bad:
        raise err(sorted(bad)[0], f"one of {sorted(PLATFORM_KEYS)}", sorted(bad)[0])
    segs = []
    for i, s in enumerate(d.get("scheme", [])):
        if not isinstance(s, dict) or set(s) != {"axis", "rate_dps", "duration_s"}:
            raise err(f"scheme[{i}]", "a table with axis, rate_dps and duration_s", s)
        axis = _AXES.get(s["axis"]) if isinstance(s["axis"], str) else s["axis"]
        if axis is None or not isinstance(axis, (list, tuple)) or len(axis) != 3:
            raise err(f"scheme[{i}].axis", f"one of {sorted(_AXES)} or [E, N, U]", s["axis"])
        segs.append(pf.Segment(tuple(float(a) for a in axis), np.radians(float(s["rate_dps"])), float(s["duration_s"])))
    if not segs:
        raise err("scheme", "at least one segment", d.get("scheme"))
    try:
        scheme = pf.Scheme(tuple(segs))
    except ValueError as exc:
        raise ValueError(f"{where}: field 'platform.scheme': {exc}") from None

    def vec3(key, default):
        v = d.get(key, default)
        if not isinstance(v, list) or len(v) != 3 or not all(isinstance(x, (int, float)) for x in v):
            raise err(key, "3 numbers", v)
        return np.radians(np.array(v, dtype=float))

    def coeffs(key):
        out = np.zeros(pf.N_COEFFS)
        table = d.get(key, {})
        if not isinstance(table, dict):
            raise err(key, "a table of group = value or [values]", table)
        for name, val in table.items():
            sl = _GROUP_KEYS.get(name)
            if sl is None:
                raise err(f"{key}.{name}", f"one of {sorted(_GROUP_KEYS)}", name)
            n = sl.stop - sl.start
            vals = np.broadcast_to(np.asarray(val, dtype=float), (n,)) if np.ndim(val) == 0 or len(val) == n else None
            if vals is None or not np.all(np.isfinite(vals)):
                raise err(f"{key}.{name}", f"a number or {n} numbers", val)
            out[sl] = vals
        return out * pf.COEFF_SCALE

    def num(key, default, lo=0.0):
        v = d.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < lo:
            raise err(key, f"a number >= {lo}", v)
        return float(v)

    sig = coeffs("coeff_sigma")
    if np.any(sig < 0):
        raise err("coeff_sigma", "non-negative values", d.get("coeff_sigma"))
    return PlatformSpec(scheme, vec3("initial_angles_deg", [0.0, 0.0, 0.0]), vec3("initial_angles_sigma_deg", [0.0] * 3),
                        coeffs("coeff_mean"), sig, num("gyro_noise_dph", 0.05) * units.DEG_PER_H,
                        num("accel_noise_ug", 1.0) * units.UG, num("readout_s", 100.0, lo=0.2), dict(d))


def available_calibrators():
    """Registered calibration methods: ``{name: entry point}`` of the ``fusionbench.calibrators`` group."""
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def load_calibrator(spec, **options):
    """A calibration method by registered name or ``module:Class`` path (ValueError naming it otherwise)."""
    obj = load_entry(GROUP, spec, "calibration method", **options)
    if not callable(getattr(obj, "calibrate", None)):
        raise ValueError(f"calibration method {spec!r}: expected an object with calibrate()")
    return obj


def draw_truth(spec: PlatformSpec, seed, k):
    """True coefficients (42, SI) and initial angles (3, rad) of run ``k``: depend on (seed, k) only."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(k), 2002]))
    c = spec.coeff_mean + spec.coeff_sigma * rng.standard_normal(pf.N_COEFFS)
    a = spec.angles_mean + spec.angles_sigma * rng.standard_normal(3)
    return c, a


def _one_run(scn, spec, method_names, k, seed):
    """Simulate run k and calibrate it with every method."""
    c, a = draw_truth(spec, seed, k)
    run = pf.simulate(spec.scheme, c, pf.angles_to_dcm(a), scn.site.lat, scn.site.h, spec.gyro_noise,
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
        phi, phi_causal = (metrics.misalignment_history(pf.angles_to_dcm(r.x[:, pf.ANGLES])[None], run.C_pn[0])[0]
                           for r in (res, causal))  # (M, 3) rad, ENU
        settle = metrics.settling_time(run.t, phi_causal[None, :, 2] / units.ARCMIN, scn.settling_band_arcmin)[0]
        first = causal.final(spec.readout_s)[:pf.N_COEFFS] - truth[-1, :pf.N_COEFFS]
        est = np.asarray(res.final(spec.readout_s))
        bound = res.bound() if hasattr(res, "bound") else None
        # the histories go back as squares only, summed over runs by the caller (memory independent of runs)
        out[name] = {"err": est[:pf.N_COEFFS] - truth[-1, :pf.N_COEFFS], "sigma": res.sigma[-1, :pf.N_COEFFS],
                     "bound": None if bound is None else bound[:pf.N_COEFFS],
                     "phi2": phi ** 2, "phi2_causal": phi_causal ** 2, "phi_end": phi[-1], "phi_end_causal": phi_causal[-1],
                     "settle": settle, "err_causal": first, "has_first_pass": causal is not res,
                     "wall": wall, "figures": dict(getattr(res, "figures", {}) or {}),
                     "x": res.x if k == 0 else None, "sig_hist": res.sigma if k == 0 else None,
                     "x_causal": causal.x if k == 0 and causal is not res else None,
                     "sig_causal": causal.sigma if k == 0 and causal is not res else None,
                     "truth": truth[:, :pf.N_COEFFS] if k == 0 else None}
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
    ``progress``: a bar over runs (:func:`fusionbench.progress.bar`: None shows one on a terminal)."""
    methods = list(methods or scn.methods)
    for m in methods:
        scn.method(m)
    duration, default_runs = scn.sized(quick)
    runs = default_runs if runs is None else int(runs)
    if runs < 1:
        raise ValueError(f"runs: expected a positive number of Monte Carlo runs, found {runs}")
    spec = scn.setup["platform"].scaled(duration)
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
        err = pf.to_customary(oc["err"])
        sig = pf.to_customary(oc["sigma"])
        coeffs = {n: {"unit": u, "error_mean": float(err[:, i].mean()), "error_std": float(err[:, i].std()),
                      "sigma_mean": float(sig[:, i].mean())}
                  for i, (n, u) in enumerate(zip(pf.COEFF_NAMES, pf.COEFF_CUSTOMARY_UNITS))}
        if oc.get("bound") is not None:  # the information bound of each coefficient (mean over runs)
            bnd = pf.to_customary(oc["bound"]).mean(axis=0)
            for i, n in enumerate(pf.COEFF_NAMES):
                coeffs[n]["bound"] = float(bnd[i])
        entry = {
            "final_error_arcmin": {ax: metrics.stats(phi_end[:, i]) for i, ax in enumerate("ENU")},
            "settling_time_s": {"U": metrics.stats(oc["settle"]), "band_arcmin": band},
            "wall_s": float(oc["wall"]),
            "coefficients": coeffs,
            "groups": {g: {"max_abs_error_mean": float(np.abs(err[:, sl].mean(axis=0)).max()),
                           "unit": pf.COEFF_CUSTOMARY_UNITS[sl.start], "paper_below": claim}
                       for g, sl, claim in GROUPS},
        }
        if oc["has_first_pass"]:  # what the causal first pass alone reaches
            ec = pf.to_customary(oc["err_causal"])
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


def _platform_table(d, src, duration):
    """The scenario's ``[platform]`` table (:func:`parse_platform`), its scheme as long as ``duration_s``."""
    spec = parse_platform(d, src)
    total = sum(sg.duration for sg in spec.scheme.segments)
    if abs(total - duration) > 1e-6:
        raise ValueError(f"{src}: field 'duration_s': expected the scheme's length {total:g} s, found {duration:g}")
    return spec


class PlatformRolling:
    """Seed 002's platform self-calibration (``experiment = "platform-rolling"``) as an
    :class:`fusionbench.experiment.Experiment`: a ``[platform]`` table, methods from ``fusionbench.calibrators``."""

    name = "platform-rolling"
    kind = "calibration"
    method_group = GROUP
    #: Its own top-level table of the scenario file and the parser of it (the scenario's ``setup["platform"]``).
    tables = {"platform": _platform_table}

    def load(self, data, src):
        from . import scenarios

        return scenarios.parse(data, src, tables=self.tables)

    def load_method(self, scn, spec, **options):
        return load_calibrator(spec, **options)

    def run(self, scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, refusals=False):
        return run_calibration(scn, methods, runs, seed, quick, n_jobs, progress)

    def write_report(self, out, folder):
        from .calibration_report import write_report

        return write_report(out, folder)

    def events(self, scn, duration_s):
        """The roll phases of the scheme (scaled to ``duration_s``) as unshaded spans."""
        return scheme_events(scn.setup["platform"].scaled(duration_s).scheme)

    def check(self, new, ref):
        """A coefficient group's largest |mean error| may not grow beyond 10 % of the reference (customary units)."""
        from .check import REL_TOL

        bad = []
        for name, r in ref.get("methods", {}).items():
            n = new.get("methods", {}).get(name, {})
            for g, rg in r.get("groups", {}).items():
                rv = rg["max_abs_error_mean"]
                nv = n.get("groups", {}).get(g, {}).get("max_abs_error_mean", float("nan"))
                if not nv <= rv * (1 + REL_TOL):
                    bad.append((name, f"{g} max |mean error| ({rg.get('unit', '')})", rv, nv, rv * (1 + REL_TOL)))
        return bad


def scheme_events(scheme):
    """The roll phases of a platform's rolling scheme (:class:`fusionbench.platform.Scheme`) as unshaded spans
    (:class:`fusionbench.figures.Event`)."""
    from .figures import Event

    names = {v: k for k, v in _AXES.items()}
    ev, t = [], 0.0
    for seg in scheme.segments:
        ev.append(Event(t, t + seg.duration, f"roll about {names.get(tuple(seg.axis), str(tuple(seg.axis)))}",
                        shade=False))
        t += seg.duration
    return ev
