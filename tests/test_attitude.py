"""Attitude conventions: Euler order, heading, misalignment, Euler platform error angles (seed 000)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from fusionbench.simulation import attitude
from tests.conftest import load_fixture

D = np.pi / 180


def rx(a):
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def ry(a):
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def rz(a):
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_euler_is_rz_rx_ry():
    p, r, y = 0.3, -0.7, 2.1
    assert attitude.euler_to_dcm([p, r, y]) == pytest.approx(rz(y) @ rx(p) @ ry(r), abs=1e-15)
    scipy_zxy = Rotation.from_euler(attitude._ORDER, [y, p, r]).as_matrix()
    assert attitude.euler_to_dcm([p, r, y]) == pytest.approx(scipy_zxy, abs=1e-15)


@settings(max_examples=50, deadline=None)
@given(st.floats(-1.5, 1.5), st.floats(-3.1, 3.1), st.floats(-3.1, 3.1))
def test_euler_round_trip(p, r, y):
    back = attitude.dcm_to_euler(attitude.euler_to_dcm([p, r, y]))
    assert back == pytest.approx([p, r, y], abs=1e-9)


def test_pyins_fixture_angles_give_its_dcm_and_heading():
    _, _, _, meta = load_fixture("pyins_static_40n_perfect")
    p, r, y = np.radians(meta["last_pitch_roll_yaw_deg"])
    assert attitude.euler_to_dcm([p, r, y]) == pytest.approx(np.array(meta["C_bn_first"]), abs=1e-12)
    assert np.degrees(attitude.heading(y)) == pytest.approx(meta["last_heading_deg"], abs=1e-9)
    # the fixture's pyins heading 75 deg (clockwise) is yaw -75 deg here
    assert np.degrees(y) == pytest.approx(-75.0, abs=1e-9)


def test_misalignment_matches_small_angle_definition():
    C = attitude.euler_to_dcm([0.1, 0.2, 1.0])
    phi = np.array([1e-4, -2e-4, 3e-4])
    C_est = (np.eye(3) - attitude.skew(phi)) @ C
    assert attitude.misalignment(C_est, C) == pytest.approx(phi, abs=1e-7)  # second-order terms ~1e-8


def test_apply_misalignment_is_inverse_of_misalignment_for_large_angles():
    C = attitude.euler_to_dcm(np.random.default_rng(0).uniform(-1, 1, (5, 3)))
    phi = np.random.default_rng(1).uniform(-1, 1, (5, 3))
    assert attitude.misalignment(attitude.apply_misalignment(C, phi), C) == pytest.approx(phi, abs=1e-12)


def test_euler_platform_matrix_is_the_papers_eq1():
    ax, ay, az = 0.3, -0.2, 2.5
    s, c = np.sin, np.cos
    paper = np.array([
        [c(ay) * c(az) - s(ay) * s(ax) * s(az), c(ay) * s(az) + s(ay) * s(ax) * c(az), -s(ay) * c(ax)],
        [-c(ax) * s(az), c(ax) * c(az), s(ax)],
        [s(ay) * c(az) + c(ay) * s(ax) * s(az), s(ay) * s(az) - c(ay) * s(ax) * c(az), c(ay) * c(ax)],
    ])
    assert attitude.euler_platform_to_dcm([ax, ay, az]) == pytest.approx(paper, abs=1e-15)
    assert attitude.dcm_to_euler_platform(paper) == pytest.approx([ax, ay, az], abs=1e-12)


def test_euler_platform_angles_equal_phi_when_small_and_round_trip_when_large():
    phi = np.array([2e-5, -1e-5, 3e-5])
    assert attitude.phi_to_euler_platform(phi) == pytest.approx(phi, abs=1e-9)
    alpha = np.array([[0.05, -0.05, np.pi - 0.01], [0.01, 0.02, -1.0]])
    assert attitude.phi_to_euler_platform(attitude.euler_platform_to_phi(alpha)) == pytest.approx(alpha, abs=1e-12)
    C_true = attitude.euler_to_dcm([0.1, 0.2, 0.3])
    C_est = attitude.euler_platform_to_dcm(alpha[0]) @ C_true
    assert attitude.euler_platform_angles(C_est, C_true) == pytest.approx(alpha[0], abs=1e-12)


def test_quaternion_round_trip_batched():
    C = attitude.euler_to_dcm(np.random.default_rng(2).uniform(-1, 1, (4, 2, 3)))
    assert attitude.quat_to_dcm(attitude.dcm_to_quat(C)) == pytest.approx(C, abs=1e-14)
    assert attitude.dcm_to_quat(C).shape == (4, 2, 4)
