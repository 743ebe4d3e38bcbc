"""The overview of a ``fusionbench run``: ``index.html`` (one self-contained page) and ``index.md``.

The page holds the scoreboard of every method across every scenario, each cell the figure its scenario is
about (:func:`headline`), links to every scenario's page (``report.html``, an HTML rendering of its
``report.md``, written beside it by :func:`fusionbench.files.pages.write_page`) and the run's provenance. Figures are
linked relatively, nothing is fetched from a network and the page needs no JavaScript: copy the folder anywhere.
"""

from __future__ import annotations

import html
import re
from dataclasses import dataclass, field
from pathlib import Path

from fusionbench.bench.experiment import load_experiment
from fusionbench.files.imufiles import atomic_open
from fusionbench.files.pages import page, write_page

#: A cell within this factor of its column's best is drawn good, within POOR_FACTOR fair, beyond it poor.
GOOD_FACTOR = 1.25
POOR_FACTOR = 3.0



@dataclass
class Column:
    """One scenario's column of the scoreboard: the figure it is about, per method.

    ``values`` maps a method to ``(number, text)``: the number ranks the cell (smaller is better unless
    ``higher_is_better``), the text is what a reader sees; ``number`` None leaves the cell unranked."""

    scenario: str
    kind: str
    figure: str
    note: str = ""
    higher_is_better: bool = False
    values: dict = field(default_factory=dict)
    short: str = ""
    #: A column of claims: its numbers are ratios to a claim, a cell good within 1 (met), else fair within
    #: POOR_FACTOR, or poor at once when ``strict``; None: cells are graded against the column's best.
    claim: bool = False
    strict: bool = False


def _rms_about(stat, centre):
    """RMS over runs of (x - centre) from a figure's mean and standard deviation over runs."""
    return float((stat["std"] ** 2 + (stat["mean"] - centre) ** 2) ** 0.5)


def headline(kind, metrics, has_init=False, experiment="alignment"):
    """The scoreboard column of one scenario: the figure the scenario is about, for every method.

    Parameters
    ----------
    kind : str
        The scenario's kind (:data:`fusionbench.bench.scenarios.SCENARIO_KINDS`).
    metrics : dict
        The scenario's metrics.json content.
    has_init : bool
        Whether the methods start from a prescribed initial misalignment (the figure is then the settling time).
    experiment : str
        The scenario's experiment; one with a ``headline(metrics)`` of its own gives the column.

    Returns
    -------
    Column
        alignment: RMS over runs of the final azimuth error about the theoretical limit (arcmin), or the
        azimuth settling time (s) from a prescribed initial error; a noise jump: the azimuth RMS inside the
        jump window (arcmin); moving-alignment: the final azimuth RMS against the truth (arcmin);
        navigation: the level RMSE in the scenario's window (arcmin, with the reduction in the note);
        another experiment's own column (e.g. the conformance matrix: claimed cells passed and the worst azimuth
        efficiency).
    """
    name, methods = metrics["scenario"], metrics["methods"]
    exp = load_experiment(experiment)
    if hasattr(exp, "headline"):  # an experiment that scores its own figure (a conformance matrix, a calibration)
        return exp.headline(metrics)
    if kind == "navigation":
        note = f"reduction {metrics['reduction_percent']:.1f} %" if "reduction_percent" in metrics else ""
        col = Column(name, kind, "level RMSE in the window (arcmin)", note, short="level RMSE, arcmin")
        for meth, r in methods.items():
            w = r.get("window_rmse_arcmin")
            col.values[meth] = (w["level"], f"{w['level']:.3f}") if w else (None, "-")
        return col
    if any("jump" in r for r in methods.values()):
        a, b = next(r["jump"]["window_s"] for r in methods.values() if "jump" in r)
        col = Column(name, kind, f"phiU RMS in the jump window {a:g}-{b:g} s (arcmin)", short="phiU in jump, arcmin")
        for meth, r in methods.items():
            v = r.get("jump", {}).get("rms_arcmin", {}).get("during", {}).get("U")
            col.values[meth] = (v, f"{v:.2f}") if v is not None else (None, "-")
        return col
    if kind == "moving-alignment":
        col = Column(name, kind, "final phiU RMS against the truth (arcmin)", short="phiU RMS, arcmin")
        for meth, r in methods.items():
            v = r["final_error_arcmin"]["U"]["rms"]
            col.values[meth] = (v, f"{v:.2f}")
        return col
    if has_init:
        band = next(iter(methods.values()))["settling_time_s"]["band_arcmin"] if methods else 0
        col = Column(name, kind, f"azimuth settling, mean (s, {band:g} arcmin band)", short="settling, s")
        for meth, r in methods.items():
            v, frac = r["settling_time_s"]["U"]["mean"], r.get("settled_fraction_U", 1.0)
            col.values[meth] = (v, f"{v:.0f}" + (f" ({frac:.0%} of runs settle)" if frac < 1 else ""))
        return col
    lim = metrics["limits_arcmin"]["U"]
    col = Column(name, kind, "final phiU RMS about the limit (arcmin)", f"limit {lim:.2f} arcmin",
                 short="phiU about limit, arcmin")
    for meth, r in methods.items():
        v = _rms_about(r["final_error_arcmin"]["U"], lim)
        col.values[meth] = (v, f"{v:.2f}")
    return col


