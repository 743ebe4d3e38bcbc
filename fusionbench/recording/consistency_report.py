"""The report of a consistency check (:mod:`fusionbench.recording.consistency`): consistency.json, consistency.png and
the lines the command line prints. The folder is written whole or not at all (:mod:`fusionbench.files.reportdir`,
:data:`OUTPUT`).

consistency.json (``allow_nan=False``; undefined figures are null; angles in the units their names say)::

    {"kind": "consistency", "window_s": 300.0, "samples_per_window": 30000, "windows": 8, "record_s": 2410.0,
     "site": {"lat_deg", "lon_deg", "height_m"},
     "t_start_s": [...], "t_end_s": [...],          # each window's initial state and last sample
     "pair_t_end_s": [...],                          # pair k: window k carried to window k+1's end
     "imu_model": "navigation" | null,
     "aiding": null | {"file", "format", "rows", "kinds", "lever_arm_m", "delay_s", "time_offset_s", "t_first_s",
                       "t_last_s", "rows_per_window": [...]},   # the receiver's rows (--aiding), each window's
     "bound": null | {"bound_arcmin": {"E", "N", "U"}, "expected_disagreement_arcmin": {"E", "N", "U"}},
     "methods": {name: {
         "windows_aligned": 8, "refused": [{"window": k, "t_end_s": ..., "message": "..."}],
         "attitude_deg": {"pitch": [...], "roll": [...], "yaw": [...]},     # per window, at t_end_s
         "disagreement_arcmin": {"E": [...], "N": [...], "U": [...]},      # per pair (misalignment, ENU)
         "disagreement_euler_arcmin": {"pitch": [...], "roll": [...], "yaw": [...]},
         "agreement_arcmin": {"E": [...], "N": [...], "U": [...]},         # per window, median against the others
         "summary": {"pairs": 7, "disagreement_arcmin": {"mean": {E, N, U}, "std": {...}, "rms": {...}},
                     "agreement_arcmin": {"mean": {...}, "rms": {...}},
                     "rms_over_expected": {E, N, U} | null}}},
     "pairwise_rms_arcmin": {name: {other: {"E", "N", "U"}}}}
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from fusionbench.files import reportdir
from fusionbench.files.imufiles import atomic_open
from fusionbench.recording.consistency import Consistency
from fusionbench.simulation import attitude, units

JSON_FILE, FIGURE_FILE = "consistency.json", "consistency.png"
#: A previous output of ``consistency``, which a new one replaces whole: consistency.json (``"kind":
#: "consistency"``) and nothing but the two files it writes.
OUTPUT = reportdir.Output(JSON_FILE, ("kind",), f"a previous fusionbench consistency output ({JSON_FILE}, "
                          f"{FIGURE_FILE} and nothing else)", files=(JSON_FILE, FIGURE_FILE),
                          values={"kind": "consistency"})

AXES = ("E", "N", "U")
EULER = ("pitch", "roll", "yaw")


def _num(x):
    x = float(x)
    return x if np.isfinite(x) else None


def _list(a, scale=1.0):
    return [_num(v / scale) for v in np.asarray(a, dtype=float)]


def _axes(v, scale, names=AXES):
    return {n: _num(x / scale) for n, x in zip(names, np.asarray(v, dtype=float))}


def _series(a, scale, names=AXES):
    a = np.asarray(a, dtype=float)
    return {n: _list(a[:, i], scale) for i, n in enumerate(names)}


def to_json(res: Consistency, aiding=None) -> dict:
    """The content of consistency.json (module docstring) as plain Python values; ``aiding``: what the command line
    says of the rows (:func:`fusionbench.cli_record.aiding_json`), to which the rows of each window are added."""
    am = units.ARCMIN
    out = {"kind": "consistency", "window_s": res.window_s, "samples_per_window": res.samples_per_window,
           "windows": res.windows, "record_s": res.record_s,
           "site": {"lat_deg": float(np.degrees(res.site.lat)), "lon_deg": float(np.degrees(res.site.lon)),
                    "height_m": float(res.site.h)},
           "t_start_s": _list(res.t_start), "t_end_s": _list(res.t_end), "pair_t_end_s": _list(res.t_end[1:]),
           "imu_model": res.imu_model,
           "aiding": None if res.aiding_rows is None else {**(aiding or {}),
                                                           "rows_per_window": [int(n) for n in res.aiding_rows]},
           "bound": None if res.bound is None else {"bound_arcmin": _axes(res.bound, am),
                                                    "expected_disagreement_arcmin": _axes(res.expected, am)},
           "methods": {}}
    for m, name in enumerate(res.methods):
        s = res.summary(name)
        euler = np.degrees(attitude.dcm_to_euler(np.nan_to_num(res.C_bn[m], nan=0.0)))
        euler[[r is not None for r in res.refused[m]]] = np.nan
        ratio = None if res.expected is None else _axes(s["disagreement_rms"] / res.expected, 1.0)
        out["methods"][name] = {
            "windows_aligned": s["windows"],
            "refused": [{"window": k, "t_end_s": float(res.t_end[k]), "message": r}
                        for k, r in enumerate(res.refused[m]) if r is not None],
            "attitude_deg": _series(euler, 1.0, EULER),
            "disagreement_arcmin": _series(res.disagreement[m], am),
            "disagreement_euler_arcmin": _series(res.disagreement_euler[m], am, EULER),
            "agreement_arcmin": _series(res.agreement[m], am),
            "summary": {"pairs": s["pairs"],
                        "disagreement_arcmin": {k: _axes(s[f"disagreement_{k}"], am) for k in ("mean", "std", "rms")},
                        "agreement_arcmin": {k: _axes(s[f"agreement_{k}"], am) for k in ("mean", "rms")},
                        "rms_over_expected": ratio}}
    out["pairwise_rms_arcmin"] = {a: {b: _axes(res.pairwise_rms[i, j], am) for j, b in enumerate(res.methods) if j != i}
                                  for i, a in enumerate(res.methods)}
    return out


def _fmt(v):
    return "n/a" if not np.isfinite(v) else f"{v:.3g}"


def _triple(v, scale=units.ARCMIN):
    return ", ".join(f"{a} {_fmt(x / scale)}" for a, x in zip(AXES, v))


def summary_lines(res: Consistency) -> list:
    """The lines the command line prints: the windows, the bound when known, then one line per method (its
    window-to-window RMS per axis, as a multiple of the expected one when known, its RMS against the others and
    the windows it refused)."""
    used = res.t_end[-1] - res.t_start[0]
    lines = [f"{res.windows} windows of {res.window_s:g} s ({used:g} s of the {res.record_s:g} s record), "
             f"{res.windows - 1} window pairs; window k carried with the gyros to the end of window k+1"]
    if res.aiding_rows is not None:
        lines.append(f"aiding rows per window: {', '.join(str(int(n)) for n in res.aiding_rows)}")
    if res.bound is not None:
        lines.append(f"attainable bound of one window (IMU {res.imu_model}): {_triple(res.bound)} arcmin; two "
                     f"windows at it disagree by {_triple(res.expected)} arcmin")
    width = max(len(n) for n in res.methods)
    for m, name in enumerate(res.methods):
        s = res.summary(name)
        refused = [(k, r) for k, r in enumerate(res.refused[m]) if r is not None]
        head = f"{name:<{width}}  "
        if len(refused) == res.windows:
            lines.append(head + f"refused every window: {refused[0][1]}")
            continue
        text = f"window to window RMS {_triple(s['disagreement_rms'])} arcmin"
        if res.expected is not None:
            text += " (" + ", ".join(_fmt(x) for x in s["disagreement_rms"] / res.expected) + " x expected)"
        if np.isfinite(s["agreement_rms"]).any():
            text += f"; against the others RMS {_triple(s['agreement_rms'])} arcmin"
        if refused:
            k, r = refused[0]
            text += f"; refused {len(refused)} of {res.windows} windows (window {k}: {r})"
        lines.append(head + text)
    return lines


def plot_consistency(res: Consistency, path):
    """consistency.png: per axis (east, north, up) the window-to-window disagreement of each method against the
    end time of the later window, with the expected spread at the bound when known, and a summary panel (each
    method's RMS per axis against the expected)."""
    from fusionbench.reports import figures

    plt = figures.plt
    am = units.ARCMIN
    cols = figures.colors(res.methods)
    scale, unit = figures.time_axis(float(res.t_end[-1]))
    t = res.t_end[1:] / scale
    fig, axes = plt.subplots(2, 2, figsize=(12.0, 7.6))
    titles = ("east (level): disagreement", "north (level): disagreement", "up (azimuth): disagreement")
    drawn = [n for m, n in enumerate(res.methods) if np.isfinite(res.disagreement[m]).any()]
    for i, ax in enumerate(axes.flat[:3]):
        if res.expected is not None:
            e = res.expected[i] / am
            ax.axhspan(-e, e, color="0.85", lw=0, label="+-1 sigma expected at the bound")
        ax.axhline(0.0, color="0.5", lw=0.6)
        for m, name in enumerate(res.methods):
            if name in drawn:
                ax.plot(t, res.disagreement[m, :, i] / am, "o-", color=cols[name], ms=3.5, lw=1.0, label=name)
        ax.set_title(titles[i], fontsize=9)
        ax.set_ylabel("window k+1 - carried window k (arcmin)", fontsize=8)
        ax.set_xlabel(f"end of window k+1 ({unit})", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
    ax = axes[1, 1]
    width = 0.8 / max(1, len(drawn))
    x = np.arange(3)
    marked = False
    for j, name in enumerate(drawn):
        s = res.summary(name)
        ax.bar(x - 0.4 + (j + 0.5) * width, s["disagreement_rms"] / am, width, color=cols[name], label=name)
        if np.isfinite(s["agreement_rms"]).any():
            ax.plot(x - 0.4 + (j + 0.5) * width, s["agreement_rms"] / am, "kx", ms=5,
                    label=None if marked else "RMS against the others")
            marked = True
    if res.expected is not None:
        for i in range(3):
            ax.plot([i - 0.45, i + 0.45], [res.expected[i] / am] * 2, "k--", lw=1.2,
                    label="expected at the attainable bound" if i == 0 else None)
    ax.set_yscale("log")
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi * (hi / lo) ** 0.6)  # head room for the legend above the bars
    figures.plain_log_ticks(ax)
    ax.set_xticks(x, ["east", "north", "up"], fontsize=8)
    ax.set_ylabel("window-to-window RMS (arcmin)", fontsize=8)
    ax.set_title("spread per method", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.grid(alpha=0.3, axis="y", which="both")
    handles, labels = ax.get_legend_handles_labels()
    if res.expected is not None:
        handles.append(axes[0, 0].patches[0])
        labels.append("+-1 sigma expected at the bound")
    ax.legend(handles, labels, fontsize=7, loc="upper left", ncol=2)
    refused = [f"{n} refused every window" for m, n in enumerate(res.methods) if n not in drawn]
    notes = [f"{res.windows} windows of {res.window_s:g} s: each method aligns each window alone; window k's attitude "
             f"is carried with the gyros to the end of window k+1 and compared with window k+1's own there.",
             "A constant bias puts every window on the same theoretical limit: it does not show here (the limits and "
             "a simulated twin answer for it).",
             f"Grey band and dashed lines: the spread of two independent windows each at the attainable bound (IMU "
             f"{res.imu_model}), the carry's own gyro noise included." if res.expected is not None else
             "No IMU model given: no bound drawn.",
             "; ".join(refused) + "." if refused else ""]
    figures.finish(fig, "Consistency without truth: window against window", notes)
    figures.save_png(fig, str(path))


def write_consistency_report(res: Consistency, out_dir, aiding=None) -> list:
    """Write consistency.png and consistency.json into ``out_dir``, whole or not at all
    (:func:`fusionbench.files.reportdir.written`: assembled beside it and renamed into place; after an error ``out_dir``
    is as it was), and return their paths; ``aiding`` as :func:`to_json`.

    Raises
    ------
    ValueError
        One line naming ``out_dir`` when it is neither absent, nor empty, nor a previous consistency output
        (nothing touched).
    """
    out = Path(out_dir)
    text = json.dumps(to_json(res, aiding), indent=1, allow_nan=False)
    with reportdir.written(out, OUTPUT) as tmp:
        plot_consistency(res, tmp / FIGURE_FILE)
        with atomic_open(tmp / JSON_FILE) as fh:
            fh.write(text + "\n")
    return [out / JSON_FILE, out / FIGURE_FILE]
