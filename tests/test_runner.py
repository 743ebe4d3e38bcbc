"""Scenarios as data, the Monte Carlo runner's determinism, the report and the regression check."""

import json

import numpy as np
import pytest

from fusionbench import scenarios
from fusionbench.check import compare
from fusionbench.report import write_scenario_report
from fusionbench.runner import run_scenario

TOML = """
name = "tiny"
description = "tiny static test scenario"
duration_s = 30.0
rate_hz = 50.0
runs = 3
methods = ["coarse"]
[site]
lat_deg = -45.0
[attitude]
heading_deg = 200.0
[imu]
preset = "tactical"
"""


def test_builtin_scenarios_load():
    names = scenarios.builtin_names()
    assert {"static-34n", "sway-34n"} <= set(names)
    s = scenarios.get("sway-34n")
    assert s.sway_frequency == (0.2, 0.1, 0.05)
    assert np.degrees(s.site.lat) == pytest.approx(34.0)


@pytest.mark.parametrize("edit,field", [
    ('lat_deg = -45.0', "lat_deg"),
    ('preset = "tactical"', "imu.preset"),
    ('duration_s = 30.0', "duration_s"),
    ('heading_deg = 200.0', "attitude.color"),
])
def test_bad_fields_are_named(tmp_path, edit, field):
    bad = {"lat_deg": 'lat_deg = 95.0', "imu.preset": 'preset = "gold"', "duration_s": 'duration_s = "long"',
           "attitude.color": 'heading_deg = 200.0\ncolor = "red"'}[field]
    p = tmp_path / "bad.toml"
    p.write_text(TOML.replace(edit, bad))
    with pytest.raises(scenarios.ScenarioError) as exc:
        scenarios.load(p)
    assert field in str(exc.value) and str(p) in str(exc.value)
    assert "\n" not in str(exc.value)


def test_run_is_identical_whatever_the_batch_size_and_workers(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(TOML)
    scn = scenarios.load(p)
    a = run_scenario(scn, runs=3, seed=7, batch_size=3, progress=False)
    b = run_scenario(scn, runs=3, seed=7, batch_size=1, progress=False)
    c = run_scenario(scn, runs=3, seed=7, batch_size=1, n_jobs=2, progress=False)
    for other in (b, c):
        assert np.array_equal(a.outcomes["coarse"].phi, other.outcomes["coarse"].phi)
    d = run_scenario(scn, runs=3, seed=8, progress=False)
    assert not np.array_equal(a.outcomes["coarse"].phi, d.outcomes["coarse"].phi)


def test_metrics_follow_the_contract_and_the_report_is_written(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(TOML)
    out = run_scenario(scenarios.load(p), runs=2, seed=1, progress=False)
    folder = tmp_path / "out"
    write_scenario_report(out, folder)
    m = json.loads((folder / "metrics.json").read_text())
    assert set(m) >= {"scenario", "runs", "seed", "duration_s", "quick", "limits_arcmin", "methods"}
    r = m["methods"]["coarse"]
    for ax in "ENU":
        assert set(r["final_error_arcmin"][ax]) == {"mean", "std", "rms", "max_abs"}
    assert set(r["settling_time_s"]) == {"U", "band_arcmin"} and "wall_s" in r
    # coarse alignment of a tactical IMU: level errors at the accelerometer-bias limit within noise
    assert abs(r["final_error_arcmin"]["E"]["mean"] - m["limits_arcmin"]["E"]) < 0.5
    assert (folder / "report.md").read_text().count("errors.png") == 1
    assert (folder / "errors.png").stat().st_size > 10000


def test_check_flags_only_regressions():
    ref = {"methods": {"m": {"final_error_arcmin": {ax: {"mean": 1.0, "rms": 2.0} for ax in "ENU"},
                             "settling_time_s": {"U": {"mean": 100.0}}}}}
    same = json.loads(json.dumps(ref))
    assert compare(same, ref) == []
    better = json.loads(json.dumps(ref))
    better["methods"]["m"]["final_error_arcmin"]["U"]["rms"] = 0.5
    assert compare(better, ref) == []
    worse = json.loads(json.dumps(ref))
    worse["methods"]["m"]["final_error_arcmin"]["U"]["rms"] = 2.5
    worse["methods"]["m"]["settling_time_s"]["U"]["mean"] = 200.0
    rows = compare(worse, ref)
    assert [r[1] for r in rows] == ["final phiU |rms| (arcmin)", "settling U mean (s)"]
    assert compare({"methods": {}}, ref)[0][1] == "method missing from run"


def test_imu_overrides_are_converted_from_customary_units(tmp_path):
    from fusionbench import units
    p = tmp_path / "o.toml"
    p.write_text(TOML.replace('preset = "tactical"', 'preset = "tactical"\ngyro_bias_dph = [0.02, 0, 0]\n'
                              'vrw_ug_rthz = 7.0\nrandom = false'))
    spec = scenarios.load(p).imu_spec
    assert spec.gyro.bias == pytest.approx((0.02 * units.DEG_PER_H, 0, 0))
    assert spec.accel.white == (0.0, 0.0, 0.0)  # random = false keeps only deterministic errors
    assert spec.accel.scale == pytest.approx((300e-6,) * 3)


def test_jump_window_metrics_and_filter_consistency(tmp_path):
    p = tmp_path / "jump.toml"
    p.write_text(TOML.replace('methods = ["coarse"]', 'methods = ["coarse", "kf"]').replace("duration_s = 30.0", "duration_s = 120.0")
                 + "[vref]\nsigma_mps = 0.01\nschedule = [{start_s = 40.0, end_s = 80.0, factor = 100.0}]\n"
                 "[metrics]\njump_window_s = [40.0, 80.0]\nsettling_band_arcmin = 30.0\n"
                 "[variants.kf]\nmethod = \"kf\"\nimu = \"tactical\"\nvel_sigma = 0.01\ncoarse_s = 20.0\n")
    m = run_scenario(scenarios.load(p), runs=2, seed=1, progress=False).metrics
    j = m["methods"]["kf"]["jump"]
    assert j["window_s"] == [40.0, 80.0] and set(j["rms_arcmin"]) == {"before", "during", "after"}
    assert j["reconverge_s"]["max_abs"] >= 0.0
    assert set(m["methods"]["kf"]["consistency_rms_ratio"]) == {"E", "N", "U"}
    assert "consistency_rms_ratio" not in m["methods"]["coarse"]  # no predicted sigma, no figure
