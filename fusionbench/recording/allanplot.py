"""The figure of ``fusionbench identify``: the Allan deviation of each axis with its confidence intervals, the fitted
IEEE-952 model and each of its terms, one panel for the gyros (deg/h) and one for the accelerometers (ug), and the
fitted values under each panel."""

from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter

from fusionbench.recording import allanfit
from fusionbench.recording.identify_core import ADEV_UNITS, AXES, SENSORS
from fusionbench.reports.figures import plain_log_ticks, plt, save_png

__all__ = ["TERM_NAMES", "allan_figure"]

#: What each term is called, per sensor.
TERM_NAMES = {"gyro": {"Q": "quantisation", "N": "angle random walk", "B": "bias instability",
                       "K": "rate random walk", "R": "rate ramp"},
              "accel": {"Q": "quantisation", "N": "velocity random walk", "B": "bias instability",
                        "K": "acceleration random walk", "R": "acceleration ramp"}}
_LEGEND_NAMES = {"Q": "quantisation", "N": "angle (gyro) / velocity (accel) random walk", "B": "bias instability",
                 "K": "rate / acceleration random walk", "R": "rate / acceleration ramp"}
_STYLE = {"Q": (0, (1, 1.5)), "N": (0, (5, 2)), "B": (0, (6, 2, 1, 2)), "K": (0, (2, 2)), "R": (0, (8, 2, 1, 2, 1, 2))}
_SLOPE_TEXT = {"Q": "-1", "N": "-1/2", "B": "0", "K": "+1/2", "R": "+1"}
_AXIS_COLORS = ("tab:blue", "tab:orange", "tab:green")
_TITLES = {"gyro": "Gyros: Allan deviation of the angular rate",
           "accel": "Accelerometers: Allan deviation of the specific force"}


def _label_at(f, term, grid, floor):
    """Where to name a term on its line, clear of the data near the bottom of the panel: ``(tau, side)`` with
    ``side`` -1 for the text left of the point, +1 right of it. A falling line (Q, N) is named where it comes down
    to ``floor``, the text on its right; a rising one (K, R) where it leaves ``floor``, the text on its left; the
    flat B at its left end, where the curve is far above it. A line that stays above or below ``floor`` is named
    at the end of the measured taus, the text inwards."""
    y = f.term_adev(term, grid)
    slope = allanfit.SLOPES[term]
    if slope == 0:
        return float(grid[0]), 1
    k = np.flatnonzero(y <= floor if slope < 0 else y >= floor)
    if k.size == 0:
        return float(grid[-1]), -1
    if k[0] == 0:
        return float(grid[0]), 1
    return float(grid[k[0]]), 1 if slope < 0 else -1


def _unclash(ax, labels):
    """Keep the labels inside the panel (a label past its left or right edge goes to the other side of its point,
    and to the other side of the line) and move each up until it overlaps none of the ones before it."""
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    placed = []
    for ann in labels:
        box = ann.get_window_extent(renderer)
        if box.x1 > frame.x1 or box.x0 < frame.x0:
            dx, dy = ann.xyann
            ann.xyann = (-dx, 3.0 if dy < 0 else -4.0)
            ann.set_horizontalalignment("right" if dx > 0 else "left")
            ann.set_verticalalignment("bottom" if dy < 0 else "top")
            box = ann.get_window_extent(renderer)
        for _ in range(10):
            hit = [b for b in placed if box.overlaps(b)]
            if not hit:
                break
            dx, dy = ann.xyann
            ann.xyann = (dx, dy + (max(b.y1 for b in hit) - box.y0 + 2.0) * 72.0 / ax.figure.dpi)
            box = ann.get_window_extent(renderer)
        placed.append(box)


def _plain_ticks(ax):
    plain_log_ticks(ax)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


