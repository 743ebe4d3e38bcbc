"""Shared helpers of the report figures: time axis, per-method colours, median and percentile bands,
divergence, small multiples, and the notes under a figure.

Every figure of a run draws a method as one line (the median over runs) with a light band (the 16th to
84th percentile over runs), at most :data:`MAX_PER_PANEL` methods in a panel (more: panels side by side),
and a method whose error is far beyond the others' (:func:`diverged`) in a panel of its own, so that it
cannot rescale the others. Signed errors are drawn on linear axes clipped to what the well-behaved methods
span (:func:`clip_limits`). Events are marked by number in every panel and named under the figure
(:mod:`fusionbench.reports.figure_events`).
"""

from __future__ import annotations

import os
import tempfile
import textwrap
import warnings
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fusionbench.reports.figure_events import (Event, events_note, in_record, mark_events, method_events,  # noqa: E402
                                               scenario_events)

#: Records longer than this are drawn against hours, s.
HOURS_FROM_S = 2 * 3600.0
#: Most methods drawn in one panel; more are spread over panels side by side.
MAX_PER_PANEL = 5
#: Percentiles over runs of the light band around each method's median, %.
BAND_PERCENTILES = (16.0, 84.0)
#: A method diverges when its error size exceeds this factor times the well-behaved methods' (:func:`diverged`).
DIVERGENCE_FACTOR = 20.0
#: Smallest reference error size of :func:`diverged` in the report's figures, arcmin: a method within
#: DIVERGENCE_FACTOR times this of the others is never called diverged.
DIVERGENCE_FLOOR_ARCMIN = 1.0
#: The shared y range of signed errors ends at this factor times the well-behaved methods' error size
#: (:func:`reference_size`): a slow transient of one of them leaves the panel instead of flattening the others.
CLIP_FACTOR = 10.0
#: Share of the record at its end over which a method's error size is measured.
TAIL_FRACTION = 0.1
#: What the figures draw per scenario kind (:data:`fusionbench.bench.scenarios.SCENARIO_KINDS`): the stationary
#: theoretical limit and the settling band around it apply only to an alignment on a stationary or swaying base.
DECORATIONS = {"alignment": {"limit": True, "band": True},
               "moving-alignment": {"limit": False, "band": False},
               "navigation": {"limit": False, "band": False},
               "calibration": {"limit": False, "band": False},
               "conformance": {"limit": True, "band": True}}


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def save_png(fig, path):
    """Save a matplotlib figure as PNG atomically and close it (mode 0666 less the umask, like any new file)."""
    fd, tmp = tempfile.mkstemp(suffix=".png", dir=os.path.dirname(path) or ".")
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it 0600: unreadable to a colleague or a web server
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.unlink(tmp)


def decorations(kind):
    """``{"limit": bool, "band": bool}``: whether a scenario of ``kind`` gets the limit and the settling band."""
    return DECORATIONS.get(kind, {"limit": False, "band": False})


def time_axis(t_end_s):
    """Unit of a time axis for a record ending at ``t_end_s`` (s): ``(divisor_s, "s" or "h")``, hours beyond
    :data:`HOURS_FROM_S`."""
    return (3600.0, "h") if t_end_s > HOURS_FROM_S else (1.0, "s")


def colors(names):
    """A fixed colour per method name, in order (tab10, then tab20 beyond ten methods)."""
    cmap = plt.get_cmap("tab10" if len(names) <= 10 else "tab20")
    return {n: cmap(i % cmap.N) for i, n in enumerate(names)}


def plain_log_ticks(ax):
    """Label a log y axis with plain numbers (1, 10, 100; and 2, 5, 20, 50 over two decades or less) instead of
    powers of ten."""
    from matplotlib.ticker import FuncFormatter

    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))

    def minor(v, _):  # 2 and 5 of each decade, when the axis spans at most two decades
        lo, hi = ax.get_ylim()
        few = lo > 0 and hi / lo <= 150.0
        return f"{v:g}" if few and round(v / 10 ** np.floor(np.log10(v) + 1e-9)) in (2, 5) else ""

    ax.yaxis.set_minor_formatter(FuncFormatter(minor))


