"""report.md and its figures (matplotlib, Agg backend) for a scenario run (the overview of several:
:mod:`fusionbench.overview`).

Each scenario folder holds ``metrics.json``, ``report.md`` and PNG figures: the misalignment
(E, N, U) against time for every method, the median over runs with a 16-84 % band, at most five methods a
panel, a diverged method apart, the events of the run marked, and the theoretical limit dashed where the
scenario's kind gives it a meaning (the helpers: :mod:`fusionbench.figures`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import figures as fg
from . import units
from .figures import plt, save_png  # noqa: F401 (plt, save_png: used by the methods' own figures)
from .imufiles import atomic_open
from .runner import write_metrics


def _diverged(out):
    """Names of the methods whose misalignment diverges (:func:`fusionbench.figures.diverged_histories`)."""
    return fg.diverged_histories({n: (oc.t, oc.phi / units.ARCMIN) for n, oc in out.outcomes.items()})


def _context(out):
    return fg.context(out.scenario, out.metrics, {n: oc.t for n, oc in out.outcomes.items()}, _diverged(out))


def error_figure(out, path):
    """Misalignment (E, N, U, arcmin) against time: per method the median over runs and the 16-84 percentile
    band; a diverged method apart; the stationary limit dashed only for the alignment kind; the y range is
    what the other methods span after ``zoom_from_s`` (the whole record for navigation). Returns the Figure."""
    c = _context(out)
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
    """Azimuth error against time (like seed 000's Figs. 3 and 4): above, the RMS over runs on a log scale over
    the whole record; below, from the scenario's ``zoom_from_s``, median and 16-84 % band, with the limit and the
    settling band where they apply (alignment kind). Returns the Figure."""
    c = _context(out)
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
    for top, zoom in zip(*axes):  # every panel of a row over the same times
        top.set_xlim(-0.02 * end, 1.02 * end)
        zoom.set_xlim(t0 / c.scale, 1.02 * end)
    fg.finish(fig, f"{c.title}: azimuth error; above: rms over runs, whole record; below: median and 16-84 % band "
              f"from {t0 / c.scale:g} {c.unit}", fg.notes(c))
    save_png(fig, path)
    return fig


def level_figure(out, path):
    """Level misalignment (phiE, phiN, arcmin) against time, median and 16-84 % band of every method, with the
    scenario's RMSE window shaded and the events marked (like seed 004's Figs. 9-11). Returns the Figure."""
    c = _context(out)
    fig, axes = fg.small_multiples(c, [(i, f"phi{'EN'[i]} (arcmin)", 0.0, False, []) for i in range(2)],
                                   lambda n, i: out.outcomes[n].phi[..., i] / units.ARCMIN)
    win = out.scenario.rmse_window_s
    if win is not None:
        for ax in axes.ravel():
            ax.axvspan(win[0] / c.scale, win[1] / c.scale, color="tab:blue", alpha=0.08, lw=0)
    fg.finish(fig, f"{c.title}: level errors, median over runs and 16-84 % band",
              fg.notes(c, "" if win is None else f"Blue: the RMSE window, {win[0] / c.scale:.4g} to "
                    f"{win[1] / c.scale:.4g} {c.unit}."))
    save_png(fig, path)
    return fig


def series_figure(out, path):
    """Series a method reports about itself (e.g. a damping coefficient), median and band over runs, a panel per
    series; the axis label from the method's optional ``series_labels`` mapping. Returns the Figure."""
    c = _context(out)
    keys = list(dict.fromkeys(k for oc in out.outcomes.values() for k in oc.extra.get("series", {})))
    c.names = [n for n in c.names if out.outcomes[n].extra.get("series")]
    c.bad = []
    fig, _ = fg.small_multiples(c, [(k, fg.series_label(c.methods, k), 0.0, False, []) for k in keys],
                                lambda n, k: out.outcomes[n].extra["series"].get(k))
    fg.finish(fig, f"{c.title}: series reported by the methods, median over runs", fg.notes(c))
    save_png(fig, path)
    return fig