def _panel(ax, ident, sensor):

    unit, scale = ADEV_UNITS[sensor]
    fits = ident.fits(sensor)
    lo_y, hi_y = np.inf, 0.0
    for f, color in zip(fits, _AXIS_COLORS):
        c = f.curve
        ax.errorbar(c.tau, c.adev / scale, yerr=[(c.adev - c.lo) / scale, (c.hi - c.adev) / scale], fmt="o", ms=3.5,
                    color=color, ecolor=color, elinewidth=0.9, capsize=2, zorder=3)
        grid = np.geomspace(c.tau[0], c.tau[-1], 200)
        ax.plot(grid, np.sqrt(f.avar(grid)) / scale, color=color, lw=1.5, zorder=2)
        positive = c.lo[c.lo > 0] / scale
        lo_y = min(lo_y, positive.min()) if positive.size else lo_y
        hi_y = max(hi_y, (c.hi / scale).max())
        for t in allanfit.TERMS:
            if f.is_present(t):
                ax.plot(grid, f.term_adev(t, grid) / scale, color=color, lw=1.0, ls=_STYLE[t], alpha=0.75, zorder=1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    y_lo = lo_y / 5.0 if np.isfinite(lo_y) else 1.0
    ax.set_ylim(y_lo, max(hi_y * 1.5, 10.0 * y_lo))
    labels = []
    for t in allanfit.TERMS:  # name each term once, on the axis where it is largest
        present = [j for j, f in enumerate(fits) if f.is_present(t)]
        if present:
            f = fits[max(present, key=lambda k: fits[k].value(t))]
            grid = np.geomspace(f.curve.tau[0], f.curve.tau[-1], 200)
            x, side = _label_at(f, t, grid, 2.0 * y_lo * scale)
            y = float(f.term_adev(t, np.array([x]))[0]) / scale
            above = allanfit.SLOPES[t] * side < 0  # the text on the side of the point away from the line
            labels.append(ax.annotate(
                f"{t}: slope {_SLOPE_TEXT[t]}", (x, y), xytext=(4 * side, 3 if above else -4),
                textcoords="offset points", ha="left" if side > 0 else "right", va="bottom" if above else "top",
                fontsize=8, color="0.1", zorder=4,
                bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="0.7", lw=0.5, alpha=0.85)))
    _unclash(ax, labels)
    _plain_ticks(ax)
    ax.grid(True, which="major", lw=0.5, alpha=0.5)
    ax.grid(True, which="minor", lw=0.3, alpha=0.25)
    ax.set_xlabel("averaging time tau (s)")
    ax.set_ylabel(f"Allan deviation ({unit})")
    ax.set_title(_TITLES[sensor], fontsize=10)


def _legend(fig, ident):

    handles = [Line2D([], [], color=c, marker="o", ms=4, lw=1.5, label=f"axis {a}: measured (68 % interval) and fit")
               for a, c in zip(AXES, _AXIS_COLORS)]
    for t in allanfit.TERMS:
        if any(f.is_present(t) for s in SENSORS for f in ident.fits(s)):
            handles.append(Line2D([], [], color="0.3", lw=1.0, ls=_STYLE[t],
                                  label=f"{t}: {_LEGEND_NAMES[t]}, slope {_SLOPE_TEXT[t]}"))
    fig.legend(handles=handles, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, 0.305), ncol=3, frameon=False)


def allan_figure(ident, path, lines):
    """Draw the Allan deviation figure of an :class:`fusionbench.recording.identify.Identification` and save it as PNG
    at ``path`` (atomically); ``lines`` are its printed summary
    (:func:`fusionbench.recording.identify_report.summary`), the figures of each sensor drawn under its panel."""
    fig, axes = plt.subplots(1, 2, figsize=(13.0, 8.4))
    fig.subplots_adjust(left=0.06, right=0.98, top=0.92, bottom=0.37, wspace=0.16)
    for k, (ax, sensor) in enumerate(zip(axes, SENSORS)):
        _panel(ax, ident, sensor)
        values = "\n".join(textwrap.fill(s, 80, subsequent_indent=" " * 9) for s in lines[1 + 3 * k:4 + 3 * k])
        x0 = ax.get_position().x0
        fig.text(x0, 0.235, "Fitted, +- 1 sigma:\n" + values, va="top", ha="left", fontsize=8, family="monospace")
    _legend(fig, ident)
    title = f"{ident.name}: noise identified from a static record" + (f" ({ident.source})" if ident.source else "")
    fig.suptitle(title, fontsize=11)
    notes = [lines[0], "Dots: the overlapping Allan deviation of each body axis with its 68 % confidence interval "
             "(long averaging times rest on few independent samples). Solid lines: the fitted total; dashed: each "
             "term alone, a straight line of the slope marked.", *lines[7:]]
    fig.text(0.01, 0.01, "\n".join(textwrap.fill(n, 200) for n in notes), fontsize=7.5, va="bottom", ha="left",
             color="0.2")
    save_png(fig, path)
