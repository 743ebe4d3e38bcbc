"""The conformance matrix: every registered aligner on every condition it claims, scored against the truth,
the theoretical limit and the attainable bound (scenario ``experiment = "conformance"``).

A condition is a base (static, a mild sway, seed 000's (Zhou 2011, ADRC gyrocompass) Table-1 sway, or a vehicle
accelerating at 0.1 g along its heading with a velocity reference), a latitude, a true heading, an IMU preset and the
noise of the velocity reference. The matrix file lists about twenty of them so that every level of every factor appears,
not the full product. Each condition becomes an ordinary alignment scenario (:func:`condition_scenario`) run by
:func:`fusionbench.bench.runner.run_alignment`: the methods start on their own (no initial guess but on a condition's
``init_error_deg``: the truth turned by that much, which a method declaring a smaller capture range must refuse),
get the reference only where the base moves or the reference is noisy, and get the condition's IMU as their model;
a method runs only on the conditions its ``supports`` claims (:class:`fusionbench.methods.claims.Supports`).

Each cell (method x condition) is scored at the last sample, over the Monte Carlo runs:

* ``efficiency``: RMS over runs of (final azimuth error - limit), divided by the attainable bound at the end
  (:func:`fusionbench.scoring.metrics.attainable_bound`: the noise part an optimal estimator cannot remove). 1 is
  optimal; a small number of runs makes it scatter by about 1/sqrt(2 runs).
* ``level``: RMS over runs of (final level error - limit), east and north, arcmin.
* ``settling``: the first time after which abs(phiU - limit) stays inside the band until the end, against the
  truth (the band is the larger of the file's ``settling_band_arcmin`` and three bounds).

A cell passes when its efficiency is at most the method's threshold (``[conformance.efficiency]``) and both
level figures are within ``level_tolerance_arcmin`` (0.5 arcmin), or within the threshold times the level bound
where the sensors' noise alone puts an optimal estimator further off (a tactical IMU: 0.22-0.27 arcmin of level
bound from its gyro noise and accelerometer bias instability). A condition with ``expect = "refuse"`` (a MEMS-grade gyro
whose bias hides the earth rate) passes only when the method refuses (ValueError): a confident heading there is
wrong whatever its value.

metrics.json keeps the contract's keys (``limits_arcmin`` and each method's figures are those of the first
condition) and adds ``conditions``, ``cells`` and ``scoreboard``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from joblib import delayed

from fusionbench.bench.conformance_file import (Matrix, condition_bound,  # noqa: F401 (the experiment's)
                                                condition_scenario, parse)
from fusionbench.bench.memory import parallel_compiling_first
from fusionbench.files.progress import bar as progress_bar
from fusionbench.methods import aligner
from fusionbench.methods.aligner import available_methods
from fusionbench.methods.claims import azimuth_bias_ratio, supports
from fusionbench.simulation import units


def aligner_names():
    """Every registered aligner (navigators that need an initial attitude left out). A method that claims no
    condition still meets the MEMS condition, where every aligner must refuse."""
    return [name for name, ep in sorted(available_methods().items()) if not supports(ep.load()).needs_init]


@dataclass
class MatrixOutput:
    """A finished conformance run: its metrics (the metrics.json mapping) and each condition's RunOutput."""

    scenario: Matrix
    metrics: dict
    runs: dict  # condition name -> fusionbench.bench.runner.RunOutput


