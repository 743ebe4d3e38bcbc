"""What is written and printed of an identification (:mod:`fusionbench.recording.identify_core`): the ``[imu]`` table
of the identified spec and its TOML file (:func:`spec_table`, :func:`write_spec_toml`), ``identify.json``
(:func:`report_dict`, :func:`write_identify_report`, with the figure ``allan.png``) and the lines the command line
prints (:func:`summary`, :func:`poor_fit_note`). Every public name here is also
:mod:`fusionbench.recording.identify`'s. Units: the datasheet units of each key (deg/h, deg/sqrt(h), ug, ...) in the
spec and the summary, SI in the JSON beside them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from fusionbench.files import reportdir
from fusionbench.files.imufiles import atomic_open
from fusionbench.recording import allanfit
from fusionbench.recording.identify_core import (ADEV_SI, AXES, FIGURE_FILE, FIT_P_MIN, JSON_FILE, OUTPUT, SENSORS,
                                                 SPEC_FILE, UNITS, Identification, _fmt, _point_p, _vec, identify,
                                                 spec_table)
from fusionbench.simulation import units
from fusionbench.simulation.imudata import IMUData


def poor_fit_note(ident: Identification):
    """One line naming the axes whose Allan curve the standard terms do not describe, or ""."""
    bad = ident.poor_fits()
    if not bad:
        return ""
    axes = ", ".join(f"{s} {ax} ({r:.3g} x the model at {t:.3g} s)" for s, ax, t, r, _ in bad)
    return (f"warning: the IEEE-952 terms do not describe {axes}: a point that far off has a probability below "
            f"{FIT_P_MIN:g}; "
            f"correlated (Gauss-Markov) noise, a vibration, a motion or a temperature drift in the record? (see "
            f"allan.png) Those axes' terms, and the spec's, are only an approximation of the sensor's noise")


def write_spec_toml(ident: Identification, path):
    """Write the identified spec as an IMU spec TOML (an ``[imu]`` table, :func:`fusionbench.simulation.imu.load_spec`
    reads it), atomically, each number commented with where it comes from. Returns the path.

    Raises
    ------
    ValueError
        A figure beyond what the ``[imu]`` parser accepts (nothing written).
    """
    rows = spec_table(ident)
    ident.to_spec()  # the parser accepts every figure, or nothing is written
    lines = ["# IMU spec identified by fusionbench identify from a static record (overlapping Allan deviation and",
             "# a least-squares fit of the IEEE-952 terms; see docs/identify.md). Values per body axis x, y, z.",
             f"# record: {ident.source or '(not named)'}, run {ident.run}, {ident.samples} samples of {ident.dt:.6g} s "
             f"({ident.duration:.6g} s), kind {ident.kind}",
             "[imu]"]
    for key, value, comment in rows:
        text = json.dumps(value) if isinstance(value, str) else (_vec(value) if isinstance(value, list) else _fmt(value))
        lines.append(f"{key} = {text}" + (f"  # {comment}" if comment else ""))
    for s, ax, t, r, _ in ident.poor_fits():
        lines.append(f"# WARNING: {s} {ax}: the IEEE-952 terms do not describe its Allan curve ({r:.3g} x the model "
                     f"at {t:.3g} s); its figures above only approximate the sensor's noise")
    for s in SENSORS:
        ramps = [ident.term(s, j, "R") for j in range(3)]
        if any(r.present for r in ramps):
            lines.append(f"# {s} rate ramp R = {_vec(r.datasheet for r in ramps)} {UNITS[s]['R'][1]}: the error model "
                         f"has no ramp, it is not in this spec")
    with atomic_open(path) as fh:
        fh.write("\n".join(lines) + "\n")
    return Path(path)


# ------------------------------------------------------------------------------------------------ the report


def _axis_json(f: allanfit.AllanFit, sensor):
    c = f.curve
    terms = {}
    for t in allanfit.TERMS:
        si, ds, factor = UNITS[sensor][t]
        present = f.is_present(t)
        terms[t] = {"present": present, "adev_slope": allanfit.SLOPES[t],
                    "si": f.value(t) if present else None, "si_sigma": f.sigma(t) if present else None, "si_unit": si,
                    "datasheet": f.value(t) / factor if present else None,
                    "datasheet_sigma": f.sigma(t) / factor if present else None, "datasheet_unit": ds}
    return {"tau_s": c.tau.tolist(), "adev": c.adev.tolist(), "adev_lo": c.lo.tolist(), "adev_hi": c.hi.tolist(),
            "edf": c.edf.tolist(), "noise_alpha": c.alpha.tolist(), "adev_unit": ADEV_SI[sensor],
            "tau_floor_s": f.tau_floor, "chi2": f.chi2, "dof": f.dof,
            "worst_point_p": float(_point_p(c.adev ** 2 / f.avar(c.tau), c.edf).min()), "terms": terms}


def report_dict(ident: Identification):
    """Everything of the identification as a JSON-able dict (SI and datasheet units, uncertainties 1 sigma)."""
    x_peak, adev_peak = allanfit.gm_peak()
    out = {"name": ident.name, "source": ident.source,
           "record": {"samples": ident.samples, "dt_s": ident.dt, "duration_s": ident.duration, "kind": ident.kind,
                      "run": ident.run, "mean_rate_dph": ident.mean_rate / units.DEG_PER_H,
                      "mean_specific_force_mps2": ident.mean_specific_force, "static_note": ident.static_note()},
           "method": {"allan": "overlapping Allan deviation (allantools.oadev) of the cumulative increments at octave "
                               "taus up to a quarter of the record; 1-sigma chi-square intervals with Greenhall's "
                               "equivalent degrees of freedom",
                      "model": "sigma^2(tau) = 3 Q^2/tau^2 + N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 + R^2 tau^2/2",
                      "fit": "generalised least squares of the Allan variance, non-negative, with the estimates' "
                             "covariance (edf, octave correlations) from the model; terms: the subset minimising the log-space deviance + "
                             f"{allanfit.SIGNIFICANCE:g}^2 per term",
                      "uncertainty": "1 sigma from the least-squares covariance, scaled by the reduced chi-square "
                                     "when above 1",
                      "significance_sigma": allanfit.SIGNIFICANCE,
                      "gauss_markov_peak": {"tau_over_T": x_peak, "adev_over_sigma": adev_peak}},
           "turn_on_bias": "not observable in one static record: the spec's bias sigma is a placeholder (B)",
           "poor_fit_note": poor_fit_note(ident)}
    for s in SENSORS:
        sig, T, floor = ident.gauss_markov(s)
        out[s] = {"axes": {ax: _axis_json(f, s) for ax, f in zip(AXES, ident.fits(s))},
                  "gauss_markov": {"sigma_si": sig.tolist(), "sigma_datasheet": (sig / UNITS[s]["B"][2]).tolist(),
                                   "tau_s": T, "tau_floor_s": floor},
                  "quantum_si": ident.quantum(s)}
    out["spec"] = {k: v for k, v, _ in spec_table(ident)}
    return out


def write_identify_report(ident: Identification, out_dir):
    """Write ``identify.json`` (:func:`report_dict`, no NaN) and the figure ``allan.png`` into ``out_dir``, whole
    or not at all (:func:`fusionbench.files.reportdir.written`): ``out_dir`` must be absent, empty or a previous
    identify output (:data:`fusionbench.recording.identify.OUTPUT`), which the two files replace. Returns the two paths.

    Raises
    ------
    ValueError
        One line naming ``out_dir`` when it holds other files (nothing touched).
    """
    out = Path(out_dir)
    with reportdir.written(out, OUTPUT) as tmp:
        _write_report_files(ident, tmp)
    return [out / JSON_FILE, out / FIGURE_FILE]


def _write_report_files(ident: Identification, folder):
    """identify.json and allan.png into ``folder`` (a folder being assembled)."""
    from fusionbench.recording.allanplot import allan_figure  # matplotlib only when a figure is drawn

    folder = Path(folder)
    with atomic_open(folder / JSON_FILE) as fh:
        json.dump(report_dict(ident), fh, indent=1, allow_nan=False)
        fh.write("\n")
    allan_figure(ident, folder / FIGURE_FILE, summary(ident))


def _pm(value, sigma):
    """``value +- sigma`` rounded to the uncertainty's second significant digit."""
    if not (sigma > 0 and np.isfinite(sigma)):
        return f"{value:.4g}"
    digits = max(0, 1 - int(math.floor(math.log10(sigma))))
    if digits > 6 or abs(value) >= 1e6:
        return f"{value:.3g} +- {sigma:.2g}"
    return f"{value:.{digits}f} +- {sigma:.{digits}f}"


