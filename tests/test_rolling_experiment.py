"""Platform self-calibration experiments: the [platform] table, determinism, metrics and report."""

import json

import numpy as np
import pytest

from baselines.rolling import model
from baselines.rolling.experiment import RollingScenario
from baselines.rolling.spec import PlatformSpec, draw_truth
from fusionbench.bench import scenarios
from fusionbench.bench.check import compare
from fusionbench.bench.experiment import run_scenario, write_scenario_report

TOML = """
name = "tiny-rolling"
experiment = "platform-rolling"
duration_s = 120.0
rate_hz = 5.0
runs = 2
methods = ["rolling-ekf"]
[site]
lat_deg = 34.0
[platform]
scheme = [{axis = "south", rate_dps = 0.5, duration_s = 60.0}, {axis = "east", rate_dps = 0.5, duration_s = 60.0}]
initial_angles_deg = [1.0, 2.0, 3.0]
initial_angles_sigma_deg = [0.1, 0.1, 0.1]
coeff_mean = {D0 = 1.0, K0 = 100.0}
coeff_sigma = {D0 = 0.2, K0 = 10.0}
"""


def _load(tmp_path, text=TOML):
    p = tmp_path / "r.toml"
    p.write_text(text)
    return scenarios.load(p)


def test_paper_scenario_loads_with_the_papers_scheme():
    scn = scenarios.get("paper002-rolling")
    assert scn.experiment == "platform-rolling"
    # its experiment's own type, the [platform] table as a field, not a dict entry to look up
    assert isinstance(scn, RollingScenario) and isinstance(scn.platform, PlatformSpec) and "platform" not in scn.setup
    assert scn.experiment_type.name == "platform-rolling"
    segs = scn.platform.scheme.segments
    assert [s.duration for s in segs] == [1800.0, 900.0, 1800.0, 900.0]
    assert segs[0].axis == (0.0, -1.0, 0.0) and segs[1].axis == (1.0, 0.0, 0.0)
    assert segs[0].rate == pytest.approx(np.radians(0.1))
    quick = scn.platform.scaled(900.0)
    assert sum(s.duration for s in quick.scheme.segments) == pytest.approx(900.0)


def test_truth_depends_on_seed_and_run_only(tmp_path):
    spec = _load(tmp_path).platform
    c0, a0 = draw_truth(spec, 5, 1)
    c1, a1 = draw_truth(spec, 5, 1)
    assert np.array_equal(c0, c1) and np.array_equal(a0, a1)
    assert not np.array_equal(c0, draw_truth(spec, 5, 2)[0])
    # drawn from the table: gyro bias around 1 deg/h, accelerometer bias around 100 ug, others zero
    c = np.stack([draw_truth(spec, 0, k)[0] for k in range(400)])
    assert np.mean(c[:, model.D0]) / model.COEFF_SCALE[0] == pytest.approx(1.0, abs=0.05)
    assert np.std(c[:, model.K0]) / model.COEFF_SCALE[27] == pytest.approx(10.0, rel=0.15)
    assert np.all(c[:, model.KT] == 0.0)


def test_run_metrics_follow_the_contract_and_do_not_depend_on_workers(tmp_path):
    scn = _load(tmp_path)
    a = run_scenario(scn, seed=3)
    b = run_scenario(scn, seed=3, n_jobs=2)
    assert np.array_equal(a.outcomes["rolling-ekf"]["err"], b.outcomes["rolling-ekf"]["err"])
    m = a.metrics
    r = m["methods"]["rolling-ekf"]
    assert set(m) >= {"scenario", "runs", "seed", "duration_s", "quick", "limits_arcmin", "methods"}
    assert set(r["final_error_arcmin"]["U"]) == {"mean", "std", "rms", "max_abs"} and "wall_s" in r
    assert set(r["coefficients"]) == set(model.COEFF_NAMES)
    assert r["coefficients"]["D0_X"]["unit"] == "deg/h"
    assert 0 < r["information_rank"] <= 45 and m["information_rank"] == r["information_rank"]
    # two passes: the settling time is the causal first pass's; its own end errors are reported beside
    oc = a.outcomes["rolling-ekf"]
    from fusionbench.simulation import units
    assert oc["has_first_pass"] and r["passes"] == 2 and oc["settle"].shape == (2,) and oc["phi_end_causal"].shape == (2, 3)
    assert r["settling_time_s"]["U"]["mean"] == pytest.approx(np.mean(oc["settle"]))
    assert r["first_pass"]["final_error_arcmin"]["U"]["rms"] == pytest.approx(
        np.sqrt(np.mean(oc["phi_end_causal"][:, 2] ** 2)) / units.ARCMIN)
    assert not np.allclose(oc["phi_end"], oc["phi_end_causal"])
    # the summed squares of the histories end where the per-run end errors say
    assert oc["phi_rms"][-1] == pytest.approx(np.sqrt(np.mean(oc["phi_end"] ** 2, axis=0)), rel=1e-12)
    assert oc["phi_rms_causal"][-1] == pytest.approx(np.sqrt(np.mean(oc["phi_end_causal"] ** 2, axis=0)), rel=1e-12)
    assert set(r["first_pass"]["groups"]) == set(r["groups"])
    folder = tmp_path / "rep"
    write_scenario_report(a, folder)
    text = (folder / "report.md").read_text()
    assert "coefficients.png" in text and (folder / "attitude.png").stat().st_size > 10000
    assert compare(json.loads((folder / "metrics.json").read_text()), m) == []


@pytest.mark.parametrize("edit,field", [
    ('axis = "south"', "platform.scheme[0].axis"),
    ("D0 = 1.0, K0", "platform.coeff_mean.D9"),
    ("duration_s = 120.0", "duration_s"),
])
def test_bad_platform_fields_are_named(tmp_path, edit, field):
    bad = {"platform.scheme[0].axis": 'axis = "sideways"', "platform.coeff_mean.D9": "D9 = 1.0, K0",
           "duration_s": "duration_s = 100.0"}[field]
    with pytest.raises(scenarios.ScenarioError) as exc:
        _load(tmp_path, TOML.replace(edit, bad, 1))
    assert field in str(exc.value) and "\n" not in str(exc.value)


def test_bad_method_options_name_the_variant(tmp_path):
    text = TOML.replace('methods = ["rolling-ekf"]', 'methods = ["ekf3"]') + '[variants.ekf3]\nmethod = "rolling-ekf"\n'
    scn = _load(tmp_path, text + 'passes = "three"\n')  # a value: the method checks it when it is built
    with pytest.raises(scenarios.ScenarioError) as exc:
        run_scenario(scn)
    assert "r.toml: field 'variants.ekf3'" in str(exc.value) and "passes: expected a whole number >= 1 or 'auto'" \
        in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(scenarios.ScenarioError) as exc:  # an option the class does not take: when the file is read
        _load(tmp_path, text + "pases = 3\n")
    assert "r.toml: field 'variants.ekf3.pases': unknown option of method 'rolling-ekf'" in str(exc.value)
    assert "'passes'" in str(exc.value) and "\n" not in str(exc.value)
