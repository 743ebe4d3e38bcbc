"""The motion check every aligner applies without aiding (fusionbench.methods.motion): fixed bases pass with margin, a
base that moves anywhere in the record is refused in one line naming --aiding."""

import numpy as np
import pytest

from fusionbench.methods import motion
from fusionbench.methods.aligner import Site, load_method
from fusionbench.simulation import drive, imu, trajectory
from fusionbench.simulation.translation import Translation, VelocityDisturbance

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
                                               Translation(disturbance=VelocityDisturbance(
                                                   (0.1, 0.1, 0.3), (0.05, 0.3))), duration=duration),
        "car": lambda: drive.car_drive(LAT, heading=0.5, duration=duration),
        "car-waits-60": lambda: drive.car_drive(LAT, heading=0.5, wait=60.0, duration=duration),
        "car-drives-last-10-s": lambda: drive.car_drive(LAT, heading=0.5, wait=duration - 10.0, duration=duration),
        "accelerating": lambda: trajectory.accelerating(LAT, mean=MEAN, duration=duration),
    }
    tr = trs[kind]()
    return imu.simulate(tr, imu.PRESETS[spec], 0.02, runs=3, seed=1)


def _worst(data):
    """Worst residual over its threshold on each of the check's scales, and the whole record's gravity excess."""
    tk, V = motion._integrated(data)
    out = []
    for W in motion.scales(tk[-1]):
        res, _, _, excess = motion._windows(tk, V, Site(LAT), W, W / motion.BLOCKS_PER_WINDOW)
        out.append(res.max() / motion.threshold_mps(W))
    return np.array(out), excess


@pytest.mark.parametrize("kind, spec, duration", [
    ("static", "tactical", 600.0),      # 1 deg/h and 0.5 deg/h of instability: the whole record's fit 0.46
    ("mild", "tactical", 600.0),
    ("moored", "tactical", 600.0),      # Table-1 sway, 0.1 m/s of disturbance: 0.47-0.63 of the thresholds
    ("heave", "tactical", 600.0),       # 0.3 m/s of slow vertical heave: vertical, not counted
    ("static", "navigation", 300.0),
])
def test_fixed_bases_pass_with_margin(kind, spec, duration):
    data = _record(kind, spec, duration)
    ratio, excess = _worst(data)
    assert ratio.size == 3 and ratio.max() < 1 / 1.5  # every scale, a margin of 1.5
    assert np.abs(excess).max() < motion.MAX_GRAVITY_EXCESS / 3
    motion.check_stationary(data, Site(LAT), "pid")


@pytest.mark.parametrize("kind, duration, scale, least", [
    ("car", 300.0, 0, 10.0),                     # 23 thresholds: every 60-s window holds a turn or the start
    ("car-waits-60", 300.0, 0, 10.0),
    ("car-drives-last-10-s", 600.0, 0, 2.0),     # 2.7: 10 s of driving in the last 60-s window
    ("accelerating", 300.0, 1, 1.1),             # 0.1 g from the start: 1.28 on 120 s, 1.63 on the whole record
])
def test_a_base_that_moves_anywhere_is_refused_naming_aiding(kind, duration, scale, least):
    data = _record(kind, duration=duration)
    ratio, _ = _worst(data)
    assert ratio[scale] > least
    with pytest.raises(ValueError, match=r"^adrc: the base moves \(recording \d: between \d+ and \d+ s .*needs its "
                                         r"velocity or position as aiding \(--aiding FILE\)$"):
        load_method("adrc").align(data, Site(LAT))


def test_a_short_constant_acceleration_is_refused_by_the_specific_force():
    data = _record("accelerating", duration=60.0)  # 0.1 g from the first sample: a tilt to first order
    ratio, excess = _worst(data)
    assert ratio.max() < 0.2 and excess.min() > 4e-3  # a^2 / 2 g^2 = 4.9 mg, less the Eotvos effect: 4.8
    with pytest.raises(ValueError, match=r"^coarse-i0: the base accelerates .*\+4\.\d mg.*--aiding FILE\)$"):
        load_method("coarse-i0").align(data, Site(LAT))


def test_the_scales_and_thresholds():
    assert motion.scales(300.0) == [60.0, 120.0, 300.0] and motion.scales(90.0) == [60.0, 90.0]
    assert motion.scales(45.0) == [45.0]
    assert motion.threshold_mps(120.0) == pytest.approx(0.15 + 6e-6 * 120.0**2)
    assert motion.threshold_mps(60.0) < motion.threshold_mps(120.0)