def summary(ident: Identification):
    """Lines for the command line: the record, one line per sensor axis with the present terms in datasheet units
    (+- 1 sigma), and what the spec cannot hold."""
    f0 = ident.gyro[0].curve
    lines = [f"{ident.name}: {ident.samples} samples of {ident.dt:.6g} s ({ident.duration / 3600:.3g} h, {ident.kind}); "
             f"Allan deviation at {f0.tau.size} taus {f0.tau[0]:.3g}-{f0.tau[-1]:.4g} s, IEEE-952 terms +- 1 sigma "
             f"(absent: below {allanfit.SIGNIFICANCE:g} sigma)"]
    for s in SENSORS:
        for j, ax in enumerate(AXES):
            terms = [ident.term(s, j, t) for t in allanfit.TERMS]
            shown = [f"{t.name} {_pm(t.datasheet, t.datasheet_sigma)} {t.unit}" for t in terms if t.present]
            absent = [t.name for t in terms if not t.present]
            lines.append(f"{s:5s} {ax}: " + ("; ".join(shown) or "no term") + (f"  ({', '.join(absent)} absent)"
                                                                              if absent else ""))
    lines.append("turn-on bias: not observable in one static record (the mean mixes it with earth rate and gravity); "
                 "the spec's bias sigmas are placeholders (B): replace them with the datasheet's bias repeatability")
    if any(ident.term(s, j, "R").present for s in SENSORS for j in range(3)):
        lines.append("rate ramp: the error model has none; reported, not in the spec")
    notes = [ident.static_note(), poor_fit_note(ident)]
    return lines + [n for n in notes if n]


