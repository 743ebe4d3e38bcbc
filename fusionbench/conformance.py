"""The conformance matrix: every registered aligner on every condition it claims, scored against the truth,
the theoretical limit and the attainable bound (scenario ``experiment = "conformance"``).

A condition is a base (static, a mild sway, seed 000's Table-1 sway, or a vehicle accelerating at 0.1 g along
its heading with a velocity reference), a latitude, a true heading, an IMU preset and the noise of the velocity
reference. The matrix file lists about twenty of them so that every level of every factor appears, not the full
product. Each condition becomes an ordinary alignment scenario (:func:`condition_scenario`) run by
:func:`fusionbench.runner.run_alignment`: the methods start on their own (no initial guess), get the reference
only where the base moves or the reference is noisy, and get the condition's IMU as their model; a method runs
only on the conditions its ``supports`` claims (:class:`fusionbench.claims.Supports`).

Each cell (method x condition) is scored at the last sample, over the Monte Carlo runs:

* ``efficiency``: RMS over runs of (final azimuth error - limit), divided by the attainable bound at the end
  (:func:`fusionbench.metrics.attainable_bound`: the noise part an optimal estimator cannot remove). 1 is
  optimal; a small number of runs makes it scatter by about 1/sqrt(2 runs).
* ``level``: RMS over runs of (final level error - limit), east and north, arcmin.
* ``settling``: the first time after which |phiU - limit| stays inside the band until the end, against the
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

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from joblib import Parallel, delayed

from . import aligner, claims, fields, imu, metrics, units
from .aligner import available_methods
from .claims import azimuth_bias_ratio, supports
from .progress import bar as progress_bar

#: Bases of a condition: kind claimed (:data:`fusionbench.claims.BASES`), sway amplitude (deg) and frequency (Hz)
#: of [pitch, roll, yaw].
BASES = {
    "static": ("static", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "sway-mild": ("sway", (1.0, 1.5, 2.0), (0.2, 0.1, 0.05)),
    "sway-table1": ("sway", (5.0, 7.0, 9.0), (0.5, 0.3, 0.2)),
    "moving": ("moving", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
}
#: Acceleration of the moving base along its heading, m/s^2 (0.1 g).
MOVING_ACCEL = 0.1 * units.G0
#: Mean tilt of every base, deg (pitch, roll): a level IMU would hide sign errors between the level axes.
TILT_DEG = (1.0, -2.0)
_TOP = {"name", "description", "kind", "experiment", "duration_s", "rate_hz", "runs", "methods", "quick", "metrics",
        "conformance", "condition", "paper", "imu", "site", "template", "run_unclaimed"}
#: Longitude (deg) and height (m) of a condition when the matrix gives no ``[site]``.
DEFAULT_LON_DEG, DEFAULT_HEIGHT_M = 108.0, 100.0
_CONDITION_KEYS = {"name", "base", "lat_deg", "heading_deg", "imu", "vref_sigma_mps", "expect"}


@dataclass(frozen=True)
class Condition:
    """One condition of the matrix (deg, m/s, m); ``expect`` is "align" or "refuse"; ``imu`` a preset name or the
    absolute path of an IMU spec file."""

    name: str
    base: str
    lat_deg: float
    heading_deg: float
    imu: str
    vref_sigma_mps: float = 0.0
    expect: str = "align"
    lon_deg: float = DEFAULT_LON_DEG
    height_m: float = DEFAULT_HEIGHT_M

    @property
    def kind(self):
        return BASES[self.base][0]


@dataclass(frozen=True)
class Matrix:
    """A validated conformance matrix file."""

    name: str
    description: str
    conditions: tuple
    duration_s: float
    rate_hz: float
    runs: int
    quick_duration_s: float
    quick_runs: int
    methods: tuple | None
    settling_band_arcmin: float
    level_tolerance_arcmin: float
    efficiency_max: dict
    source: str = ""
    paper: dict = field(default_factory=dict)
    experiment: str = "conformance"
    kind: str = "conformance"
    template: bool = False
    run_unclaimed: bool = False

    def sized(self, quick):
        """(duration_s, runs) for a full or a quick run."""
        return (self.quick_duration_s, self.quick_runs) if quick else (self.duration_s, self.runs)

    def threshold(self, method):
        """The efficiency a method must reach: its entry of ``[conformance.efficiency]``, else ``default``."""
        return float(self.efficiency_max.get(method, self.efficiency_max["default"]))


def parse(data, src="<conformance>"):
    """Validate a conformance matrix mapping (as read from TOML); errors name the file and the field."""
    bad = sorted(set(data) - _TOP)
    if bad:
        raise fields.FieldError(f"{fields.where(src, bad[0])}: unknown (expected one of {sorted(_TOP)})")
    name = fields.string(data, "name", src)
    if data.get("kind", "conformance") != "conformance":
        raise fields.FieldError(f"{fields.where(src, 'kind')}: expected 'conformance' for a conformance matrix, "
                                f"found {data['kind']!r}")
    duration = fields.number(data, "duration_s", src, lo=10.0, hi=86400.0)
    rate = fields.number(data, "rate_hz", src, lo=1.0, hi=10000.0)
    runs = int(fields.number(data, "runs", src, 20.0, lo=1, hi=100000))
    quick = fields.table(data, "quick", src, {"duration_s", "runs"})
    methods = data.get("methods")
    if methods is not None and (not isinstance(methods, list) or not methods
                                or not all(isinstance(m, str) and m for m in methods)):
        raise fields.FieldError(f"{fields.where(src, 'methods')}: expected a non-empty list of method names (absent: "
                                f"every registered aligner), found {methods!r}")
    met = fields.table(data, "metrics", src, {"settling_band_arcmin"})
    conf = fields.table(data, "conformance", src, {"level_tolerance_arcmin", "efficiency"})
    eff = conf.get("efficiency", {})
    if not isinstance(eff, dict) or "default" not in eff:
        raise fields.FieldError(f"{fields.where(src, 'conformance.efficiency')}: expected a table with 'default' and "
                                f"per-method thresholds, found {eff!r}")
    eff = {k: fields.number(eff, k, src, lo=1.0, hi=1e6, label=f"conformance.efficiency.{k}") for k in eff}
    sensor = data.get("imu")
    if sensor is not None:
        spec = imu.spec_field(sensor, src)  # checked here, once
        sensor = sensor if sensor in imu.PRESETS else str(imu.near(sensor, src).resolve())
    site = fields.table(data, "site", src, {"lat_deg", "lon_deg", "height_m"})
    site_lat = fields.number(site, "lat_deg", src, lo=-89.0, hi=89.0, label="site.lat_deg") if "lat_deg" in site else None
    template, unclaimed = data.get("template", False), data.get("run_unclaimed", False)
    for key, value in (("template", template), ("run_unclaimed", unclaimed)):
        if not isinstance(value, bool):
            raise fields.FieldError(f"{fields.where(src, key)}: expected true or false, found {value!r}")
    items = data.get("condition")
    if not isinstance(items, list) or not items:
        raise fields.FieldError(f"{fields.where(src, 'condition')}: expected [[condition]] tables, found {items!r}")
    conds, seen = [], set()
    for i, c in enumerate(items):
        label = f"condition[{i}]"
        if not isinstance(c, dict):
            raise fields.FieldError(f"{fields.where(src, label)}: expected a table, found {c!r}")
        extra = sorted(set(c) - _CONDITION_KEYS)
        if extra:
            raise fields.FieldError(f"{fields.where(src, label + '.' + extra[0])}: unknown (expected one of "
                                    f"{sorted(_CONDITION_KEYS)})")
        cname = fields.string(c, "name", src, label=f"{label}.name")
        if cname in seen:
            raise fields.FieldError(f"{fields.where(src, label + '.name')}: expected a unique name, found {cname!r} again")
        seen.add(cname)
        lat = fields.number(c, "lat_deg", src, site_lat, lo=-89.0, hi=89.0, label=f"{label}.lat_deg")
        cimu = fields.string(c, "imu", src, sensor, choices=None if sensor else imu.PRESETS, label=f"{label}.imu")
        if cimu != sensor and cimu not in imu.PRESETS:
            raise fields.FieldError(f"{fields.where(src, label + '.imu')}: expected one of {sorted(imu.PRESETS)} (or "
                                    f"the matrix's own imu), found {cimu!r}")
        expect = fields.string(c, "expect", src, "align", choices=("align", "refuse", "auto"), label=f"{label}.expect")
        if expect == "auto":  # refuse where the gyro bias hides the earth rate (every aligner given the model does)
            ratio = azimuth_bias_ratio(spec if cimu == sensor else imu.PRESETS[cimu], np.radians(lat))
            expect = "refuse" if ratio > claims.MAX_BIAS_TO_EARTH_RATE else "align"
        conds.append(Condition(
            cname, fields.string(c, "base", src, choices=BASES, label=f"{label}.base"), lat,
            fields.number(c, "heading_deg", src, lo=-360.0, hi=360.0, label=f"{label}.heading_deg"), cimu,
            fields.number(c, "vref_sigma_mps", src, 0.0, lo=0.0, hi=10.0, label=f"{label}.vref_sigma_mps"), expect,
            fields.number(site, "lon_deg", src, DEFAULT_LON_DEG, lo=-360.0, hi=360.0, label="site.lon_deg"),
            fields.number(site, "height_m", src, DEFAULT_HEIGHT_M, lo=-1e4, hi=1e5, label="site.height_m")))
    return Matrix(name, str(data.get("description", "")), tuple(conds), duration, rate, runs,
                  fields.number(quick, "duration_s", src, duration, lo=10.0, hi=duration, label="quick.duration_s"),
                  int(fields.number(quick, "runs", src, float(min(runs, 3)), lo=1, hi=runs, label="quick.runs")),
                  None if methods is None else tuple(methods),
                  fields.number(met, "settling_band_arcmin", src, 30.0, lo=1e-3, hi=1e4, label="metrics.settling_band_arcmin"),
                  fields.number(conf, "level_tolerance_arcmin", src, 0.5, lo=0.0, hi=1e4,
                                label="conformance.level_tolerance_arcmin"),
                  eff, src, dict(data.get("paper", {})), template=template,
                  run_unclaimed=unclaimed)


def aligner_names():
    """Every registered aligner (navigators that need an initial attitude left out). A method that claims no
    condition still meets the MEMS condition, where every aligner must refuse."""
    return [name for name, ep in sorted(available_methods().items()) if not supports(ep.load()).needs_init]


def condition_scenario(matrix, cond, quick=False, band_arcmin=None):
    """The alignment scenario (:class:`fusionbench.scenarios.Scenario`) of one condition."""
    from . import scenarios

    duration, runs = matrix.sized(quick)
    _, amp, freq = BASES[cond.base]
    d = {"name": f"{matrix.name}.{cond.name}",
         "description": f"conformance condition {cond.name}: {cond.base} base, {cond.lat_deg:g} deg latitude, heading "
                        f"{cond.heading_deg:g} deg, {Path(cond.imu).stem} IMU, reference noise {cond.vref_sigma_mps:g} m/s",
         "duration_s": duration, "rate_hz": matrix.rate_hz, "runs": runs, "quick": {"duration_s": duration, "runs": runs},
         "site": {"lat_deg": cond.lat_deg, "lon_deg": cond.lon_deg, "height_m": cond.height_m},
         "attitude": {"pitch_deg": TILT_DEG[0], "roll_deg": TILT_DEG[1], "heading_deg": cond.heading_deg,
                      "sway_amplitude_deg": list(amp), "sway_frequency_hz": list(freq)},
         "imu": cond.imu,
         "vref": {"sigma_mps": [cond.vref_sigma_mps] * 3},
         "metrics": {"settling_band_arcmin": matrix.settling_band_arcmin if band_arcmin is None else band_arcmin}}
    if cond.kind == "moving":
        h = np.radians(cond.heading_deg)
        d["motion"] = {"segments": [{"accel_mps2": [MOVING_ACCEL * np.sin(h), MOVING_ACCEL * np.cos(h), 0.0],
                                     "duration_s": duration}]}
    return scenarios.parse(d, f"{matrix.source} condition '{cond.name}'")


def condition_bound(scn, cond, duration):
    """Attainable bound (3,) rad of a condition at the end of its record (:func:`metrics.attainable_bound`)."""
    traj = scn.trajectory(duration)
    _, sigma = metrics.attainable_bound(scn.imu_spec, duration, trajectory=traj, vref_sigma=cond.vref_sigma_mps,
                                        vref_dt=scn.dt)
    return sigma[-1]


@dataclass
class MatrixOutput:
    """A finished conformance run: its metrics (the metrics.json mapping) and each condition's RunOutput."""

    scenario: Matrix
    metrics: dict
    runs: dict  # condition name -> fusionbench.runner.RunOutput