def spread(values):
    """``(low, high)`` (M,) of ``values`` (R, M) over runs: the :data:`BAND_PERCENTILES` percentiles (one run: the
    run itself)."""
    values = np.asarray(values, dtype=float)
    if values.shape[0] < 2 or values.shape[1] == 0:
        return values[0], values[0]
    # np.nanpercentile takes the times one at a time (24 000 of them, 1.2 s, in one report): the times without a
    # NaN go to np.percentile at once, the same interpolation on the same values
    gaps = np.isnan(values).any(axis=0)
    out = np.empty((len(BAND_PERCENTILES), values.shape[1]))
    out[:, ~gaps] = np.percentile(values[:, ~gaps], BAND_PERCENTILES, axis=0)
    if gaps.any():
        with warnings.catch_warnings():  # a time where every run is NaN (not drawn) stays NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            out[:, gaps] = np.nanpercentile(values[:, gaps], BAND_PERCENTILES, axis=0)
    return out[0], out[1]


def median_band(ax, t, values, color, label, band=True, **kw):
    """Draw the median over runs of ``values`` (R, M) against ``t`` (M,) and, with two runs or more, the
    :func:`spread` band in a light shade of the same colour. Returns the line."""
    values = np.asarray(values, dtype=float)
    with warnings.catch_warnings():  # a time where every run is NaN (not drawn) stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        mid = np.nanmedian(values, axis=0)
    (line,) = ax.plot(t, mid, color=color, label=label, lw=kw.pop("lw", 1.2), **kw)
    if band and values.shape[0] > 1:
        ax.fill_between(t, *spread(values), color=color, alpha=0.1, lw=0)
    return line


def error_size(t, values):
    """A method's error size on one axis: the median over runs of the RMS over the last :data:`TAIL_FRACTION`
    of the record of ``values`` (R, M), in the unit of ``values``; ``t`` (M,) s."""
    t = np.asarray(t, dtype=float)
    tail = t >= t[0] + (1.0 - TAIL_FRACTION) * (t[-1] - t[0])
    return float(np.median(np.sqrt(np.mean(np.asarray(values, dtype=float)[:, tail] ** 2, axis=1))))