def _window_section(out):
    m = out.metrics
    rows = [(n, r) for n, r in m["methods"].items() if "window_rmse_arcmin" in r or "amplitude_arcmin" in r]
    if not rows:
        return ""
    lines = ["## Attitude over the run", ""]
    win = out.scenario.rmse_window_s
    amp_names = list(out.scenario.amplitude_windows_s)
    head = "| method |"
    if win is not None:
        head += f" RMSE {win[0]:.0f}-{win[1]:.0f} s: E / N / level |"
    head += "".join(f" amplitude '{w}' {out.scenario.amplitude_windows_s[w][0]:.0f}-"
                    f"{out.scenario.amplitude_windows_s[w][1]:.0f} s: E / N |" for w in amp_names)
    lines += ["Level misalignment, arcmin: RMS over runs and the window's time, and the half peak-to-peak "
              "in each amplitude window (mean over runs):", "", head, "|---" * (head.count("|") - 1) + "|"]
    for n, r in rows:
        row = f"| {n} |"
        if win is not None:
            w = r.get("window_rmse_arcmin")
            row += f" {w['E']:.3f} / {w['N']:.3f} / {w['level']:.3f} |" if w else " - |"
        for a in amp_names:
            v = r.get("amplitude_arcmin", {}).get(a)
            row += f" {v['E']:.3f} / {v['N']:.3f} |" if v else " - |"
        lines.append(row)
    if "reduction_percent" in m:
        base, cand = out.scenario.compare
        lines += ["", f"Level RMSE in the window: `{base}` {m[f'rmse_{base}_arcmin']:.3f} arcmin, `{cand}` "
                  f"{m[f'rmse_{cand}_arcmin']:.3f} arcmin; reduction 100 (base - candidate) / base = "
                  f"**{m['reduction_percent']:.1f} %**."]
    return "\n".join(lines) + "\n"


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


def _paper_section(out):
    paper = out.scenario.paper
    if not paper:
        return ""
    lines = [f"## Beside the paper ({paper.get('reference', 'source paper')})", ""]
    claims = paper.get("settling_time_s", {})
    if claims:
        band = out.scenario.settling_band_arcmin
        lines += [f"| method | paper: azimuth settles in (s) | here: mean (max) settling in a {band:g} arcmin band (s) "
                  "| final phiU rms (arcmin) |", "|---|---|---|---|"]
        for name, r in out.metrics["methods"].items():
            st = r["settling_time_s"]["U"]
            base = out.scenario.variants.get(name, {}).get("method", name)
            lines.append(f"| {name} | {claims.get(base, '-')} | {st['mean']:.0f} ({st['max_abs']:.0f}) "
                         f"| {r['final_error_arcmin']['U']['rms']:.2f} |")
        lines.append("")
    if paper.get("note"):
        lines += [paper["note"].strip(), ""]
    return "\n".join(lines)


def _jump_section(m):
    rows = [(n, r["jump"]) for n, r in m["methods"].items() if "jump" in r]
    if not rows:
        return ""
    a, b = rows[0][1]["window_s"]
    lines = [f"## Noise jump ({a:g} s to {b:g} s)", "",
             "Misalignment RMS over runs and time in each part of the record, peak |error| from the jump on, and "
             "the time after the jump ends until phiU stays within the settling band of its final value "
             "(arcmin, s):", "",
             "| method | before E/N/U | during E/N/U | after E/N/U | peak E/N/U | re-converge (mean, max) |",
             "|---|---|---|---|---|---|"]
    fmt = lambda d: " / ".join(f"{d[ax]:.2f}" for ax in "ENU") if d else "-"  # noqa: E731
    for n, j in rows:
        r = j["rms_arcmin"]
        lines.append(f"| {n} | {fmt(r.get('before'))} | {fmt(r.get('during'))} | {fmt(r.get('after'))} "
                     f"| {fmt(j['peak_arcmin'])} | {j['reconverge_s']['mean']:.0f}, {j['reconverge_s']['max_abs']:.0f} |")
    cons = [(n, r["consistency_rms_ratio"]) for n, r in m["methods"].items() if "consistency_rms_ratio" in r]
    if cons:
        lines += ["", "Filter consistency at the end: RMS over runs of the actual error over the predicted sigma "
                  "(1 for a consistent filter):", "", "| method | E | N | U |", "|---|---|---|---|"]
        lines += [f"| {n} | {c['E']:.2f} | {c['N']:.2f} | {c['U']:.2f} |" for n, c in cons]
    return "\n".join(lines) + "\n"