def run_matrix(matrix, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None):
    """Run every method on every condition it claims; returns a :class:`MatrixOutput`.

    ``methods`` defaults to the file's list, else every registered aligner; ``runs`` to the file's size.
    Same seed, same numbers whatever ``n_jobs``.
    """
    from .runner import run_alignment

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
        bound = condition_bound(scn, cond, duration)
        band = max(matrix.settling_band_arcmin, 3.0 * bound[2] / units.ARCMIN)
        scn = condition_scenario(matrix, cond, quick, band_arcmin=band)
        ratio = azimuth_bias_ratio(scn.imu_spec, np.radians(cond.lat_deg))
        covered = {n for n in names if cond.expect == "refuse" or claims[n].covers(cond.kind, cond.lat_deg, ratio)}
        claimed = list(names) if matrix.run_unclaimed else [n for n in names if n in covered]
        conditions[cond.name] = {"base": cond.base, "lat_deg": cond.lat_deg, "heading_deg": cond.heading_deg,
                                 "imu": scn.imu_spec.name, "vref_sigma_mps": cond.vref_sigma_mps, "expect": cond.expect,
                                 "gyro_bias_ratio": float(ratio),
                                 "bound_arcmin": _axes(bound / units.ARCMIN), "settling_band_arcmin": band}
        for n in names:
            if n not in claimed:
                cells[n][cond.name] = {"status": "not claimed"}
        if claimed:
            todo.append((cond, scn, claimed, bound))
    # one condition per worker, all its runs in one batch (the batched filters vectorize over runs); the same
    # numbers as any other split, since run k of a seed does not depend on the batching
    run = delayed(run_alignment)
    jobs = (run(scn, methods=claimed, runs=runs, seed=seed, quick=quick, n_jobs=1, progress=False, refusals=True)
            for _, scn, claimed, _ in todo)
    pbar = progress_bar(progress, runs * len(todo), matrix.name)
    results = []
    for out in Parallel(n_jobs=n_jobs, return_as="generator")(jobs):  # conditions in order, as they finish
        results.append(out)
        pbar.update(runs)
    pbar.close()
    for (cond, _, claimed, bound), out in zip(todo, results):
        outputs[cond.name] = out
        conditions[cond.name]["limit_arcmin"] = _axes(out.limits / units.ARCMIN)
        for n in claimed:
            cells[n][cond.name] = _cell(matrix, cond, n, out, bound)
            if n not in covered:  # run by the file's choice (run_unclaimed): scored, and marked outside the claim
                cells[n][cond.name]["claimed"] = False
    return MatrixOutput(matrix, _metrics(matrix, names, conditions, cells, outputs, runs, seed, quick, duration), outputs)