def reference_size(sizes, floor):
    """The size of the well-behaved methods: the median of the smaller half of ``sizes`` (n_methods, ...) along
    the first axis (whatever the worse half does), but at least ``floor``."""
    S = np.asarray(sizes, dtype=float)
    S = np.where(np.isfinite(S), S, np.inf)
    return np.maximum(np.median(np.sort(S, axis=0)[: -(-len(S) // 2)], axis=0), floor)


def diverged(sizes, floor):
    """Names of the methods that diverge.

    Rule: on each axis the reference is :func:`reference_size` of all methods' sizes (the median of the smaller
    half, at least ``floor``); a method diverges when on any axis its size exceeds :data:`DIVERGENCE_FACTOR`
    times the reference, or is not finite. With fewer than two methods nothing diverges (there is nothing to
    compare with).

    Parameters
    ----------
    sizes : dict of str to array_like, shape (n_axes,)
        Each method's :func:`error_size` per axis, e.g. arcmin.
    floor : float
        Smallest reference size, same unit (e.g. :data:`DIVERGENCE_FLOOR_ARCMIN`).

    Returns
    -------
    list of str
        In the order of ``sizes``.
    """
    if len(sizes) < 2:
        return []
    S = np.array([np.asarray(v, dtype=float) for v in sizes.values()])
    S = np.where(np.isfinite(S), S, np.inf)
    ref = reference_size(S, floor)
    return [n for n, s in zip(sizes, S) if np.any(s > DIVERGENCE_FACTOR * ref)]


def diverged_histories(histories, floor=DIVERGENCE_FLOOR_ARCMIN):
    """:func:`diverged` of error histories: name to ``(t (M,) s, err (R, M, n_axes))``, sizes per axis by
    :func:`error_size` (``floor`` in the unit of ``err``, arcmin by default)."""
    return diverged({n: [error_size(t, e[..., i]) for i in range(e.shape[-1])] for n, (t, e) in histories.items()},
                    floor)


def series_label(methods, key):
    """The axis label of a reported series ``key``: from the first method object (of ``methods``, name to object)
    whose optional ``series_labels`` mapping names it; else the key itself."""
    return next((m.series_labels[key] for m in methods.values() if key in getattr(m, "series_labels", {})),
                f"{key} (as reported)")


def clip_limits(curves, pad=0.08, log=False, cap=np.inf, keep=()):
    """Limits ``(lo, hi)`` of an axis spanning the finite values of ``curves`` (arrays) within +-``cap`` and the
    values ``keep`` (always in view), padded by ``pad`` of the span on each side (``log``: of the decades,
    positive values only); None when there are none."""
    vals = np.concatenate([np.ravel(np.asarray(c, dtype=float)) for c in curves]) if curves else np.empty(0)
    vals = vals[np.isfinite(vals) & (np.abs(vals) <= cap)]
    vals = np.concatenate([vals] + [np.ravel(np.asarray(k, dtype=float)) for k in keep])
    vals = vals[np.isfinite(vals) & ((vals > 0) if log else True)]
    if not vals.size:
        return None
    if log:
        lo, hi = np.log10(vals.min()), np.log10(vals.max())
        span = max(hi - lo, 1.0)
        return 10 ** (lo - pad * span), 10 ** (hi + pad * span)
    lo, hi = float(vals.min()), float(vals.max())
    span = hi - lo or max(abs(hi), 1.0)
    return lo - pad * span, hi + pad * span


def groups(names, size=MAX_PER_PANEL):
    """``names`` in consecutive groups of at most ``size``, as even as possible."""
    names = list(names)
    k = max(1, -(-len(names) // size))
    return [list(g) for g in np.array_split(np.array(names, dtype=object), k) if len(g)]


def panels(nrows, names, bad=(), row_height=2.4, col_width=4.6, sharex=True):
    """A small-multiples grid: ``nrows`` rows, a column per group of well-behaved methods and a narrower last
    column for the ``bad`` (diverged) ones. Returns ``(fig, axes (nrows, ncols), cols)`` where ``cols`` lists
    each column's method names (the last one the diverged methods when there are any)."""
    good = [n for n in names if n not in bad]
    cols = groups(good) if good else []
    widths = [1.0] * len(cols)
    if bad:
        cols.append([n for n in names if n in bad])
        widths.append(0.7)
    fig, axes = plt.subplots(nrows, len(cols), figsize=(max(8.5, 1.0 + col_width * sum(widths)), 1.2 + row_height * nrows),
                             squeeze=False, sharex=sharex, gridspec_kw={"width_ratios": widths})
    if bad:
        for ax in axes[:, -1]:
            ax.set_facecolor("#fff4f2")
        axes[0, -1].set_title("diverged: own scale", fontsize=9, color="crimson")
    return fig, axes, cols


def context(scn, metrics, times, bad=(), labels=None):
    """What every figure of a run shares: method names (those of ``times``, name to (M,) s), their labels in legends
    and notes (``labels``, name to label; default the names) and colours, the diverged methods ``bad`` (drawn
    apart), the events of the scenario and of the methods, the time unit, what the scenario's kind draws
    (:func:`decorations`) and a title (the runs and the duration run, "quick" for the reduced size). Methods are
    instantiated through ``scn.method``."""
    duration = metrics["duration_s"]
    names = list(times)
    methods = {}
    for n in names:
        try:
            methods[n] = scn.method(n)
        except ValueError:
            continue
    init_given = scn.init_misalignment is not None
    events = scenario_events(scn, duration) + method_events(methods, init_given)
    scale, unit = time_axis(duration)
    size = f"{metrics['runs']} runs of {duration / scale:g} {unit}{', quick' if metrics.get('quick') else ''}"
    return SimpleNamespace(names=names, labels={n: (labels or {}).get(n, n) for n in names}, t=dict(times),
                           colors=colors(names), bad=list(bad), methods=methods,
                           events=in_record(events, duration), scale=scale, unit=unit, deco=decorations(scn.kind),
                           title=f"{metrics['scenario']} ({scn.kind}, {size})")


def small_multiples(c, rows, values, sharex=True):
    """Small multiples: a row per ``rows`` item ``(key, ylabel, t_from_s, log, refs)`` x a column per method group;
    ``values(name, key)`` gives (R, M) arrays (None: not drawn) drawn as median and band. The well-behaved columns
    share each row's y range, what they span from ``t_from_s`` on and the ``refs`` ((y or (y0, y1), style,
    label) lines and bands); diverged methods in the last column on their own scale. ``c`` is a :func:`context`.
    Returns (fig, axes)."""
    fig, axes, cols = panels(len(rows), c.names, c.bad, sharex=sharex)
    for i, (key, ylabel, t_from, log, refs) in enumerate(rows):
        keep = [np.ravel(y) for y, _, _ in refs] + ([] if log else [np.zeros(1)])  # the truth in view
        span, sizes, own = [], [], []
        for j, col in enumerate(cols):
            ax = axes[i, j]
            for k, n in enumerate(col):
                v = values(n, key)
                if v is None:
                    continue  # later lines thinner: one that coincides with an earlier one leaves its edges in view
                median_band(ax, c.t[n] / c.scale, v, c.colors[n], c.labels.get(n, n), lw=max(0.8, 2.0 - 0.3 * k))
                (own if n in c.bad else span).extend(spread(v[:, c.t[n] >= t_from]))
                if n not in c.bad:
                    sizes.append(error_size(c.t[n], v))
            ax.set_yscale("log" if log else "linear")
            if log:
                plain_log_ticks(ax)
            else:
                ax.axhline(0.0, color="0.6", lw=0.6)
            for y, style, label in refs:
                if style == "band":
                    ax.axhspan(y[0], y[1], color="k", alpha=0.07, lw=0, label=label)
                else:
                    ax.axhline(y, color="k", ls=style, lw=1, label=label)
            mark_events(ax, c.events, c.scale, col, numbers=i == 0)
            ax.grid(alpha=0.3, which="both" if log else "major")
            ax.set_ylabel(ylabel if j == 0 or (c.bad and j == len(cols) - 1) else "", fontsize=9)
        cap = np.inf if log or not sizes else \
            CLIP_FACTOR * reference_size(sizes, DIVERGENCE_FLOOR_ARCMIN) + np.max(np.abs(np.concatenate(keep)))
        lim = clip_limits(span, log=log, cap=cap, keep=keep)
        for j, col in enumerate(cols):
            if lim is not None and not set(col) & set(c.bad):
                axes[i, j].set_ylim(lim)
        if c.bad and own:  # the diverged ones: their own range, from t_from on too
            axes[i, -1].set_ylim(clip_limits(own, log=log, keep=keep))
    for j in range(axes.shape[1]):
        axes[0, j].legend(fontsize=7, loc="best")
        axes[-1, j].set_xlabel(f"time ({c.unit})")
    top = set(axes[0, 0].get_legend_handles_labels()[1])
    for i in range(1, len(rows)):  # lines of reference below the first row: their own legend
        hl = [(h, lab) for h, lab in zip(*axes[i, 0].get_legend_handles_labels()) if lab not in c.labels.values()]
        if hl and {lab for _, lab in hl} - top:
            axes[i, 0].legend(*zip(*hl), fontsize=7, loc="best")
    return fig, axes


def notes(c, extra=""):
    """The paragraphs under a run's figure: its events, ``extra``, and which methods are drawn apart."""
    label = getattr(c, "labels", {})
    bad = (f"Diverged (error at the end over {DIVERGENCE_FACTOR:g} times the better half's): "
           f"{', '.join(label.get(n, n) for n in c.bad)}, drawn apart on its own scale." if c.bad else "")
    events = [Event(e.t0_s, e.t1_s, e.label, tuple(label.get(n, n) for n in e.methods), e.shade) for e in c.events]
    return [events_note(events, c.scale, c.unit), extra, bad]


def finish(fig, title, notes=(), fontsize=10):
    """Title the figure and put the paragraphs ``notes`` (e.g. :func:`events_note`) under it, both wrapped to the
    figure's width, and lay it out."""
    width = fig.get_figwidth()
    fig.suptitle(textwrap.fill(title, int(width * 13)), fontsize=fontsize)
    note = "\n".join(textwrap.fill(n, int(width * 19)) for n in notes if n)
    if note:
        fig.text(0.01, 0.01, note, fontsize=7, va="bottom", ha="left", color="0.2")
    bottom = (0.1 + 0.13 * (note.count("\n") + 1)) / fig.get_figheight() if note else 0.0
    fig.tight_layout(rect=(0, bottom, 1, 1))