def _flag_diverged(col, metrics):
    """A method the report found diverging (metrics.json ``diverged``) reads so in its cell and is ranked last."""
    for meth in metrics.get("diverged", []):
        if meth in col.values:
            col.values[meth] = (float("inf"), f"{col.values[meth][1]} (diverged)")
    return col


def grade(col, method):
    """``good``, ``fair``, ``poor`` or ``none``: a cell against its column's best (GOOD_FACTOR, POOR_FACTOR);
    in a column of claims (``Column.claim``) good when the claim is met (value <= 1)."""
    value = col.values.get(method, (None, ""))[0]
    if value is None:
        return "none"
    if col.claim:
        return "good" if value <= 1.0 else "poor" if col.strict or value > POOR_FACTOR else "fair"
    if value == float("inf"):
        return "poor"
    ranked = [v for v, _ in col.values.values() if v is not None and v != float("inf")] or [value]
    best = max(ranked) if col.higher_is_better else min(ranked)
    ratio = (best / value if value else float("inf")) if col.higher_is_better else (value / best if best else
                                                                                    (1.0 if value == 0 else 10.0))
    return "good" if ratio <= GOOD_FACTOR else "fair" if ratio <= POOR_FACTOR else "poor"


def _methods(columns):
    seen = {}
    for col in columns:
        for m in col.values:
            seen.setdefault(m, None)
    return list(seen)


def _first_image(report_md):
    found = re.search(r"!\[[^\]]*\]\(([^)\s]+)\)", Path(report_md).read_text(encoding="utf-8"))
    return found.group(1) if found else None


def _scoreboard_html(columns):
    methods = _methods(columns)
    head = "".join(f'<th title="{html.escape(c.figure)}"><a href="{html.escape(c.scenario)}/report.html">'
                   f"{html.escape(c.scenario)}</a><br><small>{html.escape(c.short or c.figure)}</small></th>"
                   for c in columns)
    rows = []
    for m in methods:
        cells = "".join(f'<td class="{grade(c, m)}">{html.escape(c.values[m][1])}</td>' if m in c.values else
                        '<td class="none">·</td>' for c in columns)
        rows.append(f"<tr><td><code>{html.escape(m)}</code></td>{cells}</tr>")
    legend = "".join(f"<li><b>{html.escape(c.scenario)}</b>: {html.escape(c.figure)}"
                     + (f"; {html.escape(c.note)}" if c.note else "") + "</li>" for c in columns)
    return (f'<div class="scroll"><table id="scoreboard">\n<tr><th>method</th>{head}</tr>\n' + "\n".join(rows)
            + f"\n</table></div>\n<p>The columns:</p>\n<ul>{legend}</ul>")


def _provenance_rows(prov, wall_total):
    if not prov:
        return "<p>No provenance recorded.</p>"
    items = [("fusionbench", prov.get("fusionbench")),
             ("git commit", (prov.get("git_commit") or "not a checkout") + (" (uncommitted changes)" if prov.get("git_dirty")
                                                                           else "")),
             ("date (UTC)", prov.get("date_utc")), ("command", prov.get("command")),
             ("seed", prov.get("seed")), ("size", "--quick" if prov.get("quick") else "default"),
             ("wall time of the whole run", f"{wall_total:.0f} s" if wall_total is not None else None),
             ("Python", prov.get("python")), ("platform", prov.get("platform")), ("CPUs", prov.get("cpus")),
             ("libraries", ", ".join(f"{k} {v}" for k, v in (prov.get("libraries") or {}).items()))]
    return "<table>\n" + "\n".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>"
                                   for k, v in items if v is not None) + "\n</table>"


