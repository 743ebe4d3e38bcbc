"""The output sensitivity figure of the rolling platform's self-calibration (seed 002 (Ding, rolling-platform
self-calibration), Figs. 4-7): one panel per group of error states, the change of an accelerometer output (ug) that an
initial error of one prior standard deviation causes, against time. The curves come from
:func:`baselines.rolling.observability.sensitivity_curves`."""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import units

from .observability import ERROR_STATE_NAMES

#: Groups drawn by :func:`sensitivity_figure`: (title, state names).
FIGURE_GROUPS = (
    ("gyro biases", ["D0_X", "D0_Y", "D0_Z"]),
    ("X gyro g-sensitive terms", ["DI_X", "DO_X", "DS_X", "DIO_X", "DIS_X", "DOS_X"]),
    ("X gyro mounting angles", ["G_XY", "G_XZ"]),
    ("Y accelerometer terms", ["K0_Y", "K1_Y", "K2_Y", "A_YX"]),
)


def sensitivity_figure(times, S, names=None, path="sensitivity.png", groups=FIGURE_GROUPS, events=()):
    """Draw output sensitivity curves, one panel per group of states, and save a PNG.

    Each panel shows, for each state of the group, the sensitivity of the output it drives most
    (the X, Y or Z accelerometer with the largest peak): the change of that output, in ug, that an initial
    error of one prior standard deviation of the state causes, against time (s, or h beyond 2 h).

    Parameters
    ----------
    times : array_like, shape (T,)
        Times, s.
    S : array_like, shape (T, 3, n)
        Sensitivities, m/s^2 per sigma (:func:`baselines.rolling.observability.sensitivity_curves`).
    names : list of str, optional
        State names, default :data:`ERROR_STATE_NAMES`.
    path : str or path-like
        PNG file written (atomically, :func:`fusionbench.reports.figures.save_png`).
    groups : sequence of (title, list of names), optional
        Panels; default :data:`FIGURE_GROUPS`.
    events : sequence of fusionbench.reports.figure_events.Event, optional
        Marked on the time axis (e.g. :func:`baselines.rolling.scheme.scheme_events`, the roll phases).

    Returns
    -------
    str
        The path written.
    """
    from fusionbench.reports import figures as fg  # matplotlib only when a figure is drawn
    from fusionbench.reports.figure_events import events_note, in_record, mark_events

    t = np.asarray(times, dtype=float)
    S = np.asarray(S, dtype=float)
    if t.ndim != 1 or S.shape[:2] != (t.size, 3) or S.ndim != 3:
        raise ValueError(f"S: expected shape ({t.size}, 3, n) to match times, found {S.shape}")
    names = list(ERROR_STATE_NAMES if names is None else names)
    if len(names) != S.shape[2]:
        raise ValueError(f"names: expected {S.shape[2]} names, found {len(names)}")
    for title, members in groups:
        for m in members:
            if m not in names:
                raise ValueError(f"groups: state {m!r} of panel {title!r} is not in names")
    scale, unit = fg.time_axis(t[-1] if t.size else 0.0)
    events = in_record(events, t[-1]) if t.size else []
    fig, axes = fg.plt.subplots(len(groups), 1, figsize=(8.5, 1.4 + 2.4 * len(groups)), sharex=True, squeeze=False)
    for k, (ax, (title, members)) in enumerate(zip(axes[:, 0], groups)):
        for m in members:
            col = S[:, :, names.index(m)] / units.UG
            out = int(np.argmax(np.abs(col).max(axis=0)))
            ax.plot(t / scale, col[:, out], lw=1.0, label=f"{m} -> {'XYZ'[out]} accelerometer")
        ax.set_title(title, fontsize=9, loc="left")
        ax.set_ylabel("output change (ug)\nper prior sigma", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best", ncol=2)
        mark_events(ax, events, scale, numbers=k == 0)
    axes[-1, 0].set_xlabel(f"time ({unit})")
    fg.finish(fig, "Output sensitivity along the rolling scheme (seed 002 Figs. 4-7): the change of an accelerometer "
              "output caused by an initial error of one prior sigma of each coefficient",
              [events_note(events, scale, unit)])
    fg.save_png(fig, str(path))
    return str(path)
