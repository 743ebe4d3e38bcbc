"""report.md and the scoreboard figure of a conformance matrix run (:mod:`fusionbench.experiments.conformance`)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from fusionbench.bench.run_metrics import write_metrics  # noqa: E402
from fusionbench.files.imufiles import atomic_open  # noqa: E402
from fusionbench.reports import figures as fg  # noqa: E402
from fusionbench.reports.figures import save_png  # noqa: E402


def _cell_text(c):
    if c["status"] == "not claimed":
        return "·"
    if c.get("refused"):
        return "refused ✓" if c["status"] == "pass" else "refused ✗"
    mark = ("" if c["status"] == "pass" else " ✗") + ("" if c.get("claimed", True) else " °")
    return f"{c['efficiency_U']:.2f}{mark}"


def _aiding_text(c):
    """A condition's aiding in a few words: the receiver's (kinds, rate, lever arm, latency, outage), the
    per-increment reference of a moving base, or "-" on a fixed base."""
    a = c.get("aiding")
    if a is None:
        return "velocity per sample" if c["base"] in ("moving", "drive") else "-"
    words = [f"{a['kinds']} {a['rate_hz']:g} Hz"]
    if "position" in a["kinds"]:
        words.append(f"{a['position_sigma_m']:g} m")
    if any(a["lever_arm_m"]):
        words.append(f"lever {np.linalg.norm(a['lever_arm_m']):.1f} m")
    if a["delay_s"]:
        words.append(f"{1e3 * a['delay_s']:.0f} ms late")
    if a["outage_s"]:
        words.append(f"{a['outage_s']:g}-s outage")
    return ", ".join(words)


def scoreboard_figure(m, path):
    """Conditions (rows) x methods (columns), coloured by efficiency over the method's threshold (log scale:
    green below 1, red above); R: refused, blank: not claimed; each passing cell shows its efficiency.
    Returns the Figure."""
    conds, methods = list(m["conditions"]), list(m["cells"])
    ratio = np.full((len(conds), len(methods)), np.nan)
    for j, n in enumerate(methods):
        for i, c in enumerate(conds):
            cell = m["cells"][n].get(c, {"status": "not claimed"})
            if "efficiency_U" in cell and not cell.get("refused"):
                ratio[i, j] = cell["efficiency_U"] / cell["efficiency_max"]
    fig, ax = plt.subplots(figsize=(max(7.5, 3.8 + 0.85 * len(methods)), 2.0 + 0.38 * len(conds)))
    im = ax.imshow(np.clip(ratio, 0.1, 10.0), cmap="RdYlGn_r", norm=LogNorm(0.1, 10.0), aspect="auto")
    for i, c in enumerate(conds):
        for j, n in enumerate(methods):
            cell = m["cells"][n].get(c, {"status": "not claimed"})
            if cell["status"] == "not claimed":
                continue
            txt = ("R" if cell["status"] == "pass" else "R!") if cell.get("refused") else f"{cell['efficiency_U']:.2g}"
            txt += "" if cell.get("claimed", True) else "°"
            if cell["status"] == "fail":
                txt += " ✗"
                ax.add_patch(plt.Rectangle((j - 0.46, i - 0.44), 0.92, 0.88, fill=False, ec="crimson", lw=1.5))
            ax.text(j, i, txt, ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(methods)), methods, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(conds)), conds, fontsize=8)
    ax.set_xlabel("method", fontsize=9)
    ax.set_ylabel("condition", fontsize=9)
    cb = fig.colorbar(im, ax=ax, fraction=0.08, pad=0.03, aspect=30)
    cb.set_ticks([0.1, 0.3, 1.0, 3.0, 10.0], labels=["0.1", "0.3", "1", "3", "10"])
    cb.set_label("efficiency / threshold (1: pass line)", fontsize=8)
    sb = m["scoreboard"]
    fg.finish(fig, f"{m['scenario']}: azimuth efficiency, {m['runs']} runs per cell; {sb['passed']} of "
              f"{sb['total']} cells pass", ["Efficiency: RMS over runs of (final azimuth error - limit) over the "
                                            "attainable bound (1 is optimal). Red box: fails (efficiency or level); "
                                            "R: refused; blank: not claimed; °: run outside the method's claim."])
    save_png(fig, path)
    return fig


def write_report(out, folder):
    """Write metrics.json, report.md and scoreboard.png of a conformance run into ``folder``; returns report path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    m, matrix = out.metrics, out.scenario
    scoreboard_figure(m, folder / "scoreboard.png")
    methods, conds = list(m["cells"]), list(m["conditions"])
    head = "| condition | " + " | ".join(f"`{n}`" for n in methods) + " |"
    rows = [head, "|---" * (len(methods) + 1) + "|"]
    for c in conds:
        rows.append(f"| {c} | " + " | ".join(_cell_text(m["cells"][n].get(c, {"status": "not claimed"}))
                                            for n in methods) + " |")
    board = ["| method | cells passed / claimed | worst efficiency | threshold |", "|---|---|---|---|"]
    for n, b in m["scoreboard"]["methods"].items():
        worst = "-" if b["worst_efficiency"] is None else f"{b['worst_efficiency']:.2f}"
        board.append(f"| `{n}` | {b['passed']} / {b['claimed']} | {worst} | {b['efficiency_max']:g} |")
    cond_rows = ["| condition | base | latitude (deg) | heading (deg) | IMU | reference noise (m/s) | aiding | limit U "
                 "(arcmin) | bound E / N / U (arcmin) | settling band (arcmin) |", "|---" * 10 + "|"]
    for name, c in m["conditions"].items():
        lim = c.get("limit_arcmin", {}).get("U")
        b = c["bound_arcmin"]
        cond_rows.append(f"| {name} | {c['base']} | {c['lat_deg']:g} | {c['heading_deg']:g} | {c['imu']} | "
                         f"{c['vref_sigma_mps']:g} | {_aiding_text(c)} | {'-' if lim is None else f'{lim:.2f}'} | "
                         f"{b['E']:.3f} / {b['N']:.3f} / {b['U']:.2f} | {c['settling_band_arcmin']:.1f} |"
                         + (" refuse expected" if c["expect"] == "refuse" else "")
                         + (f" init given {c['init_error_deg']:g} deg off in azimuth"
                            if c.get("init_error_deg") is not None else ""))
    fails = [f"- `{n}` on {c}: {cell.get('message', '')}" + ("" if cell.get("claimed", True) else " (outside its claim)")
             for n in methods for c, cell in m["cells"][n].items() if cell["status"] == "fail"]
    unclaimed_note = (", ° a cell outside the method's claim, run because the file asks for every method everywhere "
                      "(not counted in its passed / claimed)" if getattr(matrix, "run_unclaimed", False) else "")
    settle = ["| method | " + " | ".join(conds) + " |", "|---" * (len(conds) + 1) + "|"]
    for n in methods:
        settle.append(f"| `{n}` | " + " | ".join(
            f"{m['cells'][n][c]['settling_mean_s']:.0f}" if "settling_mean_s" in m["cells"][n].get(c, {}) else "·"
            for c in conds) + " |")
    spread = 1.0 / np.sqrt(2.0 * m["runs"])  # relative standard deviation of an RMS over that many runs
    scatter = (f" With {m['runs']} runs an optimal method's efficiency scatters by +-{100 * spread:.0f} % (1 / sqrt(2 runs)), "
               f"and every method on a condition sees the same recordings: read the verdicts at 20 runs or more."
               if m["runs"] < 20 else "")
    text = f"""# {m['scenario']}

{matrix.description}

Runs: {m['runs']} per condition (seed {m['seed']}{', quick size' if m['quick'] else ''}), {m['duration_s']:.0f} s at
{matrix.rate_hz:g} Hz, every method from its own start (no initial guess; a condition with an init error hands
each the truth turned by that much, and a method that declares a smaller capture range passes by refusing it),
given the condition's IMU as its model.
A cell is the azimuth **efficiency**: the RMS over runs of (final azimuth error - theoretical limit) divided by the
attainable bound (the standard deviation an optimal estimator reaches with this IMU's noise; 1 is optimal). A cell
passes when the efficiency is at most the method's threshold and the level errors are within
{matrix.level_tolerance_arcmin:g} arcmin (RMS over runs) of the limit, or within the threshold times the level bound
where that is larger (the sensors' noise alone leaves an optimal estimator further off); where the gyro bias hides
the earth rate ("refuse expected") the only right answer is to refuse. ✗ marks a failure, · a condition the method
does not claim{unclaimed_note}.

**{m['scoreboard']['passed']} of {m['scoreboard']['total']} cells pass.**{scatter}

{chr(10).join(board)}

{chr(10).join(rows)}

![scoreboard](scoreboard.png)

Failures:

{chr(10).join(fails) if fails else '- none'}

Conditions (limit at the last sample; bound at the end of the record):

{chr(10).join(cond_rows)}

Settling, mean over runs (s): the first time after which |phiU - limit| stays within the condition's band until
the end (smoothers: on prefixes of the record every 25 s):

{chr(10).join(settle)}

The contract figures of metrics.json (`limits_arcmin`, each method's `final_error_arcmin`) are those of the first
condition, `{m['reference_condition']}`; every cell is under `cells`.

Reproduce: `fusionbench run {m['scenario']} --runs {m['runs']} --seed {m['seed']}{' --quick' if m['quick'] else ''}`
"""
    write_metrics(folder / "metrics.json", m)
    with atomic_open(folder / "report.md") as fh:
        fh.write(text)
    return folder / "report.md"
