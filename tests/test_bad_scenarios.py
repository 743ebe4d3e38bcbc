"""Bad scenario files: each is refused when it is read, with one line naming the file and the field (issue 14)."""

import pytest

from fusionbench.bench import scenarios

BASE = """
name = "p"
duration_s = 30.0
rate_hz = 50.0
runs = 2
methods = ["coarse"]
[site]
lat_deg = 34.0
"""

CASES = [  # (what is appended or replaced, the field the message names, words it must hold)
    ("[imu]\nschedule = [{start_s = 1, end_s = 2, factor = 3, sensors = \"gyro\"}]", "imu.schedule[0].sensors",
     "expected a list"),
    ("[imu]\nschedule = [{start_s = 10, end_s = 10, factor = 3}]", "imu.schedule[0].end_s", "after start_s"),
    ("[imu]\nschedule = [{start_s = 100, end_s = 200, factor = 3}]", "imu.schedule[0].start_s", "inside the record"),
    ("[vref]\nschedule = [{start_s = 40, end_s = 50, factor = 3}]", "vref.schedule[0].start_s", "inside the record"),
    ("[imu]\ngyro_bias_dph = -1e30", "imu.gyro_bias_dph", "in [-3600, 3600]"),
    ("[imu]\narw_dpsh = -5", "imu.arw_dpsh", "in [0, 100]"),
    ("[vref]\nsigma_mps = [-0.1, 0.1, 0.1]", "sigma_mps", "in [0, 100]"),
    ("[motion]\nsegments = [{accel_mps2 = [1e9, 0, 0], duration_s = 10}]", "accel_mps2", "in [-100, 100]"),
    ("[motion]\nstart_s = 1e9\nsegments = [{accel_mps2 = [0.1, 0, 0], duration_s = 10}]", "motion.start_s",
     "inside the record"),
    ("[motion]\ndisturbance_rms_mps = -1", "disturbance_rms_mps", "in [0, 100]"),
    ("[attitude]\nsway_amplitude_deg = [1e6, 0, 0]", "sway_amplitude_deg", "in [0, 45]"),
    ("[attitude]\nsway_phase_deg = [0, 0, 1e6]", "sway_phase_deg", "in [-360, 360]"),
    ("[init]\nmisalignment_deg = [1e9, 0, 0]", "misalignment_deg", "in [-180, 180]"),
    ("[paper]\nsettling_time_s = {coarse = \"fast\"}", "paper.settling_time_s.coarse", "expected a number"),
    ("[variants.fast]\nmethod = \"adrc\"\nh_one = 4.0", "variants.fast.h_one", "unknown option of method 'adrc'"),
    ("[variants.fast]\nmethod = \"no-such-method\"", "variants.fast.method", "expected one of"),
    (("methods = [\"coarse\"]", "methods = []"), "methods", "non-empty list"),
    (("methods = [\"coarse\"]", "methods = [\"\"]"), "methods", "non-empty list"),
    ("experiment = \"nope\"", "experiment", "expected one of"),
    # a receiver and a drive (docs/scenarios.md [aiding], [motion] legs)
    ("[vref]\nsigma_mps = 0.1\n[aiding]\nrate_hz = 10.0\nvelocity_sigma_mps = 0.1", "aiding", "found both"),
    ("[aiding]\nrate_hz = 10.0", "aiding", "found neither"),
    ("[aiding]\nvelocity_sigma_mps = 0.1", "aiding.rate_hz", "is missing"),
    ("[aiding]\nrate_hz = 10.0\nvelocity_sigma_mps = 0.1\nlever_arm_m = [0.1, 0.2]", "aiding.lever_arm_m",
     "expected 3 numbers"),
    ("[aiding]\nrate_hz = 10.0\nvelocity_sigma_mps = 0.1\noutages = [{start_s = 20.0, end_s = 10.0}]",
     "aiding.outages[0].end_s", "in [20, inf]"),
    ("[aiding]\nrate_hz = 10.0\nvelocity_sigma_mps = 0.1\nschedule = [{start_s = 40, end_s = 50, factor = 3}]",
     "aiding.schedule[0].start_s", "inside the record"),
    ("[motion]\nspeed_mps = 5.0", "motion.speed_mps", "only with legs"),
    ("[motion]\nlegs = [{duration_s = 10.01}]", "motion.legs[0].duration_s", "whole samples"),
    ("[motion]\nlegs = [{duration_s = 10.0, accel_mps2 = -1.0}]", "motion.legs[0].accel_mps2", "stays positive"),
    ("[motion]\nlegs = [{duration_s = 10.0, turn_rate_dps = 100.0}]", "turn_rate_dps", "in [-90, 90]"),
    ("[motion]\nlegs = [{duration_s = 10.0}]\ndisturbance_rms_mps = 0.05", "motion.disturbance_rms_mps",
     "found both"),
    ("[attitude]\nsway_amplitude_deg = [1.0, 1.0, 1.0]\nsway_frequency_hz = [0.1, 0.1, 0.1]\n[motion]\n"
     "legs = [{duration_s = 10.0}]", "motion.legs", "a drive and a sway"),
]


