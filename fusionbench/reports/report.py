"""report.md and its figures (matplotlib, Agg backend) for a scenario run (the overview of several:
:mod:`fusionbench.experiments.overview`).

Each scenario folder holds ``metrics.json``, ``report.md`` and PNG figures: the misalignment
(E, N, U) against time for every method, the median over runs with a 16-84 % band, at most five methods a
panel, a diverged method apart, the events of the run marked, and the theoretical limit dashed where the
scenario's kind gives it a meaning (the helpers: :mod:`fusionbench.reports.figures`).
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from fusionbench.bench.run_metrics import write_metrics
from fusionbench.files.imufiles import atomic_open
from fusionbench.reports import figures as fg
from fusionbench.reports.figures import plt, save_png  # noqa: F401 (plt, save_png: used by the methods' own figures)
from fusionbench.simulation import units


def _diverged(out):
    """Names of the methods whose misalignment diverges (:func:`fusionbench.reports.figures.diverged_histories`), as
    given (the keys of ``out.outcomes``)."""
    return fg.diverged_histories({n: (oc.t, oc.phi / units.ARCMIN) for n, oc in out.outcomes.items()})


def run_context(out):
    """The :func:`fusionbench.reports.figures.context` of an alignment run (its methods with their labels, events,
    time axis, diverged ones)."""
    return fg.context(out.scenario, out.metrics, {n: oc.t for n, oc in out.outcomes.items()}, _diverged(out),
                      {n: oc.name for n, oc in out.outcomes.items()})


def _optimal(out):
    """The course of an optimal estimator's azimuth error, arcmin, where the run has a bound (an alignment kind):
    ``(t (M,) s, limit (M,), bound (M,))`` (the limit it lands on and its spread about it), else None."""
    if "bound_arcmin" not in out.metrics:
        return None
    from fusionbench.bench.runner import scenario_limits
    from fusionbench.scoring.bound import scenario_bound

    scn, duration = out.scenario, out.metrics["duration_s"]
    traj = scn.trajectory(duration)
    t, sigma = scenario_bound(scn, traj, duration, history=True)
    limit = scenario_limits(scn, traj, t, traj.truth(t).C_bn)[:, 2]
    return t, limit / units.ARCMIN, sigma[:, 2] / units.ARCMIN


def error_figure(out, path):
    """Misalignment (E, N, U, arcmin) against time: per method the median over runs and the 16-84 percentile
    band; a diverged method apart; the stationary limit dashed only for the alignment kind; the y range is
    what the other methods span after ``zoom_from_s`` (the whole record for navigation). Returns the Figure."""
    c = run_context(out)
    lim = out.limits / units.ARCMIN
    t_from = 0.0 if out.scenario.kind == "navigation" else out.scenario.zoom_from_s
    rows = [(i, f"phi{'ENU'[i]} (arcmin)", t_from, False, [(lim[i], "--", "limit")] if c.deco["limit"] else [])
            for i in range(3)]
    fig, _ = fg.small_multiples(c, rows, lambda n, i: out.outcomes[n].phi[..., i] / units.ARCMIN)
    clip = f"Vertical range: what the methods span from {t_from / c.scale:g} {c.unit} on; earlier transients leave it." \
        if t_from > 0 else ""
    fg.finish(fig, f"{c.title}: misalignment against the truth, median over runs and 16-84 % band",
              fg.notes(c, clip))
    save_png(fig, path)
    return fig


def azimuth_figure(out, path):
    """Azimuth error against time (like seed 000's (Zhou 2011, ADRC gyrocompass) Figs. 3 and 4): above, the RMS over
    runs on a log scale over the whole record; below, from the scenario's ``zoom_from_s``, median and 16-84 % band, with
    the limit and the settling band where they apply (alignment kind). Returns the Figure."""
    c = run_context(out)
    t0 = out.scenario.zoom_from_s
    lim, band = out.limits[2] / units.ARCMIN, out.scenario.settling_band_arcmin
    rows = [("rms", "rms over runs of |phiU| (arcmin)", 0.0, True, [(abs(lim), "--", "|limit|")] * c.deco["limit"]),
            ("zoom", "phiU (arcmin)", t0, False, [(lim, "--", "limit")] * c.deco["limit"]
             + [((lim - band, lim + band), "band", f"limit +- {band:g} arcmin")] * c.deco["band"])]

    def values(n, row):
        u = out.outcomes[n].phi[..., 2] / units.ARCMIN
        if row == "rms":
            return np.sqrt(np.mean(u**2, axis=0))[None]
        return np.where(out.outcomes[n].t >= t0, u, np.nan)

    fig, axes = fg.small_multiples(c, rows, values, sharex=False)
    end = out.metrics["duration_s"] / c.scale
    best = _optimal(out)
    for top, zoom in zip(*axes):  # every panel of a row over the same times
        if best is not None:  # the optimal estimator's course, on the scale the methods set
            t, lim_t, sig = best
            ylim = top.get_ylim(), zoom.get_ylim()
            top.plot(t / c.scale, np.hypot(lim_t, sig), color="k", ls=":", lw=1.2, label="optimal estimator")
            for sign, label in ((1, "limit +- bound"), (-1, None)):
                zoom.plot(t[t >= t0] / c.scale, (lim_t + sign * sig)[t >= t0], color="k", ls=":", lw=1.0,
                          label=label)
            end_rms, lo, hi = np.hypot(lim_t[-1], sig[-1]), lim_t[-1] - sig[-1], lim_t[-1] + sig[-1]
            top.set_ylim(min(ylim[0][0], end_rms / 1.5), max(ylim[0][1], end_rms * 1.5))  # its end in view
            pad = 0.1 * (hi - lo)
            zoom.set_ylim(min(ylim[1][0], lo - pad), max(ylim[1][1], hi + pad))
        top.set_xlim(-0.02 * end, 1.02 * end)
        zoom.set_xlim(t0 / c.scale, 1.02 * end)
    if best is not None:  # the legends again, with the optimal estimator's lines
        axes[0, 0].legend(fontsize=7, loc="best")
        axes[1, 0].legend(*zip(*[(h, lab) for h, lab in zip(*axes[1, 0].get_legend_handles_labels())
                                 if lab not in c.labels.values()]), fontsize=7, loc="best")
    optimal = ("Dotted: an optimal estimator (the Kalman filter of the error model with the true noise and the "
               "scenario's reference): above its rms over runs, sqrt(limit^2 + bound^2); below the limit +- the "
               "attainable bound, its 16-84 % band." if best is not None else "")
    fg.finish(fig, f"{c.title}: azimuth error; above: rms over runs, whole record; below: median and 16-84 % band "
              f"from {t0 / c.scale:g} {c.unit}", fg.notes(c, optimal))
    save_png(fig, path)
    return fig


def series_figure(out, path):
    """Series a method reports about itself (e.g. a damping coefficient), median and band over runs, a panel per
    series; the axis label from the method's optional ``series_labels`` mapping. Returns the Figure."""
    c = run_context(out)
    keys = list(dict.fromkeys(k for oc in out.outcomes.values() for k in oc.series))
    c.names = [n for n in c.names if out.outcomes[n].series]
    c.bad = []
    fig, _ = fg.small_multiples(c, [(k, fg.series_label(c.methods, k), 0.0, False, []) for k in keys],
                                lambda n, k: out.outcomes[n].series.get(k))
    fg.finish(fig, f"{c.title}: series reported by the methods, median over runs", fg.notes(c))
    save_png(fig, path)
    return fig


def _method_figures(out, folder):
    """Figures the methods draw about themselves (``report_figures(folder)``), once per file name."""
    seen = {}
    for name in out.outcomes:
        try:
            method = out.scenario.method(name)
        except ValueError:
            continue
        if hasattr(method, "report_figures"):
            for fname, caption in method.report_figures(folder):
                seen.setdefault(fname, caption)
    return seen


def _consistency_section(m):
    cons = [(n, r["consistency_rms_ratio"]) for n, r in m["methods"].items() if "consistency_rms_ratio" in r]
    if not cons:
        return ""
    lines = ["Filter consistency at the end: RMS over runs of the actual error over the predicted sigma "
             "(1 for a consistent filter):", "", "| method | E | N | U |", "|---|---|---|---|"]
    lines += [f"| {n} | {c['E']:.2f} | {c['N']:.2f} | {c['U']:.2f} |" for n, c in cons]
    return "\n".join(lines) + "\n"


def paper_section(out):
    """The ``[paper]`` features' sections of a run (:class:`fusionbench.features.paper.PaperClaims`): the source
    paper's claims beside ours; "" when the scenario has none."""
    return "".join(f.markdown(out) for f in out.scenario.features if f.table == "paper")


def _settling(r, runs):
    """A method's azimuth settling cell: "never settled", the mean settling time (s) of the runs that settled and,
    where some did not, how many did."""
    frac, st = r.get("settled_fraction_U"), r["settling_time_s"]
    if frac is not None and frac == 0:
        return "never settled"
    mean = st.get("U_settled", st["U"])["mean"]
    if frac is None or frac == 1:
        return f"{mean:.1f}" if np.isfinite(mean) else "not measured"
    return f"{mean:.1f} ({round(frac * runs)} of {runs} settled)"


def _table(m, kind):
    """The final-error table: the limit's row where the scenario kind has one (the stationary theoretical limit;
    on a moving base the optimal estimator's, with a bound), the attainable bound's row and each method's efficiency
    where the run has a bound, the settling column where the kind has a settling band; a diverged method marked."""
    lim, bad, bound = m["limits_arcmin"], set(m.get("diverged", [])), m.get("bound_arcmin")
    settle = fg.decorations(kind)["band"]
    band = next(iter(m["methods"].values()))["settling_time_s"]["band_arcmin"] if m["methods"] else ""
    extra = ([" efficiency U |"] if bound else []) + ([f" settling U (s, band {band} arcmin) |"] if settle else [])
    rows = ["| method | phiE mean (std) | phiN mean (std) | phiU mean (std) | phiU rms |" + "".join(extra)
            + " wall (s) |", "|---" * (6 + len(extra)) + "|"]
    blank = " |" * len(extra)
    if fg.decorations(kind)["limit"] or bound:
        label = "theoretical limit" if fg.decorations(kind)["limit"] else "limit of an optimal estimator"
        rows.append(f"| *{label}* | {lim['E']:.3f} | {lim['N']:.3f} | {lim['U']:.3f} | |{blank} |")
    if bound:
        rows.append(f"| *attainable bound (std about the limit)* | ({bound['E']:.3f}) | ({bound['N']:.3f}) "
                    f"| ({bound['U']:.3f}) | | 1{' |' if settle else ''} | |")
    for name, r in m["methods"].items():
        f = r["final_error_arcmin"]
        cells = ([f" {r['efficiency_U']:.2f} |"] if bound and "efficiency_U" in r else [" |"] if bound else []) \
            + ([f" {_settling(r, m.get('runs', 1))} |"] if settle else [])
        rows.append(f"| {name}{' **(diverged)**' if name in bad else ''} | {f['E']['mean']:.3f} ({f['E']['std']:.3f}) "
                    f"| {f['N']['mean']:.3f} ({f['N']['std']:.3f}) | {f['U']['mean']:.3f} ({f['U']['std']:.3f}) "
                    f"| {f['U']['rms']:.3f} |" + "".join(cells) + f" {r['wall_s']:.2f} |")
    if bad:
        rows += ["", f"**Diverged**: {', '.join(f'`{n}`' for n in m['diverged'])}: its error over the last "
                 f"{100 * fg.TAIL_FRACTION:g} % of the record (median over runs of the RMS) is more than "
                 f"{fg.DIVERGENCE_FACTOR:g} times that of the better half of the methods (at least "
                 f"{fg.DIVERGENCE_FLOOR_ARCMIN:g} arcmin) on some axis; the figures draw it apart, on its own scale."]
    return "\n".join(rows)


def _limit_text(kind, m):
    """What the limit, the bound, the efficiency and the settling column of :func:`_table` mean."""
    if fg.decorations(kind)["limit"]:
        text = ("The limit is what any stationary alignment reaches with this IMU's constant biases: level = "
                "accelerometer bias / g, azimuth = -east gyro bias / (earth rate cos L) + tan L east accelerometer "
                "bias / g.")
    elif "bound_arcmin" in m:
        text = ("On a moving base the limit is where the optimal estimator that does not know the IMU's constant "
                "biases lands (the motion makes them partly observable: fusionbench.scoring.bound.bias_limit), and "
                "there is no settling band.")
    else:
        return (f"A {kind} scenario has no stationary limit: the errors are against the truth, and the figures draw "
                "neither a limit nor a settling band.")
    if "bound_arcmin" in m:
        text += (" The attainable bound is the standard deviation about the limit that an optimal estimator (the "
                 "Kalman filter of the error model with the true noise statistics and this scenario's reference) "
                 "reaches at the last sample; a method's **efficiency** is the RMS over runs of (final phiU - limit) "
                 "divided by that bound: 1 is optimal, and with "
                 f"{m['runs']} runs it scatters by about {1 / np.sqrt(2 * m['runs']):.2f} (1/sqrt(2 runs)).")
    if fg.decorations(kind)["band"]:
        text += (" Settling: the mean time after which phiU stays within the band about the limit until the end, "
                 "over the runs that do; *never settled*: no run ended inside the band.")
    return text


def _span(seconds):
    """A record length in s, or in h beyond :data:`fusionbench.reports.figures.HOURS_FROM_S`."""
    scale, unit = fg.time_axis(seconds)
    return f"{seconds / scale:g} {unit}"


def write_alignment_report(out, folder):
    """Write metrics.json, report.md and the figures of an alignment run (:class:`fusionbench.bench.runner.RunOutput`)
    into ``folder``; returns the report's path."""
    folder = Path(folder)
    m = out.metrics
    scn = out.scenario
    m["diverged"] = [out.outcomes[n].name for n in _diverged(out)]
    fig_name = "errors.png"
    error_figure(out, folder / fig_name)
    azimuth_figure(out, folder / "azimuth.png")
    extra_figs = {}
    for feature in scn.features:
        extra_figs.update(feature.report_figures(out, folder))
    if any(oc.series for oc in out.outcomes.values()):
        series_figure(out, folder / "series.png")
        extra_figs["series.png"] = "series reported by the methods"
    extra_figs.update(_method_figures(out, folder))
    extra_md = "\n".join(f"![{cap}]({f})\n" for f, cap in extra_figs.items())
    level = "\n".join(f"| {n} | {r['level_rms_last_100s_arcmin']['E']:.3f} | {r['level_rms_last_100s_arcmin']['N']:.3f} |"
                      for n, r in m["methods"].items())
    methods_desc = "\n".join(f"- `{oc.name}`{f' (`{n}`)' if oc.name != n else ''}: {oc.description}"
                             for n, oc in out.outcomes.items())
    size = f"{m['runs']} runs of {_span(m['duration_s'])}"
    full_d, full_r = scn.sized(False)
    full = f" (the quick size; the full size is {full_r} runs of {_span(full_d)})" if m["quick"] else ""
    final = textwrap.fill("Final misalignment at the last sample, arcmin (mean and standard deviation over runs). "
                          + _limit_text(scn.kind, m), 116)
    text = f"""# {m['scenario']}: {size}{' (quick)' if m['quick'] else ''}

Scenario: {scn.description}

This run: {size}{full}, seed {m['seed']}, at {scn.rate_hz:g} Hz, latitude {np.degrees(scn.site.lat):.3f} deg,
IMU `{scn.imu_spec.name}` ({scn.imu_spec.description}).

{final}

{_table(m, scn.kind)}

Methods:

{methods_desc}

Level errors over the last 100 s, RMS over runs and time (arcmin):

| method | phiE | phiN |
|---|---|---|
{level}

![misalignment vs time]({fig_name})

![azimuth error vs time](azimuth.png)

{_consistency_section(m)}
{"".join(feature.markdown(out) + chr(10) for feature in scn.features if feature.table == "metrics")}
{extra_md}
{paper_section(out)}
Reproduce: `fusionbench run {m['scenario']} --runs {m['runs']} --seed {m['seed']}{' --quick' if m['quick'] else ''}`
"""
    write_metrics(folder / "metrics.json", m)
    with atomic_open(folder / "report.md") as fh:
        fh.write(text)
    return folder / "report.md"
