"""Metrics: limits, settling time and statistics against closed forms."""

import numpy as np
import pytest

from fusionbench.scoring import metrics
from fusionbench.simulation import attitude, earth, units

D = np.pi / 180


def test_limits_for_a_level_north_facing_imu():
    lat = 34 * D
    g = earth.gravity(lat)
    eps = np.array([1e-7, 2e-7, 3e-7])  # body = ENU when level and facing north
    nab = np.array([3e-4, -2e-4, 1e-4])
    lim = metrics.theoretical_limits(eps, nab, np.eye(3), lat)
    W = earth.OMEGA_IE
    assert lim == pytest.approx([2e-4 / g, 3e-4 / g, -1e-7 / (W * np.cos(lat)) + np.tan(lat) * 3e-4 / g], rel=1e-14)


def test_limits_rotate_with_heading():
    # facing east (yaw -90 deg): body x points south, so a body-x gyro bias is a -north bias: no azimuth limit
    C = attitude.euler_to_dcm([0, 0, -90 * D])
    lim = metrics.theoretical_limits([1e-7, 0, 0], [0, 0, 0], C, 0.5)
    assert lim[2] == pytest.approx(0.0, abs=1e-12)
    lim = metrics.theoretical_limits([0, 1e-7, 0], [0, 0, 0], C, 0.5)
    assert lim[2] == pytest.approx(-1e-7 / (earth.OMEGA_IE * np.cos(0.5)), rel=1e-12)


def test_settling_time_of_an_exponential_decay_onto_the_limit():
    t = np.linspace(0, 100, 100001)
    limit = -2.0
    x = limit + 60.0 * np.exp(-t / 10.0)
    # |x - limit| < 1 from t = 10 ln 60
    assert metrics.settling_time(t, x, 1.0, limit) == pytest.approx(10 * np.log(60.0), abs=2e-3)
    assert metrics.settling_time(t, np.full_like(t, limit), 1.0, limit) == 0.0


def test_settling_is_against_the_truth_not_the_final_value():
    # a method that settles 5 arcmin off the limit has not settled in a 1-arcmin band, whatever its own
    # final value says
    t = np.linspace(0, 100, 1001)
    x = 5.0 + 60.0 * np.exp(-t / 10.0)
    assert metrics.settling_time(t, x, 1.0, 0.0) == t[-1]
    assert not metrics.settled(x, 1.0, 0.0)
    assert metrics.settled(x, 6.0, 0.0) and metrics.settling_time(t, x, 6.0, 0.0) < 50.0


def test_settling_time_is_batched_and_takes_a_moving_limit():
    t = np.arange(5.0)
    x = np.array([[5, 0, 0, 0, 0], [0, 0, 0, 5, 0]], dtype=float)
    assert metrics.settling_time(t, x, 1.0).tolist() == [1.0, 4.0]
    limit = np.array([0.0, 0.0, 0.0, 5.0, 0.0])  # a limit that moves with the attitude (sway)
    assert metrics.settling_time(t, x, 1.0, limit).tolist() == [4.0, 0.0]


def test_stats():
    s = metrics.stats([3.0, -4.0])
    assert s == {"mean": -0.5, "std": 3.5, "rms": pytest.approx(np.sqrt(12.5)), "max_abs": 4.0}


def test_misalignment_history_shape_and_units():
    C = attitude.euler_to_dcm(np.zeros((4, 3)))
    est = attitude.apply_misalignment(C, [units.ARCMIN, 0, 0])[None]
    phi = metrics.misalignment_history(est, C)
    assert phi.shape == (1, 4, 3)
    assert phi[0, :, 0] / units.ARCMIN == pytest.approx(np.ones(4), rel=1e-12)


@pytest.mark.parametrize("call, words", [
    (lambda: metrics.settling_time(np.arange(5.0), np.zeros(3), 1.0),
     ["settling_time x:", "expected error histories of shape (..., 5)", "found shape (3,)"]),
    (lambda: metrics.settling_time(np.arange(5.0), np.zeros((5, 3)), 1.0),  # histories along the wrong axis
     ["settling_time x:", "shape (..., 5)", "found shape (5, 3)"]),
    (lambda: metrics.settling_time(np.arange(10.0).reshape(2, 5), np.zeros(5), 1.0),
     ["settling_time t:", "expected a 1-D array of times", "found shape (2, 5)"]),
    (lambda: metrics.settling_time([], np.zeros(0), 1.0), ["settling_time x:", "M >= 1", "found shape (0,)"]),
    (lambda: metrics.settling_time(np.arange(5.0), 0.0, 1.0), ["settling_time x:", "found shape ()"]),
    (lambda: metrics.settling_time(np.arange(5.0), np.zeros((2, 5)), 1.0, np.zeros(4)),
     ["settling_time target:", "broadcastable to x's shape (2, 5)", "found shape (4,)"]),
    (lambda: metrics.settling_time(np.arange(5.0), np.zeros(5), 1.0, np.zeros((3, 5))),  # would widen x
     ["settling_time target:", "x's shape (5,)", "found shape (3, 5)"]),
    (lambda: metrics.settling_time(np.arange(5.0), np.zeros((2, 5)), np.ones(2)),
     ["settling_time band:", "x's shape (2, 5)", "found shape (2,)"]),
    (lambda: metrics.settled(np.zeros((2, 5)), 1.0, np.zeros(3)),
     ["settled target:", "x's shape (2, 5)", "found shape (3,)"]),
    (lambda: metrics.settled(np.zeros((2, 0)), 1.0), ["settled x:", "M >= 1", "found shape (2, 0)"]),
])
def test_mismatched_settling_shapes_are_one_line_naming_the_argument(call, words):
    with pytest.raises(ValueError) as err:
        call()
    msg = str(err.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


def test_settling_shapes_that_match_still_broadcast():
    t = np.arange(5.0)
    x = np.zeros((2, 3, 5))
    assert metrics.settling_time(t, x, 1.0, np.zeros(5)).shape == (2, 3)
    assert metrics.settling_time(t, x, np.ones((3, 1)), np.zeros((2, 1, 5))).shape == (2, 3)
    assert metrics.settled(x, 1.0, np.zeros(5)).shape == (2, 3) and metrics.settled(x[0, 0], 1.0).shape == ()