@pytest.mark.parametrize("edit, field, words", CASES, ids=[c[1] for c in CASES])
def test_a_bad_value_is_one_line_naming_the_file_and_the_field(tmp_path, edit, field, words):
    text = BASE.replace(*edit) if isinstance(edit, tuple) else (edit + "\n" + BASE if edit.startswith("experiment")
                                                              else BASE + edit + "\n")
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(scenarios.ScenarioError) as exc:
        scenarios.load(path)
    msg = str(exc.value)
    assert "\n" not in msg and str(path) in msg and field in msg and words in msg, msg


def test_the_base_of_the_cases_is_valid(tmp_path):
    path = tmp_path / "ok.toml"
    path.write_text(BASE)
    assert scenarios.load(path).methods == ("coarse",)


def test_a_binary_file_is_one_line_naming_it(tmp_path):
    path = tmp_path / "bin.toml"
    path.write_bytes(b"\x00\x01\x02binary\xff")
    with pytest.raises(scenarios.ScenarioError) as exc:
        scenarios.load(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_a_navigation_scenario_needs_an_initial_attitude_and_navigators(tmp_path):
    path = tmp_path / "nav.toml"
    path.write_text('experiment = "navigation"\n' + BASE)
    with pytest.raises(scenarios.ScenarioError, match=r"nav.toml: field 'init.misalignment_deg': expected the initial"):
        scenarios.load(path)
    path.write_text('experiment = "navigation"\n' + BASE.replace('["coarse"]', '["damped-nav"]')
                    + "[init]\nmisalignment_deg = [0.05, 0.05, 0.1]\n")
    scn = scenarios.load(path)
    assert scn.kind == "navigation" and scn.method("damped-nav").name == "damped-nav"
    with pytest.raises(ValueError, match="method 'coarse': expected a navigator"):
        scn.method("coarse")


@pytest.mark.parametrize("edit, field, words", CASES[:6] + CASES[-3:], ids=[c[1] for c in CASES[:6] + CASES[-3:]])
def test_the_command_line_refuses_a_bad_scenario_before_any_run_exit_2(tmp_path, capsys, edit, field, words):
    from fusionbench.cli import main

    text = BASE.replace(*edit) if isinstance(edit, tuple) else (edit + "\n" + BASE if edit.startswith("experiment")
                                                              else BASE + edit + "\n")
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fusionbench: error: ") and err.count("\n") == 1 and field in err and words in err, err
    assert not (tmp_path / "out").exists()  # nothing written


def test_an_empty_methods_option_is_refused(tmp_path, capsys):
    from fusionbench.cli import main

    path = tmp_path / "ok.toml"
    path.write_text(BASE)
    assert main(["run", str(path), "--methods", "", "--out", str(tmp_path / "out")]) == 2
    assert "--methods: expected comma-separated method names, found ''" in capsys.readouterr().err
