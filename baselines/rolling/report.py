"""report.md and figures of a platform self-calibration run (seed 002's (Ding, rolling-platform self-calibration)
rolling experiment): the platform attitude error, run 0's coefficient estimates against truth, and the tables of
coefficient groups beside the paper's claims."""

from __future__ import annotations

import numpy as np

from fusionbench.bench.run_metrics import write_metrics
from fusionbench.files.imufiles import atomic_open
from fusionbench.reports import figures as fg
from fusionbench.reports.figure_events import mark_events
from fusionbench.reports.figures import plt, save_png
from fusionbench.reports.report import paper_section
from fusionbench.simulation import units

from . import model


def calibration_figure(out, path, names=("D0_X", "DI_X", "DIO_X", "G_XY", "K0_Y", "K1_Y", "A_YX", "KT_X")):
    """Run 0's estimates of a few coefficients against truth (customary units): the final pass with its 3-sigma
    envelope shaded; for a multi-pass method its causal first pass too (the convergence a real-time filter shows)
    as a line with its envelope dotted, unshaded; the scheme's roll phases marked. Returns the Figure."""


    c = fg.context(out.scenario, out.metrics, dict.fromkeys(out.outcomes, out.t))
    fig, axes = plt.subplots(len(names) // 2, 2, figsize=(10, 1.2 + 2.2 * (len(names) // 2)), sharex=True)
    t = out.t / c.scale
    for name, oc in out.outcomes.items():
        if oc["x"] is None:
            continue
        for k, (ax, n) in enumerate(zip(axes.ravel(), names)):
            i = model.COEFF_NAMES.index(n)
            sc, truth = model.COEFF_SCALE[i], oc["truth"][0, i] / model.COEFF_SCALE[i]
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
            ax.set_ylabel(f"{n} ({model.COEFF_CUSTOMARY_UNITS[i]})", fontsize=8)
            ax.grid(alpha=0.3)
            ax.set_ylim(-lim, lim)
            mark_events(ax, c.events, c.scale, numbers=k < 2)
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
        mark_events(ax, c.events, c.scale, numbers=i == 0)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel(f"time ({c.unit})")
    fg.finish(fig, f"{c.title}: platform attitude error, rms over runs", fg.notes(c))
    save_png(fig, path)
    return fig


def write_report(out, folder):
    """Write metrics.json, report.md and the figures of a calibration run into ``folder``; returns report.md."""
    m = out.metrics
    scn = out.scenario
    attitude_figure(out, folder / "attitude.png")
    calibration_figure(out, folder / "coefficients.png")
    extra = {}
    for name in out.outcomes:
        method = scn.method(name)
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
{paper_section(out)}
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