def _table(m, kind):
    """The final-error table; the stationary limit's row and the settling column only where they apply (the
    scenario kind), a diverged method marked."""
    lim, bad = m["limits_arcmin"], set(m.get("diverged", []))
    settle = fg.decorations(kind)["band"]
    band = next(iter(m["methods"].values()))["settling_time_s"]["band_arcmin"] if m["methods"] else ""
    rows = ["| method | phiE mean (std) | phiN mean (std) | phiU mean (std) | phiU rms |"
            + (f" settling U (s, band {band} arcmin) |" if settle else "") + " wall (s) |",
            "|---" * (7 if settle else 6) + "|"]
    if fg.decorations(kind)["limit"]:
        rows.append(f"| *theoretical limit* | {lim['E']:.3f} | {lim['N']:.3f} | {lim['U']:.3f} | |{' |' if settle else ''} |")
    for name, r in m["methods"].items():
        f = r["final_error_arcmin"]
        s = r["settling_time_s"]["U"]
        rows.append(f"| {name}{' **(diverged)**' if name in bad else ''} | {f['E']['mean']:.3f} ({f['E']['std']:.3f}) "
                    f"| {f['N']['mean']:.3f} ({f['N']['std']:.3f}) | {f['U']['mean']:.3f} ({f['U']['std']:.3f}) "
                    f"| {f['U']['rms']:.3f} |" + (f" {s['mean']:.1f} |" if settle else "") + f" {r['wall_s']:.2f} |")
    if bad:
        rows += ["", f"**Diverged**: {', '.join(f'`{n}`' for n in m['diverged'])}: its error over the last "
                 f"{100 * fg.TAIL_FRACTION:g} % of the record (median over runs of the RMS) is more than "
                 f"{fg.DIVERGENCE_FACTOR:g} times that of the better half of the methods (at least "
                 f"{fg.DIVERGENCE_FLOOR_ARCMIN:g} arcmin) on some axis; the figures draw it apart, on its own scale."]
    return "\n".join(rows)


def _limit_text(kind):
    if fg.decorations(kind)["limit"]:
        return ("The limit is what\nany stationary alignment reaches with this IMU's constant biases: level = "
                "accelerometer bias / g,\nazimuth = -east gyro bias / (earth rate cos L) + tan L east accelerometer "
                "bias / g.")
    return (f"A {kind} scenario has no\nstationary limit: the errors are against the truth, and the figures draw "
            "neither a limit nor a settling band.")


