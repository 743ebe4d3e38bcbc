"""A scenario's report.md and its azimuth figure: the runs and the duration actually run, "never settled", the
attainable bound and the efficiency beside the final errors, the optimal estimator drawn, a user's method by its
name."""

import json

import numpy as np
import pytest

from fusionbench.bench import scenarios
from fusionbench.bench.experiment import run_scenario, write_scenario_report
from fusionbench.reports.report import _table, azimuth_figure
from fusionbench.scoring import bound
from fusionbench.simulation import units

TOML = """
name = "tiny-report"
description = "tiny static scenario for the report tests, 30 s"
duration_s = 30.0
rate_hz = 50.0
runs = 3
methods = ["coarse"]
[quick]
duration_s = 20.0
runs = 2
[site]
lat_deg = 34.0
[imu]
preset = "tactical"
[metrics]
settling_band_arcmin = 0.001
"""

ST = {"mean": 1.0, "std": 0.1, "rms": 1.0, "max_abs": 1.0}


def _method(settled, mean=120.0, settled_mean=None, eff=None):
    st = {"U": dict(ST, mean=mean), "band_arcmin": 2.0}
    if settled_mean is not None:
        st["U_settled"] = dict(ST, mean=settled_mean)
    r = {"final_error_arcmin": {ax: ST for ax in "ENU"}, "settling_time_s": st, "settled_fraction_U": settled,
         "wall_s": 1.0}
    return r if eff is None else dict(r, efficiency_U=eff)


def _rows(text):
    """The first table's row of each method (or label) of ``text``: later tables (the level one) repeat the names."""
    rows = {}
    for line in text.splitlines():
        if line.startswith("| "):
            rows.setdefault(line.split(" | ")[0].strip("| *"), line)
    return rows


# ------------------------------------------------------------------------------------ the table, synthetic
def test_the_settling_column_says_never_settled_and_how_many_runs_settled():
    m = {"limits_arcmin": {"E": 0.1, "N": 0.1, "U": -1.0}, "runs": 4,
         "methods": {"never": _method(0.0), "some": _method(0.5, 80.0, 40.0), "all": _method(1.0, 35.0, 35.0)}}
    rows = _rows(_table(m, "alignment"))
    assert "| never settled |" in rows["never"] and "120.0" not in rows["never"]
    assert "| 40.0 (2 of 4 settled) |" in rows["some"]  # the settled runs' mean, not 80 with the record's end
    assert "| 35.0 |" in rows["all"]


def test_the_bound_and_the_efficiency_stand_beside_the_final_errors_where_there_is_a_bound():
    m = {"limits_arcmin": {"E": 0.1, "N": 0.1, "U": -1.0}, "runs": 4, "methods": {"kf": _method(1.0, eff=1.234)},
         "bound_arcmin": {"E": 0.02, "N": 0.03, "U": 7.5}}
    text = _table(m, "alignment")
    rows = _rows(text)
    assert "efficiency U" in text.splitlines()[0]
    assert rows["attainable bound (std about the limit)"].startswith(
        "| *attainable bound (std about the limit)* | (0.020) | (0.030) | (7.500) | | 1 |")
    assert "| 1.23 |" in rows["kf"]
    assert all(line.count("|") == text.splitlines()[0].count("|") for line in text.splitlines()[:5])
    # on a moving base the limit is the optimal estimator's, and there is no settling band
    moving = _table(m, "moving-alignment")
    assert "limit of an optimal estimator" in moving and "theoretical limit" not in moving
    assert "settling" not in moving and "| 1.23 |" in moving
    # without a bound (a navigation scenario): neither
    del m["bound_arcmin"]
    assert "efficiency" not in _table(m, "alignment") and "attainable bound" not in _table(m, "alignment")


# ------------------------------------------------------------------------------- a quick run, end to end
@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("report")
    p = folder / "tiny.toml"
    p.write_text(TOML)
    scn = scenarios.load(p)
    out = run_scenario(scn, quick=True, seed=3, progress=False)
    write_scenario_report(out, folder / "out")
    return scn, out, folder / "out"


def test_a_quick_run_is_headed_by_the_runs_and_the_duration_it_ran(quick_run):
    scn, out, folder = quick_run
    text = (folder / "report.md").read_text()
    assert text.startswith("# tiny-report: 2 runs of 20 s (quick)\n")
    assert "This run: 2 runs of 20 s (the quick size; the full size is 3 runs of 30 s)" in text
    m = json.loads((folder / "metrics.json").read_text())
    assert (m["runs"], m["duration_s"], m["quick"]) == (2, 20.0, True)
    fig = azimuth_figure(out, folder / "again.png")
    assert "tiny-report (alignment, 2 runs of 20 s, quick)" in " ".join(fig.get_suptitle().split())


def test_the_bound_and_the_efficiency_of_a_run(quick_run):
    # the bound of the scenario's fixed base with its reference (none: the zero-velocity assumption, exact), and
    # the efficiency as the conformance matrix defines it, from the runs' final errors and the limit
    scn, out, folder = quick_run
    m = json.loads((folder / "metrics.json").read_text())
    _, b = bound.attainable_bound(scn.imu_spec, 20.0, trajectory=scn.trajectory(20.0), vref_sigma=0.0,
                                  vref_dt=scn.dt)
    assert [m["bound_arcmin"][ax] for ax in "ENU"] == pytest.approx(b[-1] / units.ARCMIN, rel=1e-9)
    err = out.outcomes["coarse"].per_run["phi_end"][:, 2] - out.limits[2]
    eff = np.sqrt(np.mean(err**2)) / b[-1, 2]
    assert m["methods"]["coarse"]["efficiency_U"] == pytest.approx(eff, rel=1e-9)
    text = (folder / "report.md").read_text()
    assert f"| {eff:.2f} |" in _rows(text)["coarse"]
    # a 0.001-arcmin band: no run settles, and the report says so
    assert m["methods"]["coarse"]["settled_fraction_U"] == 0.0 and "never settled" in _rows(text)["coarse"]
    assert "U_settled" not in m["methods"]["coarse"]["settling_time_s"]


def test_the_azimuth_figure_draws_the_optimal_estimator(quick_run):
    scn, out, folder = quick_run
    fig = azimuth_figure(out, folder / "again.png")
    lines = {ln.get_label(): ln for ax in fig.axes for ln in ax.lines}
    assert {"optimal estimator", "limit +- bound"} <= set(lines)
    # its rms at the end: sqrt(limit^2 + bound^2)
    b, lim = out.metrics["bound_arcmin"]["U"], out.metrics["limits_arcmin"]["U"]
    assert lines["optimal estimator"].get_ydata()[-1] == pytest.approx(np.hypot(lim, b), rel=1e-3)