def run_matrix(matrix, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None):
    """Run every method on every condition it claims; returns a :class:`MatrixOutput`.

    ``methods`` defaults to the file's list, else every registered aligner; ``runs`` to the file's size.
    Same seed, same numbers whatever ``n_jobs``.
    """
    from fusionbench.bench.runner import scenario_limits

    names = list(methods or matrix.methods or aligner_names())
    duration, default_runs = matrix.sized(quick)
    runs = default_runs if runs is None else int(runs)
    conditions, cells, outputs = {}, {n: {} for n in names}, {}
    claims = {}
    for n in names:  # fail early, with the method's own message
        probe = condition_scenario(matrix, matrix.conditions[0], quick).method(n)
        claims[n] = supports(probe)
    todo = []
    for cond in matrix.conditions:
        scn = condition_scenario(matrix, cond, quick)
        ratio = azimuth_bias_ratio(scn.imu_spec, np.radians(cond.lat_deg))
        claim = cond.aiding_claim(matrix.rate_hz)
        covered = {n for n in names
                   if cond.expect == "refuse" or claims[n].covers(cond.kind, cond.lat_deg, ratio, **claim)}
        claimed = list(names) if matrix.run_unclaimed else [n for n in names if n in covered]
        conditions[cond.name] = {"base": cond.base, "lat_deg": cond.lat_deg, "heading_deg": cond.heading_deg,
                                 "imu": scn.imu_spec.name, "vref_sigma_mps": cond.vref_sigma_mps, "expect": cond.expect,
                                 "init_error_deg": cond.init_error_deg,
                                 "gyro_bias_ratio": float(ratio),
                                 "bound_arcmin": None, "settling_band_arcmin": None}  # the worker's (below)
        if cond.receiver:
            conditions[cond.name]["aiding"] = {"kinds": cond.aiding, "rate_hz": claim["aiding_hz"],
                                               "position_sigma_m": cond.position_sigma_m,
                                               "lever_arm_m": list(cond.lever_arm_m), "delay_s": cond.delay_s,
                                               "outage_s": cond.outage_s}
        for n in names:
            if n not in claimed:
                cells[n][cond.name] = {"status": "not claimed"}
        if claimed:
            todo.append((cond, claimed, covered))
        else:  # no method claims it: its bound and limit all the same, for the table
            bound, _, band, scn = _condition_figures(matrix, cond, quick, duration)
            conditions[cond.name].update(bound_arcmin=_axes(bound / units.ARCMIN), settling_band_arcmin=band)
            traj = scn.trajectory(duration)
            conditions[cond.name]["limit_arcmin"] = _axes(scenario_limits(scn, traj, [duration],
                                                                  traj.truth([duration]).C_bn)[0] / units.ARCMIN)
    # one condition per worker, all its runs in one batch (the batched filters vectorize over runs); the same
    # numbers as any other split, since run k of a seed does not depend on the batching. Each worker takes its
    # condition's bound and limits too, so that a moving base's (an ODE solve of the path) is taken once, in parallel
    jobs = (delayed(_run_condition)(matrix, cond, quick, duration, claimed, runs, seed) for cond, claimed, _ in todo)
    # on an empty kernel cache the first conditions compile every kernel: on two runs (the batched kernels), in
    # workers that are restarted before the matrix, so that the compiler's memory does not meet a whole batch's
    rehearsal = (delayed(_run_condition)(matrix, cond, quick, duration, claimed, min(runs, 2), seed)
                 for cond, claimed, _ in todo[:2])
    pbar = progress_bar(progress, runs * len(todo), matrix.name)
    results = []
    for out in parallel_compiling_first(jobs, n_jobs, rehearsal):  # conditions in order, as they finish
        results.append(out)
        pbar.update(runs)
    pbar.close()
    for (cond, claimed, covered), (bound, sway_limit, band, out) in zip(todo, results):
        outputs[cond.name] = out
        conditions[cond.name].update(bound_arcmin=_axes(bound / units.ARCMIN), settling_band_arcmin=band,
                                     limit_arcmin=_axes(out.limits / units.ARCMIN))
        if sway_limit is not None:
            conditions[cond.name]["bias_limit_level_arcmin"] = _axes(sway_limit[0] / units.ARCMIN, "EN")
            conditions[cond.name]["bias_limit_level_sigma_arcmin"] = _axes(sway_limit[1] / units.ARCMIN, "EN")
        for n in claimed:
            cells[n][cond.name] = _cell(matrix, cond, n, out, bound, sway_limit)
            if n not in covered:  # run by the file's choice (run_unclaimed): scored, and marked outside the claim
                cells[n][cond.name]["claimed"] = False
    return MatrixOutput(matrix, _metrics(matrix, names, conditions, cells, outputs, runs, seed, quick, duration), outputs)


def _condition_figures(matrix, cond, quick, duration):
    """A condition's bound (3,) rad (:func:`condition_bound`), its sway's level limit (:func:`sway_level_limit`),
    its settling band, arcmin (the file's, or three times the azimuth bound when that is wider), and its scenario
    with that band."""
    scn = condition_scenario(matrix, cond, quick)
    bound = condition_bound(scn, cond, duration)
    sway_limit = sway_level_limit(scn, cond, duration)
    band = max(matrix.settling_band_arcmin, 3.0 * bound[2] / units.ARCMIN)
    return bound, sway_limit, band, condition_scenario(matrix, cond, quick, band_arcmin=band)