def calibration_figure(out, path, names=("D0_X", "DI_X", "DIO_X", "G_XY", "K0_Y", "K1_Y", "A_YX", "KT_X")):
    """Run 0's estimates of a few coefficients against truth (customary units): the final pass with its 3-sigma
    envelope shaded; for a multi-pass method its causal first pass too (the convergence a real-time filter shows)
    as a line with its envelope dotted, unshaded; the scheme's roll phases marked. Returns the Figure."""
    from . import platform as pf

    c = fg.context(out.scenario, out.metrics, dict.fromkeys(out.outcomes, out.t))
    fig, axes = plt.subplots(len(names) // 2, 2, figsize=(10, 1.2 + 2.2 * (len(names) // 2)), sharex=True)
    t = out.t / c.scale
    for name, oc in out.outcomes.items():
        if oc["x"] is None:
            continue
        for k, (ax, n) in enumerate(zip(axes.ravel(), names)):
            i = pf.COEFF_NAMES.index(n)
            sc, truth = pf.COEFF_SCALE[i], oc["truth"][0, i] / pf.COEFF_SCALE[i]
            lim = abs(truth) * 3 + 3 * oc["sig_hist"][-1, i] / sc + 1e-12
            if oc.get("x_causal") is not None:
                est, sig = oc["x_causal"][:, i] / sc, oc["sig_causal"][:, i] / sc
                ax.plot(t, est, color="tab:orange", lw=1, label=f"{name}, first (causal) pass, +-3 sigma dotted")
                ax.plot(t, est - 3 * sig, t, est + 3 * sig, color="tab:orange", lw=0.7, ls=":")
                lim = max(lim, abs(truth) * 3 + 3 * sig[-1])
            est, sig = oc["x"][:, i] / sc, oc["sig_hist"][:, i] / sc
            ax.fill_between(t, est - 3 * sig, est + 3 * sig, color="tab:blue", alpha=0.15, lw=0)
            ax.plot(t, est, color="tab:blue", lw=1.2, label=f"{name}, final estimate, +-3 sigma shaded")
            ax.axhline(truth, color="k", ls="--", lw=1, label="truth")
            ax.set_ylabel(f"{n} ({pf.COEFF_CUSTOMARY_UNITS[i]})", fontsize=8)
            ax.grid(alpha=0.3)
            ax.set_ylim(-lim, lim)
            fg.mark_events(ax, c.events, c.scale, numbers=k < 2)
        break
    axes.ravel()[0].legend(fontsize=7, loc="lower right")
    for ax in axes[-1]:
        ax.set_xlabel(f"time ({c.unit})")
    fg.finish(fig, f"{c.title}: run 0, coefficient estimates against the truth", fg.notes(c))
    save_png(fig, path)
    return fig


def attitude_figure(out, path):
    """Platform attitude error (E, N, U, arcsec, log), rms over runs, of every method and of a multi-pass method's
    causal first pass (dashed), the scheme's roll phases marked. Returns the Figure."""
    c = fg.context(out.scenario, out.metrics, dict.fromkeys(out.outcomes, out.t))
    fig, axes = plt.subplots(3, 1, figsize=(8.5, 7.6), sharex=True)
    for name, oc in out.outcomes.items():
        for i, ax in enumerate(axes):
            ax.semilogy(out.t / c.scale, oc["phi_rms"][:, i] / units.ARCSEC, lw=1, color=c.colors[name], label=name)
            if oc.get("has_first_pass"):
                ax.semilogy(out.t / c.scale, oc["phi_rms_causal"][:, i] / units.ARCSEC, lw=0.8, ls="--",
                            color=c.colors[name], label=f"{name}, first (causal) pass")
    for i, ax in enumerate(axes):
        ax.set_ylabel(f"rms over runs of phi{'ENU'[i]} (arcsec)", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        fg.plain_log_ticks(ax)
        fg.mark_events(ax, c.events, c.scale, numbers=i == 0)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel(f"time ({c.unit})")
    fg.finish(fig, f"{c.title}: platform attitude error, rms over runs", fg.notes(c))
    save_png(fig, path)
    return fig


def _calibration_report(out, folder):
    m = out.metrics
    scn = out.scenario
    attitude_figure(out, folder / "attitude.png")
    calibration_figure(out, folder / "coefficients.png")
    extra = {}
    for name in out.outcomes:
        method = scn.calibrator(name)
        if hasattr(method, "report_figures"):
            for fname, cap in method.report_figures(folder, scn.platform.scaled(m["duration_s"]).scheme, scn.site.lat):
                extra.setdefault(fname, cap)
    rows = []
    for name, r in m["methods"].items():
        f = r["final_error_arcmin"]
        rows.append(f"| {name} | {f['E']['rms'] * 60:.2f} | {f['N']['rms'] * 60:.2f} | {f['U']['rms'] * 60:.2f} "
                    f"| {r.get('information_rank', '-')} | {r['wall_s']:.1f} |")
    groups = []
    for name, r in m["methods"].items():
        for g, v in r["groups"].items():
            claim = "-" if v["paper_below"] is None else f"< {v['paper_below']:g}"
            fp = r.get("first_pass", {}).get("groups", {}).get(g)
            first = "-" if fp is None else f"{fp['max_abs_error_mean']:.4g}"
            bound = f"{v['bound_max']:.3g}" if "bound_max" in v else "-"
            groups.append(f"| {name} | {g} | {v['max_abs_error_mean']:.4g} | {first} | {bound} | {claim} | {v['unit']} |")
    coeff = []
    for name, r in m["methods"].items():
        for n, c in r["coefficients"].items():
            coeff.append(f"| {name} | {n} | {c['error_mean']:.4g} | {c['error_std']:.4g} | {c['sigma_mean']:.4g} "
                         f"| {c['bound']:.3g} | {c['unit']} |" if "bound" in c else
                         f"| {name} | {n} | {c['error_mean']:.4g} | {c['error_std']:.4g} | {c['sigma_mean']:.4g} | - | {c['unit']} |")
    figs = "\n".join(f"![{cap}]({fn})\n" for fn, cap in extra.items())
    text = f"""# {m['scenario']}

{scn.description}

Runs: {m['runs']} (seed {m['seed']}{', quick size' if m['quick'] else ''}), scheme of {m['duration_s']:.0f} s,
latitude {np.degrees(scn.site.lat):.3f} deg. True coefficients and initial angles drawn per run from the
scenario's [platform] distribution; each method estimates them from the accelerometer outputs.

Platform attitude error at the end (rms over runs, arcsec) and the information-matrix rank of the scheme:

| method | phiE | phiN | phiU | information rank | wall (s) |
|---|---|---|---|---|---|
{chr(10).join(rows)}

Largest |mean estimation error| per coefficient group, beside the causal first pass alone, the largest
information bound in the group and the paper's claims (seed 002, 500 runs):

| method | group | here | first pass alone | information bound (largest) | paper | unit |
|---|---|---|---|---|---|---|
{chr(10).join(groups)}

![attitude error](attitude.png)

![coefficient estimates, run 0](coefficients.png)

{figs}
{_paper_section(out)}
Every coefficient (error mean and standard deviation over runs, the filter's mean predicted sigma, and the
information bound of the outputs, mean over runs: the sigma an efficient estimator would reach):

| method | coefficient | error mean | error std | sigma | information bound | unit |
|---|---|---|---|---|---|---|
{chr(10).join(coeff)}

Reproduce: `fusionbench run {m['scenario']} --runs {m['runs']} --seed {m['seed']}{' --quick' if m['quick'] else ''}`
"""
    write_metrics(folder / "metrics.json", m)
    with atomic_open(folder / "report.md") as fh:
        fh.write(text)
    return folder / "report.md"


def write_scenario_report(out, folder):
    """Write metrics.json, report.md and the figures of one run into ``folder``; returns report path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if getattr(out.scenario, "experiment", None) == "conformance":
        from .conformance_report import write_report

        return write_report(out, folder)
    if not hasattr(out, "limits"):  # a platform self-calibration experiment
        return _calibration_report(out, folder)
    m = out.metrics
    scn = out.scenario
    m["diverged"] = _diverged(out)
    fig_name = "errors.png"
    error_figure(out, folder / fig_name)
    azimuth_figure(out, folder / "azimuth.png")
    extra_figs = {}
    if scn.rmse_window_s is not None or scn.amplitude_windows_s:
        level_figure(out, folder / "level.png")
        extra_figs["level.png"] = "level errors against time"
    if any(oc.extra.get("series") for oc in out.outcomes.values()):
        series_figure(out, folder / "series.png")
        extra_figs["series.png"] = "series reported by the methods"
    extra_figs.update(_method_figures(out, folder))
    extra_md = "\n".join(f"![{cap}]({f})\n" for f, cap in extra_figs.items())
    level = "\n".join(f"| {n} | {r['level_rms_last_100s_arcmin']['E']:.3f} | {r['level_rms_last_100s_arcmin']['N']:.3f} |"
                      for n, r in m["methods"].items())
    methods_desc = "\n".join(f"- `{n}`: {oc.description}" for n, oc in out.outcomes.items())
    text = f"""# {m['scenario']}

{scn.description}

Runs: {m['runs']} (seed {m['seed']}{', quick size' if m['quick'] else ''}), duration {m['duration_s']:.0f} s at
{scn.rate_hz:g} Hz, latitude {np.degrees(scn.site.lat):.3f} deg, IMU `{scn.imu_spec.name}`
({scn.imu_spec.description}).

Final misalignment at the last sample, arcmin (mean and standard deviation over runs). {_limit_text(scn.kind)}

{_table(m, scn.kind)}

Methods:

{methods_desc}

Level errors over the last 100 s, RMS over runs and time (arcmin):

| method | phiE | phiN |
|---|---|---|
{level}

![misalignment vs time]({fig_name})

![azimuth error vs time](azimuth.png)

{_jump_section(m)}
{_window_section(out)}
{extra_md}
{_paper_section(out)}
Reproduce: `fusionbench run {m['scenario']} --runs {m['runs']} --seed {m['seed']}{' --quick' if m['quick'] else ''}`
"""
    write_metrics(folder / "metrics.json", m)
    with atomic_open(folder / "report.md") as fh:
        fh.write(text)
    return folder / "report.md"
