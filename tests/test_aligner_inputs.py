"""One input policy for every registered method (fusionbench.methods.aligner_base.AlignerBase): samples with NaN, a
velocity reference or initial attitude of the wrong shape, with NaN, or not a rotation, a latitude beyond the method's
declared limit and a record shorter than its minimum are refused with one line naming the method and the field, before
any work."""

import re

import numpy as np
import pytest

from fusionbench.methods.aligner import Site, available_methods, load_method
from fusionbench.methods.inputs import check_inputs
from fusionbench.simulation import trajectory
from fusionbench.simulation.imu import PRESETS, simulate

SITE = Site.from_degrees(34.0, 108.0, 100.0)
IMU = simulate(trajectory.Trajectory(SITE.lat, SITE.lon, SITE.h, trajectory.EulerSway(mean=np.radians([1.0, 2.0, -30.0])),
                                     duration=20.0), PRESETS["navigation"], dt=0.1, runs=2, seed=0)
GOOD_VREF = np.zeros((2, IMU.samples, 3))
BAD = {
    "vref": [dict(vref=np.zeros((2, IMU.samples - 1, 3))),           # one sample short
             dict(vref=np.zeros((2, IMU.samples, 2))),               # no up axis
             dict(vref=np.where(np.arange(IMU.samples)[None, :, None] == 5, np.nan, GOOD_VREF))],
    "init": [dict(init=np.eye(3)[:2]),                                # (2, 3)
             dict(init=np.broadcast_to(np.eye(3), (3, 3, 3))),        # three runs, the data has two
             dict(init=2.0 * np.eye(3)),                              # not orthonormal
             dict(init=np.diag([1.0, 1.0, -1.0])),                    # a reflection
             dict(init=np.full((3, 3), np.nan))],
}


@pytest.mark.parametrize("method", sorted(available_methods()))
@pytest.mark.parametrize("arg", ["vref", "init"])
def test_every_method_refuses_a_bad_reference_or_initial_attitude(method, arg):
    m = load_method(method)
    for bad in BAD[arg]:
        kwargs = {"init": np.eye(3)} if arg == "vref" else {}
        with pytest.raises(ValueError) as exc:
            m.align(IMU, SITE, **{**kwargs, **bad})
        msg = str(exc.value)
        assert f"{arg}:" in msg and "\n" not in msg, (method, msg)


def test_check_inputs_broadcasts_a_single_attitude_and_accepts_a_good_reference():
    vref, init = check_inputs(IMU, GOOD_VREF, np.eye(3), "m")
    assert vref.shape == (2, IMU.samples, 3) and init.shape == (2, 3, 3) and np.all(init == np.eye(3))
    assert check_inputs(IMU, GOOD_VREF[0])[0].shape == (2, IMU.samples, 3)  # one reference for every run
    rates = IMU.__class__(IMU.t, IMU.gyro / IMU.dt, IMU.accel / IMU.dt, kind="rate")
    assert check_inputs(rates, np.zeros((2, IMU.samples - 1, 3)))[0].shape == (2, IMU.samples - 1, 3)


@pytest.mark.parametrize("method", sorted(available_methods()))
def test_every_method_refuses_bad_samples_a_latitude_beyond_its_limit_and_a_short_record_alike(method):
    m = load_method(method)
    who = re.escape(m.name)
    nan = IMU.__class__(IMU.t, IMU.gyro.copy(), IMU.accel)  # IMUData refuses NaN when built; an array changed
    nan.gyro[:, 7] = np.nan  # afterwards still reaches the method, whose policy refuses it
    with pytest.raises(ValueError, match=rf"^{who}: imu gyro: expected finite samples, found NaN or inf$"):
        m.align(nan, SITE, init=np.eye(3))
    lim = m.max_latitude_deg
    if lim < 90.0:
        with pytest.raises(ValueError, match=rf"^{who}: site latitude: expected a latitude between -{lim:g} and "
                                             rf"{lim:g} deg, found {lim + 0.5:g} deg$"):
            m.align(IMU, Site.from_degrees(lim + 0.5), init=np.eye(3))
    k = max(2, min(IMU.samples, int(round(m.min_duration_s / IMU.dt)) - 1))  # a record shorter than the minimum
    short = IMU.__class__(IMU.t[:k], IMU.gyro[:, :k], IMU.accel[:, :k])
    with pytest.raises(ValueError, match=rf"^{who}: duration: expected at least {m.min_duration_s:g} s of data, "
                                         rf"found {short.duration:g} s$"):
        m.align(short, SITE, init=np.eye(3))


@pytest.mark.parametrize("lat, lon, words", [(34.0, float("nan"), "longitude"), (34.0, 1e9, "longitude"),
                                             (float("nan"), 0.0, "latitude"), (90.5, 0.0, "latitude")])
def test_a_site_names_a_bad_coordinate(lat, lon, words):
    with pytest.raises(ValueError, match=words):
        Site.from_degrees(lat, lon)


@pytest.mark.parametrize("spec, option, value, words", [
    ("adrc", "h1", -4, "adrc: option h1: expected a positive number, found -4"),
    ("adrc", "h1", 0, "adrc: option h1: expected a positive number, found 0"),
    ("adrc", "h1", "fast", "adrc: option h1: expected a positive number, found 'fast'"),
    ("adrc", "shot_s", -40, "adrc: option shot_s: expected a positive number, found -40"),
    ("pid", "step_s", -0.1, "pid: option step_s: expected a positive number, found -0.1"),
    ("kf", "coarse_s", -5, "kf: option coarse_s: expected a number >= 0, found -5"),
    ("kf", "step_s", float("nan"), "kf: option step_s: expected a positive number, found nan"),
    ("coarse", "history_points", 2.5, "coarse: option history_points: expected a positive whole number, found 2.5"),
    ("gtsam", "marginals", 1, "gtsam: option marginals: expected true or false, found 1"),
])
def test_a_bad_option_is_refused_when_the_method_is_built(spec, option, value, words):
    with pytest.raises(ValueError) as exc:
        load_method(spec, **{option: value})
    assert str(exc.value) == words


def test_a_variants_bad_option_names_the_variant(tmp_path):
    from fusionbench.bench import scenarios

    p = tmp_path / "v.toml"
    p.write_text('name = "v"\nduration_s = 30.0\nrate_hz = 50.0\nmethods = ["fast"]\n[site]\nlat_deg = 34.0\n'
                 '[variants.fast]\nmethod = "adrc"\nh1 = -4.0\n')
    with pytest.raises(scenarios.ScenarioError) as exc:
        scenarios.load(p).method("fast")
    assert "v.toml: field 'variants.fast': adrc: option h1: expected a positive number, found -4.0" in str(exc.value)
