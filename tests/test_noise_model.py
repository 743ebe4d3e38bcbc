"""The IMU noise model is an input: presets and IMU spec TOML files, through the Python API and the command line."""

import json
import subprocess
import sys

import numpy as np
import pytest

from baselines.kalman import KalmanAligner
from fusionbench.methods.aligner import Site, load_method, uses_noise_model, variant
from fusionbench.simulation import fields, units
from fusionbench.simulation.imu import PRESETS, load_spec
from fusionbench.simulation.imudata import IMUData

SPEC_TOML = """
[imu]
preset = "tactical"
name = "my-fog"
arw_dpsh = 0.05
gyro_bias_dph = [0.5, 0.6, 0.7]
vrw_ug_rthz = 20.0
"""


def test_load_spec_reads_presets_files_and_scenarios(tmp_path):
    assert load_spec("tactical") is PRESETS["tactical"]
    p = tmp_path / "fog.toml"
    p.write_text(SPEC_TOML)
    spec = load_spec(p)
    assert spec.name == "my-fog"
    # customary units in the file, SI in the spec: 0.05 deg/sqrt(h) = 1.4544e-5 rad/sqrt(s)
    assert spec.gyro.white == pytest.approx((0.05 * np.pi / 180 / 60,) * 3, rel=1e-12)
    assert spec.gyro.bias == pytest.approx(tuple(np.array([0.5, 0.6, 0.7]) * units.DEG_PER_H), rel=1e-12)
    assert spec.accel.white == pytest.approx((20e-6 * 9.80665,) * 3, rel=1e-12)
    assert spec.accel.bias == PRESETS["tactical"].accel.bias  # not overridden: the preset's
    # a scenario file's [imu] table is a spec file too, named after the file
    scn = tmp_path / "my-scenario.toml"
    scn.write_text('name = "x"\nduration_s = 60.0\nrate_hz = 100.0\n[imu]\npreset = "seed000"\n')
    assert load_spec(scn).name == "my-scenario"
    assert load_spec(scn).gyro == PRESETS["seed000"].gyro


@pytest.mark.parametrize("text, field", [
    ("[imu]\npreset = 'hal9000'\n", "imu.preset"),
    ("[imu]\narw_dpsh = -5\n", "imu.arw_dpsh"),
    ("[imu]\ngyro_bias_dph = -1e30\n", "imu.gyro_bias_dph"),
    ("[imu]\nschedule = [{start_s = 1, end_s = 2, factor = 10, sensors = 'gyro'}]\n", "imu.schedule[0].sensors"),
    ("[imu]\nschedule = [{start_s = 1, end_s = 2, factor = 10, sensors = ['magnet']}]\n", "imu.schedule[0].sensors"),
    ("[imu]\nbogus = 1\n", "imu.bogus"),
    ("preset = 'tactical'\n", "imu"),
])
def test_bad_spec_files_name_the_file_and_field(tmp_path, text, field):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(fields.FieldError) as exc:
        load_spec(p)
    msg = str(exc.value)
    assert str(p) in msg and f"field '{field}'" in msg and "\n" not in msg


def test_unknown_preset_and_missing_file_are_one_line_errors(tmp_path):
    with pytest.raises(ValueError, match="expected a preset name"):
        load_spec("hal9000")
    with pytest.raises(ValueError, match="no such IMU spec file"):
        load_spec(tmp_path / "none.toml")


def test_filter_takes_its_noise_model_from_the_spec_and_states_it():
    kf = KalmanAligner(imu="tactical")
    # Q of the attitude states is the gyro white noise density squared, rad^2/s
    assert kf._qc()[0] == pytest.approx(PRESETS["tactical"].gyro.white[0] ** 2)
    assert KalmanAligner().spec.name == "navigation"  # the stated default
    # load_method gives the model only to methods that use one; options win
    assert load_method("kf", imu="mems").spec.name == "mems"
    # in a scenario the filter gets the scenario's IMU (the true model) unless its variant names one
    from fusionbench.bench import scenarios
    scn = scenarios.get("static-q-jump")
    assert scn.method("kf").spec == scn.imu_spec
    import dataclasses
    scn = dataclasses.replace(scn, variants={**scn.variants, "kf": {"method": "kf", "imu": "tactical"}})
    assert scn.method("kf").spec.name == "tactical"
    # every aligner takes an IMU, if only to refuse one whose gyro bias hides the earth rate
    assert load_method("coarse", imu="mems").spec.name == "mems"
    assert load_method("coarse").spec is None and uses_noise_model(KalmanAligner)
    with pytest.raises(ValueError, match="unobservable"):
        load_method("coarse", imu="mems").align(IMUData([0.01, 0.02], np.zeros((2, 3)), np.zeros((2, 3))),
                                                 Site.from_degrees(34.0))


def test_a_named_variant_is_the_base_class_with_other_defaults():
    Tight = variant(KalmanAligner, "Tight", "kf-tight", "the filter with a tight reference", vref_sigma=0.001)
    kf = Tight()
    assert isinstance(kf, KalmanAligner) and kf.name == "kf-tight" and kf.vref_sigma == 0.001
    assert Tight(vref_sigma=0.2).vref_sigma == 0.2  # options still override
    assert Tight.variant_of == "kf" and Tight.variant_options == {"vref_sigma": 0.001}
    assert uses_noise_model(Tight)  # the base's options survive in the signature


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "fusionbench", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def test_align_takes_imu_on_the_command_line(tmp_path, data_dir):
    f = data_dir / "pyins_static_40n_noisy.csv"
    r = _cli("align", f, "--lat", 40, "--method", "kf", "--imu", "tactical")
    assert r.returncode == 0, r.stderr
    assert "noise model tactical" in r.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text("[imu]\narw_dpsh = 'fast'\n")
    r = _cli("align", f, "--lat", 40, "--method", "kf", "--imu", bad, "--json")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and "imu.arw_dpsh" in r.stderr and str(bad) in r.stderr
    r = _cli("list")
    line = next(s for s in r.stdout.splitlines() if s.split()[:1] == ["kf"])
    assert "noise model: navigation unless --imu" in line
    assert json.loads(_cli("align", f, "--lat", 40, "--method", "kf", "--json").stdout)["method"] == "kf"
