"""The motion check every aligner applies without aiding (fusionbench.motion): fixed bases pass with margin, a base
that moves anywhere in the record is refused in one line naming --aiding."""

import numpy as np
import pytest

from fusionbench import drive, imu, motion, trajectory
from fusionbench.aligner import Site, load_method

D = np.pi / 180
LAT = 34 * D
MEAN = (1 * D, -2 * D, -30 * D)


def _record(kind, spec="navigation", duration=300.0):
    trs = {
        "static": lambda: trajectory.Trajectory(LAT, 0, 0, trajectory.EulerSway(MEAN), duration=duration),
        "mild": lambda: trajectory.Trajectory(LAT, 0, 0, trajectory.EulerSway(MEAN, (1 * D, 1.5 * D, 2 * D),
                                                                              (0.2, 0.1, 0.05)), duration=duration),
        "moored": lambda: trajectory.moored(LAT, mean=MEAN, duration=duration, disturbance_rms=0.1),
        "heave": lambda: trajectory.Trajectory(LAT, 0, 0, trajectory.EulerSway(MEAN, (5 * D, 7 * D, 9 * D),
                                                                              (0.5, 0.3, 0.2)),
                                               trajectory.Translation(disturbance=trajectory.VelocityDisturbance(
                                                   (0.1, 0.1, 0.3), (0.05, 0.3))), duration=duration),
        "car": lambda: drive.car_drive(LAT, heading=0.5, duration=duration),
        "car-waits-60": lambda: drive.car_drive(LAT, heading=0.5, wait=60.0, duration=duration),
        "car-drives-last-10-s": lambda: drive.car_drive(LAT, heading=0.5, wait=duration - 10.0, duration=duration),
        "accelerating": lambda: trajectory.accelerating(LAT, mean=MEAN, duration=duration),
    }
    tr = trs[kind]()
    return imu.simulate(tr, imu.PRESETS[spec], 0.02, runs=3, seed=1)


@pytest.mark.parametrize("kind, spec, duration, most", [
    ("static", "tactical", 600.0, 0.10),     # 1 deg/h and 0.5 deg/h of instability over 120-s windows: 0.06-0.08
    ("mild", "tactical", 600.0, 0.10),
    ("moored", "tactical", 600.0, 0.16),     # Table-1 sway, 0.1 m/s of disturbance: 0.12-0.13
    ("heave", "tactical", 600.0, 0.16),      # 0.3 m/s of slow vertical heave: vertical, not counted
    ("static", "navigation", 300.0, 0.01),
])
def test_fixed_bases_pass_with_margin(kind, spec, duration, most):
    data = _record(kind, spec, duration)
    res, _, W, excess = motion.window_residual(data, Site(LAT))
    assert W == motion.WINDOW_S and res.max() < most < motion.threshold_mps(W) / 1.4
    assert np.abs(excess).max() < motion.MAX_GRAVITY_EXCESS / 3
    motion.check_stationary(data, Site(LAT), "pid")


@pytest.mark.parametrize("kind, duration, least", [
    ("car", 300.0, 3.0),                     # 3.5 m/s: every window holds a turn or the start
    ("car-waits-60", 300.0, 3.0),
    ("car-drives-last-10-s", 600.0, 0.3),    # 0.33: 10 s at 0.5 m/s^2 in the last window
])
def test_a_base_that_moves_anywhere_is_refused_naming_aiding(kind, duration, least):
    data = _record(kind, duration=duration)
    res, start, W, _ = motion.window_residual(data, Site(LAT))
    assert res.min() > least > motion.threshold_mps(W)
    with pytest.raises(ValueError, match=r"^adrc: the base moves \(recording \d: between \d+ and \d+ s .*needs its "
                                         r"velocity or position as aiding \(--aiding FILE\)$"):
        load_method("adrc").align(data, Site(LAT))
    if kind == "car-drives-last-10-s":
        assert np.all(start == duration - W)  # the window that holds the drive


def test_a_constant_acceleration_is_refused_by_the_specific_force_or_the_fit():
    data = _record("accelerating")  # 0.1 g from the first sample: a tilt to first order, 4.9 mg of excess
    with pytest.raises(ValueError, match=r"^kf: the base (moves|accelerates) .*--aiding FILE\)$"):
        load_method("kf").align(data, Site(LAT))


def test_the_threshold_grows_with_the_window_as_the_gyros_drift():
    assert motion.threshold_mps(120.0) == pytest.approx(0.15 + 6e-6 * 120.0**2)
    assert motion.threshold_mps(60.0) < motion.threshold_mps(120.0)
