"""report.md and its figures (matplotlib, Agg backend) for a scenario run (the overview of several:
:mod:`fusionbench.overview`).

Each scenario folder holds ``metrics.json``, ``report.md`` and PNG figures: the misalignment
(E, N, U) against time for every method, Monte Carlo mean and the 1-sigma band, with the
theoretical limits drawn as dashed lines.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from . import units  # noqa: E402
from .io import atomic_open  # noqa: E402
from .runner import write_metrics  # noqa: E402


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


def error_figure(out, path):
    """Misalignment vs time, one panel per axis (arcmin), every method, limits dashed."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    lim = out.limits / units.ARCMIN
    for name, oc in out.outcomes.items():
        phi = oc.phi / units.ARCMIN
        mean, std = phi.mean(axis=0), phi.std(axis=0)
        for i, ax in enumerate(axes):
            (line,) = ax.plot(oc.t, mean[:, i], label=name)
            ax.fill_between(oc.t, mean[:, i] - std[:, i], mean[:, i] + std[:, i], color=line.get_color(), alpha=0.2)
    for i, ax in enumerate(axes):
        ax.axhline(lim[i], color="k", ls="--", lw=1, label="limit" if i == 0 else None)
        ax.set_ylabel(f"phi{'ENU'[i]} (arcmin)")
        ax.grid(alpha=0.3)
        # symmetric-log scale: large initial errors and arcsecond-level settling on one axis
        ax.set_yscale("symlog", linthresh=max(0.1, 2 * abs(lim[i])))
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{out.metrics['scenario']}: misalignment, Monte Carlo mean and 1-sigma ({out.metrics['runs']} runs)")
    fig.tight_layout()
    save_png(fig, path)


def azimuth_figure(out, path):
    """Azimuth error vs time for every method (like seed 000's Figs. 3 and 4): above, the RMS over
    runs on a log scale (no wrap-around near 180 deg); below, mean and 1 sigma from the scenario's
    ``zoom_from_s``, with the limit and the settling band."""
    fig, (full, zoom) = plt.subplots(2, 1, figsize=(8, 7))
    lim = out.limits[2] / units.ARCMIN
    t0 = out.scenario.zoom_from_s
    band = out.scenario.settling_band_arcmin
    for name, oc in out.outcomes.items():
        u = oc.phi[..., 2] / units.ARCMIN
        (line,) = full.semilogy(oc.t, np.sqrt(np.mean(u**2, axis=0)), label=name)
        sel = oc.t >= t0
        mean, std = u[:, sel].mean(axis=0), u[:, sel].std(axis=0)
        zoom.plot(oc.t[sel], mean, color=line.get_color(), label=name)
        zoom.fill_between(oc.t[sel], mean - std, mean + std, color=line.get_color(), alpha=0.2)
    full.axhline(abs(lim), color="k", ls="--", lw=1, label="|limit|")
    full.set_ylabel("rms |phiU| (arcmin)")
    zoom.axhline(lim, color="k", ls="--", lw=1, label="limit")
    zoom.axhspan(lim - band, lim + band, color="k", alpha=0.06, label=f"limit +- {band:g} arcmin")
    zoom.set_ylabel("phiU (arcmin)")
    zoom.set_xlabel("time (s)")
    for ax in (full, zoom):
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    full.set_title(f"{out.metrics['scenario']}: azimuth error, {out.metrics['runs']} runs\n"
                   f"above: rms over runs; below: mean and 1 sigma from {t0:g} s", fontsize=10)
    fig.tight_layout()
    save_png(fig, path)


def level_figure(out, path):
    """Level misalignment (phiE, phiN, arcmin) against time in hours, Monte Carlo mean of every method, with
    the scenario's RMSE window shaded (like seed 004's Figs. 9-11)."""
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for name, oc in out.outcomes.items():
        mean = oc.phi.mean(axis=0) / units.ARCMIN
        for i, ax in enumerate(axes):
            ax.plot(oc.t / 3600.0, mean[:, i], lw=1, label=name)
    win = out.scenario.rmse_window_s
    for i, ax in enumerate(axes):
        if win is not None:
            ax.axvspan(win[0] / 3600.0, win[1] / 3600.0, color="k", alpha=0.08,
                       label="RMSE window" if i == 0 else None)
        ax.set_ylabel(f"phi{'EN'[i]} (arcmin)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (h)")
    fig.suptitle(f"{out.metrics['scenario']}: level errors, mean of {out.metrics['runs']} runs", fontsize=10)
    fig.tight_layout()
    save_png(fig, path)