def _axes(v, keys="ENU"):
    return {k: float(x) for k, x in zip(keys, v)}


def _cell(matrix, cond, name, out, bound):
    """The figures and the verdict of one method on one condition."""
    if name in out.refused:
        ok = cond.expect == "refuse"
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
    level_tol = np.maximum(matrix.level_tolerance_arcmin, matrix.threshold(name) * bound[:2] / units.ARCMIN)
    cell["level_tolerance_arcmin"] = _axes(level_tol, "EN")
    level_ok = bool(np.all(rms[:2] <= level_tol))
    eff_ok = eff <= matrix.threshold(name)
    cell["status"] = "pass" if (level_ok and eff_ok) else "fail"
    if not eff_ok:
        cell["message"] = f"azimuth efficiency {eff:.2f} > {matrix.threshold(name):g}"
    elif not level_ok:
        cell["message"] = (f"level {rms[0]:.2f}/{rms[1]:.2f} arcmin from the limit > {level_tol[0]:.2f}/{level_tol[1]:.2f}")
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
    """The conformance matrix (``experiment = "conformance"``) as an :class:`fusionbench.experiment.Experiment`:
    its file is a :class:`Matrix` (:func:`parse`), its methods the registered aligners."""

    name = "conformance"
    kind = "conformance"
    method_group = aligner.GROUP

    def load(self, data, src):
        return parse(data, src)

    def load_method(self, scn, spec, **options):
        return aligner.load_method(spec, **options)

    def run(self, scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, refusals=True):
        return run_matrix(scn, methods, runs, seed, quick, n_jobs, progress)

    def write_report(self, out, folder):
        from .conformance_report import write_report

        return write_report(out, folder)

    def headline(self, metrics):
        """The overview's column (:class:`fusionbench.overview.Column`): claimed cells passed and the worst azimuth
        efficiency; a method's number is its failed cells plus its worst efficiency over its threshold (good
        within 1: every claimed cell passed)."""
        from .overview import Column

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
        from .check import ABS_TOL_EFFICIENCY, REL_TOL

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