def run_identify(imu: IMUData, out_dir, *, name="identified", source="", run=0):
    """Identify ``imu`` and write into ``out_dir``: the spec ``imu_spec.toml``, ``identify.json`` and ``allan.png``.

    The folder is written whole or not at all, as a run's report (:mod:`fusionbench.files.reportdir`): checked before
    any work (it must be absent, empty or a previous identify output, :data:`OUTPUT`), assembled beside it and renamed
    into place; after an error it is as it was.

    Returns
    -------
    list of str
        :func:`summary` followed by one line naming the files written: what the command line prints.

    Raises
    ------
    ValueError
        One line: ``out_dir`` is not a folder identify may replace, a record too short, or a figure the ``[imu]``
        parser refuses.
    """
    out = Path(out_dir)
    created = reportdir.prepare([out], OUTPUT)  # refused before any work
    try:
        ident = identify(imu, name=name, source=source, run=run)
        ident.to_spec()  # a figure the parser refuses stops here, before anything is written
        with reportdir.staged(out, OUTPUT) as tmp:
            _write_report_files(ident, tmp)
            write_spec_toml(ident, tmp / SPEC_FILE)
    except BaseException:
        reportdir.remove_empty(created)
        raise
    return summary(ident) + [f"wrote {out / SPEC_FILE}, {out / JSON_FILE}, {out / FIGURE_FILE}"]