def _run_condition(matrix, cond, quick, duration, methods, runs, seed):
    """One condition's figures (:func:`_condition_figures`, the scenario left out) and its Monte Carlo of
    ``methods`` (:func:`fusionbench.bench.runner.run_alignment`, refusals recorded), in one worker."""
    from fusionbench.bench.runner import run_alignment

    bound, sway_limit, band, scn = _condition_figures(matrix, cond, quick, duration)
    out = run_alignment(scn, methods=methods, runs=runs, seed=seed, quick=quick, n_jobs=1, progress=False,
                        refusals=True)
    return bound, sway_limit, band, out


def _axes(v, keys="ENU"):
    return {k: float(x) for k, x in zip(keys, v)}


def sway_level_limit(scn, cond, duration):
    """On a swaying base, the levels (2,) rad (E, N) where the fixed biases put the optimal estimator that does not know
    them, and its level spread (2,) rad (:func:`fusionbench.scoring.bound.bias_limit`); None on other bases.

    A sway turns the accelerometers' axes, so an estimator of the full model separates part of their horizontal biases
    from the tilts and its levels leave the stationary limit for this one (seed 000's Table-1 sway with a tactical
    IMU: 1.0 arcmin -> 0.01); a method that does not model the biases stays on the stationary limit. Either is scored
    as right (:func:`_cell`)."""
    if cond.kind != "sway":
        return None
    bl = scn.moving_limit(scn.trajectory(duration))
    return bl.limit[-1, :2], bl.sigma[-1, :2]


def _cell(matrix, cond, name, out, bound, sway_limit=None):
    """The figures and the verdict of one method on one condition; on a swaying base the levels pass about the
    stationary limit or about ``sway_limit`` (:func:`sway_level_limit`), each with its own spread."""
    if name in out.refused:
        ok = cond.expect == "refuse" or (cond.refuses_init(out.scenario.method(name))
                                         and ": init: " in out.refused[name])
        return {"status": "pass" if ok else "fail", "refused": True, "message": out.refused[name]}
    oc = out.outcomes[name]
    err = oc.per_run["phi_end"] - out.limits  # (R, 3) rad: final error minus limit
    rms = np.sqrt(np.mean(err**2, axis=0)) / units.ARCMIN
    eff = float(rms[2] * units.ARCMIN / bound[2])
    cell = {"refused": False, "efficiency_U": eff, "efficiency_max": matrix.threshold(name),
            "final_minus_limit_rms_arcmin": _axes(rms), "bound_arcmin": _axes(bound / units.ARCMIN),
            "settling_mean_s": float(np.nanmean(oc.per_run["settle"])),
            "settled_fraction": float(np.mean(oc.per_run["settled"])), "wall_s": float(oc.wall_s)}
    if cond.expect == "refuse":
        cell.update(status="fail", message="gave a heading where the azimuth is unobservable")
        return cell
    method = out.scenario.method(name)
    if cond.refuses_init(method):
        cell.update(status="fail", message=f"aligned from an init {cond.init_error_deg:g} deg off, beyond the "
                                           f"{method.init_capture_deg:g} deg it declares it recovers from")
        return cell
    level_tol = np.maximum(matrix.level_tolerance_arcmin, matrix.threshold(name) * bound[:2] / units.ARCMIN)
    cell["level_tolerance_arcmin"] = _axes(level_tol, "EN")
    level_ok = bool(np.all(rms[:2] <= level_tol))
    if sway_limit is not None:
        rms_b = np.sqrt(np.mean((oc.per_run["phi_end"][:, :2] - sway_limit[0]) ** 2, axis=0)) / units.ARCMIN
        tol_b = np.maximum(matrix.level_tolerance_arcmin, matrix.threshold(name) * sway_limit[1] / units.ARCMIN)
        cell["final_minus_bias_limit_level_rms_arcmin"] = _axes(rms_b, "EN")
        cell["bias_limit_level_tolerance_arcmin"] = _axes(tol_b, "EN")
        on_bias_limit = not level_ok and bool(np.all(rms_b <= tol_b))
        cell["level_limit"] = "bias" if on_bias_limit else "stationary"
        level_ok = level_ok or on_bias_limit
    eff_ok = eff <= matrix.threshold(name)
    cell["status"] = "pass" if (level_ok and eff_ok) else "fail"
    if not eff_ok:
        cell["message"] = f"azimuth efficiency {eff:.2f} > {matrix.threshold(name):g}"
    elif not level_ok:
        cell["message"] = (f"level {rms[0]:.2f}/{rms[1]:.2f} arcmin from the limit > {level_tol[0]:.2f}/{level_tol[1]:.2f}"
                           + ("" if sway_limit is None else f" (from the bias limit {rms_b[0]:.2f}/{rms_b[1]:.2f} > "
                                                            f"{tol_b[0]:.2f}/{tol_b[1]:.2f})"))
    return cell