def series_figure(out, path):
    """Series a method reports about itself (e.g. a damping coefficient), mean over runs, against hours."""
    names = [(n, k) for n, oc in out.outcomes.items() for k in oc.extra.get("series", {})]
    fig, ax = plt.subplots(figsize=(9, 3.5))
    for n, k in names:
        oc = out.outcomes[n]
        ax.plot(oc.t / 3600.0, oc.extra["series"][k].mean(axis=0), lw=1, label=f"{n}: {k}")
    ax.set_xlabel("time (h)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8, ncol=2)
    ax.set_title(f"{out.metrics['scenario']}: series reported by the methods, mean over runs", fontsize=10)
    fig.tight_layout()
    save_png(fig, path)


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


def _table(m):
    lim = m["limits_arcmin"]
    rows = ["| method | phiE mean (std) | phiN mean (std) | phiU mean (std) | phiU rms | settling U (s, band "
            f"{next(iter(m['methods'].values()))['settling_time_s']['band_arcmin'] if m['methods'] else ''} arcmin) "
            "| wall (s) |", "|---|---|---|---|---|---|---|",
            f"| *theoretical limit* | {lim['E']:.3f} | {lim['N']:.3f} | {lim['U']:.3f} | | | |"]
    for name, r in m["methods"].items():
        f = r["final_error_arcmin"]
        s = r["settling_time_s"]["U"]
        rows.append(f"| {name} | {f['E']['mean']:.3f} ({f['E']['std']:.3f}) | {f['N']['mean']:.3f} ({f['N']['std']:.3f}) "
                    f"| {f['U']['mean']:.3f} ({f['U']['std']:.3f}) | {f['U']['rms']:.3f} | {s['mean']:.1f} "
                    f"| {r['wall_s']:.2f} |")
    return "\n".join(rows)


def calibration_figure(out, path, names=("D0_X", "DI_X", "DIO_X", "G_XY", "K0_Y", "K1_Y", "A_YX", "KT_X")):
    """Run 0's estimates of a few coefficients against truth with their 3-sigma envelopes (customary units);
    for a multi-pass method its causal first pass too (the convergence a real-time filter shows)."""
    from . import platform as pf

    fig, axes = plt.subplots(len(names) // 2, 2, figsize=(10, 2.2 * (len(names) // 2)), sharex=True)
    for name, oc in out.outcomes.items():
        if oc["x"] is None:
            continue
        hists = [(f"{name}", oc["x"], oc["sig_hist"])]
        if oc.get("x_causal") is not None:
            hists = [(f"{name}, first (causal) pass", oc["x_causal"], oc["sig_causal"]),
                     (f"{name}, final pass", oc["x"], oc["sig_hist"])]
        for ax, n in zip(axes.ravel(), names):
            i = pf.COEFF_NAMES.index(n)
            sc = pf.COEFF_SCALE[i]
            lim = abs(oc["truth"][0, i] / sc) * 3 + 1e-12
            for label, x, sg in hists:
                est, sig = x[:, i] / sc, sg[:, i] / sc
                (line,) = ax.plot(out.t, est, lw=1, label=f"{label} estimate")
                ax.fill_between(out.t, est - 3 * sig, est + 3 * sig, color=line.get_color(), alpha=0.15)
                lim = max(lim, abs(oc["truth"][0, i] / sc) * 3 + 3 * sig[-1])
            ax.axhline(oc["truth"][0, i] / sc, color="k", ls="--", lw=1, label="truth")
            ax.set_ylabel(f"{n} ({pf.COEFF_CUSTOMARY_UNITS[i]})", fontsize=8)
            ax.grid(alpha=0.3)
            ax.set_ylim(-lim, lim)
        break
    axes.ravel()[0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"{out.metrics['scenario']}: run 0, estimates with 3-sigma envelopes", fontsize=10)
    fig.tight_layout()
    save_png(fig, path)


def _calibration_report(out, folder):
    m = out.metrics
    scn = out.scenario
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for name, oc in out.outcomes.items():
        rms = oc["phi_rms"] / units.ARCSEC
        for i, ax in enumerate(axes):
            line, = ax.semilogy(out.t, rms[:, i], lw=1, label=name)
            if oc.get("has_first_pass"):
                first = oc["phi_rms_causal"][:, i] / units.ARCSEC
                ax.semilogy(out.t, first, lw=0.8, ls="--", color=line.get_color(), label=f"{name}, first (causal) pass")
    for i, ax in enumerate(axes):
        ax.set_ylabel(f"rms phi{'ENU'[i]} (arcsec)")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{m['scenario']}: platform attitude error, rms over {m['runs']} runs", fontsize=10)
    fig.tight_layout()
    save_png(fig, folder / "attitude.png")
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

Final misalignment at the last sample, arcmin (mean and standard deviation over runs). The limit is what
any stationary alignment reaches with this IMU's constant biases: level = accelerometer bias / g,
azimuth = -east gyro bias / (earth rate cos L) + tan L east accelerometer bias / g.

{_table(m)}

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
