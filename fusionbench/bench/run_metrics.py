"""metrics.json of an alignment run: the figures of each method's outcome against the limit and the bound
(docs/contract.md), and the atomic writer every report uses."""

from __future__ import annotations

import json

import numpy as np

from fusionbench.files.imufiles import atomic_open
from fusionbench.scoring import metrics
from fusionbench.scoring.bound import efficiency
from fusionbench.simulation import units


def run_metrics(scn, outcomes, limits, runs, seed, quick, duration, bound=None):
    """The metrics.json mapping of a finished alignment run (docs/contract.md).

    Parameters
    ----------
    scn : fusionbench.bench.scenarios.Scenario
    outcomes : dict of fusionbench.bench.runner.MethodOutcome
        Each method's outcome; its ``name`` is its label in the mapping.
    limits : ndarray, shape (3,)
        The limit at the last sample, rad, ENU.
    runs, seed : int
    quick : bool
    duration : float
        The record length run, s.
    bound : ndarray, shape (3,), optional
        The attainable bound at the last sample, rad, ENU (alignment kinds): adds ``bound_arcmin`` and each
        method's ``efficiency_U``.
    """
    band = scn.settling_band_arcmin
    out = {
        "scenario": scn.name,
        "runs": runs,
        "seed": int(seed),
        "duration_s": float(duration),
        "quick": bool(quick),
        "limits_arcmin": {ax: float(limits[i] / units.ARCMIN) for i, ax in enumerate("ENU")},
        "methods": {},
    }
    if bound is not None:  # an alignment kind
        out["bound_arcmin"] = {ax: float(bound[i] / units.ARCMIN) for i, ax in enumerate("ENU")}
    for oc in outcomes.values():
        name = oc.name  # the label
        phi_end = oc.per_run["phi_end"] / units.ARCMIN
        settle, settled = oc.per_run["settle"], oc.per_run["settled"]
        # a smoother's settling is measured on the first PREFIX_RUNS runs only (NaN elsewhere); "U": a run that
        # does not settle counts with the record's end, "U_settled": the runs that settle only
        settling = {"U": metrics.stats(settle[np.isfinite(settle)]), "band_arcmin": band}
        if np.any(settled & np.isfinite(settle)):
            settling["U_settled"] = metrics.stats(settle[settled & np.isfinite(settle)])
        out["methods"][name] = {
            "final_error_arcmin": {ax: metrics.stats(phi_end[:, i]) for i, ax in enumerate("ENU")},
            "settling_time_s": settling,
            "settled_fraction_U": float(np.mean(settled)),
            "wall_s": float(oc.wall_s),
            "final_minus_limit_arcmin": {ax: float(np.mean(phi_end[:, i]) - limits[i] / units.ARCMIN)
                                         for i, ax in enumerate("ENU")},
            "level_rms_last_100s_arcmin": {ax: float(np.sqrt(oc.per_run["level_ms"][:, i].mean()) / units.ARCMIN)
                                           for i, ax in enumerate("EN")},
        }
        if bound is not None:
            out["methods"][name]["efficiency_U"] = float(efficiency(oc.per_run["phi_end"], limits, bound)[2])
        sig = oc.per_run["sigma_end"]
        if np.all(np.isfinite(sig)):  # filters: actual error over predicted sigma, RMS over runs
            ratio = np.sqrt(np.mean((oc.per_run["phi_end"] / sig) ** 2, axis=0))
            out["methods"][name]["consistency_rms_ratio"] = {ax: float(ratio[i]) for i, ax in enumerate("ENU")}
        entry = out["methods"][name]
        for feature in scn.features:
            entry.update(feature.summarise(oc.per_run))
        entry.update(oc.figures)
    for feature in scn.features:
        out.update(feature.summarise_run(out, outcomes))
    return out


def write_metrics(path, metrics_dict):
    """Write metrics.json atomically (indent 1, keys in insertion order)."""
    with atomic_open(path) as fh:
        json.dump(metrics_dict, fh, indent=1)
        fh.write("\n")