def _metrics(matrix, names, conditions, cells, outputs, runs, seed, quick, duration):
    first = next((outputs[c.name] for c in matrix.conditions if c.name in outputs), None)
    board, passed, total = {}, 0, 0
    for n in names:
        mine = [c for c in cells[n].values() if c["status"] != "not claimed" and c.get("claimed", True)]
        effs = [c["efficiency_U"] for c in mine if "efficiency_U" in c and not c.get("refused")]
        ok = sum(c["status"] == "pass" for c in mine)
        board[n] = {"claimed": len(mine), "passed": ok, "worst_efficiency": float(max(effs)) if effs else None,
                    "efficiency_max": matrix.threshold(n)}
        passed, total = passed + ok, total + len(mine)
    return {"scenario": matrix.name, "runs": runs, "seed": int(seed), "duration_s": float(duration), "quick": bool(quick),
            "limits_arcmin": dict(first.metrics["limits_arcmin"]) if first else {"E": 0.0, "N": 0.0, "U": 0.0},
            "methods": dict(first.metrics["methods"]) if first else {},
            "reference_condition": matrix.conditions[0].name,
            "conditions": conditions, "cells": cells,
            "scoreboard": {"passed": passed, "total": total, "methods": board}}


class ConformanceExperiment:
    """The conformance matrix (``experiment = "conformance"``) as an :class:`fusionbench.bench.experiment.Experiment`:
    its file is a :class:`Matrix` (:func:`parse`), its methods the registered aligners."""

    name = "conformance"
    kind = "conformance"
    method_group = aligner.METHODS_GROUP

    def load(self, data, src):
        return parse(data, src)

    def load_method(self, scn, spec, **options):
        return aligner.load_method(spec, **options)

    def run(self, scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, refusals=True):
        return run_matrix(scn, methods, runs, seed, quick, n_jobs, progress)

    def write_report(self, out, folder):
        from fusionbench.reports.conformance_report import write_report

        return write_report(out, folder)

    def headline(self, metrics):
        """The overview's column (:class:`fusionbench.experiments.overview.Column`): claimed cells passed and the
        worst azimuth efficiency; a method's number is its failed cells plus its worst efficiency over its threshold
        (good within 1: every claimed cell passed)."""
        from fusionbench.experiments.overview import Column

        col = Column(metrics["scenario"], "conformance", "cells passed of claimed; worst azimuth efficiency (1 optimal)",
                     short="passed; worst eff.", claim=True, strict=True)
        for meth, cells in metrics.get("cells", {}).items():
            claimed = [c for c in cells.values() if c.get("status") not in ("not claimed", None)]
            passed = sum(c["status"] == "pass" for c in claimed)
            effs = [c["efficiency_U"] / c["efficiency_max"] for c in claimed if "efficiency_U" in c]
            worst = max((c["efficiency_U"] for c in claimed if "efficiency_U" in c), default=None)
            text = f"{passed}/{len(claimed)}" + (f"; {worst:.2f}" if worst is not None else "")
            col.values[meth] = (len(claimed) - passed + max(effs, default=0.0), text) if claimed else (None, "claims none")
        return col

    def check(self, new, ref):
        """Every cell that passed in the reference must pass, and its azimuth efficiency may not grow beyond
        10 % of the reference plus 0.05."""
        from fusionbench.bench.check import ABS_TOL_EFFICIENCY, REL_TOL

        bad = []
        for name, rc in ref.get("cells", {}).items():
            for cond, r in rc.items():
                n = new.get("cells", {}).get(name, {}).get(cond, {"status": "missing"})
                if r["status"] == "pass" and n["status"] != "pass":
                    bad.append((name, f"{cond}: cell", "pass", n["status"], "pass"))
                if "efficiency_U" in r:
                    allowed = r["efficiency_U"] * (1 + REL_TOL) + ABS_TOL_EFFICIENCY
                    nv = n.get("efficiency_U", float("nan"))
                    if not nv <= allowed:
                        bad.append((name, f"{cond}: efficiency", r["efficiency_U"], nv, allowed))
        return bad