def _scenario_sections(folder, entries):
    parts = []
    for scn_name, meta, report_md in entries:
        rel = Path(report_md).relative_to(folder).parent.as_posix()
        img = _first_image(report_md)
        prov = meta.get("provenance", {})
        wall = f", {prov['wall_s']:.0f} s" if "wall_s" in prov else ""
        parts.append(f'<h3 id="{html.escape(scn_name)}"><a href="{rel}/report.html">{html.escape(scn_name)}</a></h3>\n'
                     f"<p>{html.escape(meta.get('description', ''))}<br><small>{meta['runs']} runs of "
                     f"{meta['duration_s']:.0f} s{wall} · <a href=\"{rel}/report.md\">report.md</a> · "
                     f'<a href="{rel}/metrics.json">metrics.json</a></small></p>'
                     + (f'\n<p><a href="{rel}/report.html"><img class="thumb" src="{rel}/{img}" '
                        f'alt="{html.escape(scn_name)}: {html.escape(img)}"></a></p>' if img else ""))
    return "\n".join(parts)


def _scoreboard_md(columns):
    methods = _methods(columns)
    lines = ["| method | " + " | ".join(f"[{c.scenario}]({c.scenario}/report.md)" for c in columns) + " |",
             "|---" * (len(columns) + 1) + "|",
             "| *figure* | " + " | ".join(c.figure + (f"; {c.note}" if c.note else "") for c in columns) + " |"]
    for m in methods:
        lines.append(f"| `{m}` | " + " | ".join(c.values[m][1] if m in c.values else "" for c in columns) + " |")
    return "\n".join(lines)


def write_overview(folder, results, wall_total=None):
    """Write ``index.html`` and ``index.md`` over the scenario folders of a run; returns the HTML path.

    Parameters
    ----------
    folder : path
        The run's output folder; each scenario's report is in ``folder/<scenario>/report.md``.
    results : list of (scenario, metrics, report_md)
        Per scenario: its :class:`fusionbench.bench.scenarios.Scenario` (or conformance matrix), its metrics.json
        content (with ``provenance``) and the path of its report.md.
    wall_total : float, optional
        Wall time of the whole run, s.
    """
    folder = Path(folder)
    columns, entries = [], []
    for scn, metrics, report_md in results:
        columns.append(_flag_diverged(headline(scn.kind, metrics, scn.init_misalignment is not None,
                                               scn.experiment), metrics))
        entries.append((metrics["scenario"], {"description": scn.description, **metrics}, report_md))
        if not Path(report_md).with_suffix(".html").exists():
            write_page(report_md)
    prov = results[0][1].get("provenance", {}) if results else {}
    body = (f"<h1>fusionbench report</h1>\n<p>{len(columns)} scenarios, {len(_methods(columns))} methods. Each cell is "
            "the figure its scenario is about (the column head names it); green within "
            f"{GOOD_FACTOR:g}x of the column's best, amber within {POOR_FACTOR:g}x, red beyond (conformance: red when a "
            "claimed cell failed; calibration: green within the paper's claim). A dot: the method was not run there. "
            "Every scenario page has the table, the figures and the paper's figures beside ours.</p>\n"
            f"<h2>Scoreboard</h2>\n{_scoreboard_html(columns)}\n<h2>Scenarios</h2>\n"
            f"{_scenario_sections(folder, entries)}\n<h2>Provenance</h2>\n{_provenance_rows(prov, wall_total)}")
    path = folder / "index.html"
    with atomic_open(path) as fh:
        fh.write(page("fusionbench report", body))
    md = ["# fusionbench report", "", "Scoreboard: each cell is the figure its scenario is about. The same as a page: "
          "[index.html](index.html).", "", _scoreboard_md(columns), ""]
    with atomic_open(folder / "index.md") as fh:
        fh.write("\n".join(md))
    return path
