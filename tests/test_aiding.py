"""The aiding type, the receiver simulator and the drive: their conventions against independent computations."""

import numpy as np
import pytest

from fusionbench.simulation import attitude, drive, earth, imu, trajectory, units
from fusionbench.simulation.aiding import Aiding
from fusionbench.simulation.aiding_geometry import bracket, enu_offset, lever_offset, lever_velocity
from fusionbench.simulation.aidingsim import AidingSpec, simulate_aiding
from fusionbench.simulation.strapdown import NavState, Strapdown

D = np.pi / 180
LAT = 45 * D


# ------------------------------------------------------------------------------------------------ the type
@pytest.mark.parametrize("kw, words", [
    (dict(t=[0.0, 1.0, 1.0], velocity=np.zeros((3, 3))), "strictly increasing times, found 1 s at row 2"),
    (dict(t=[0.0, np.nan], velocity=np.zeros((2, 3))), "finite times, found nan at row 1"),
    (dict(t=[0.0, 1.0]), "expected velocity, position or rows at rest"),
    (dict(t=[0.0, 1.0], velocity=np.zeros((3, 3))), "expected shape (2, 3)"),
    (dict(t=[0.0, 1.0], velocity=[[0, 0, 0], [3000.0, 0, 0]]), "below 2000, found 3000 at row 1"),
    (dict(t=[0.0, 1.0], velocity=[[0, 0, 0], [np.inf, 0, 0]]), "found inf at row 1"),
    (dict(t=[0.0, 1.0], position=[[0.0, 0, 0], [2.0, 0, 0]]), "latitude within +-90 deg, found 114.592 at row 1"),
    (dict(t=[0.0, 1.0], velocity=np.zeros((2, 3)), sigma_v=[0.1, -1.0]), "positive finite standard deviations"),
    (dict(t=[0.0, 1.0], velocity=np.zeros((2, 3)), lever_arm=[1.0, 2.0]), "three finite numbers X,Y,Z in m"),
    (dict(t=[0.0, 1.0], velocity=np.zeros((2, 3)), lever_arm=[0.0, 500.0, 0.0]), "at most 200 m, found 500 m"),
    (dict(t=[0.0, 1.0], velocity=np.zeros((2, 3)), delay=30.0), "latency in s within +-10"),
    (dict(t=[0.0, 1.0], velocity=np.full((2, 3), np.nan)), "only NaN"),
])
def test_bad_rows_are_one_line_naming_the_field_and_the_row(kw, words):
    with pytest.raises(ValueError) as exc:
        Aiding(**kw, source="gnss.csv")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("gnss.csv") and words in msg, msg


def test_a_row_valid_outside_the_record_is_refused_naming_it_and_its_stamp():
    a = Aiding(np.array([0.5, 1.05, 2.05]), velocity=np.zeros((3, 3)), delay=0.05, source="gnss.csv")
    a.check_record(0.0, 2.0, 0.01, "kf")  # valid at 0.45, 1.0, 2.0: inside
    late = Aiding(np.array([0.5, 2.1]), velocity=np.zeros((2, 3)), source="gnss.csv")
    with pytest.raises(ValueError, match=r"^kf: gnss.csv: row 1 is valid at 2\.100000 s, after the IMU record "
                                         r"\(0\.000000 to 2\.000000 s\)"):
        late.check_record(0.0, 2.0, 0.01, "kf")
    early = Aiding(np.array([0.01, 1.0]), velocity=np.zeros((2, 3)), delay=0.05, source="gnss.csv")
    with pytest.raises(ValueError, match=r"row 0 is valid at -0\.040000 s \(stamped 0\.010000 s, latency 0\.05 s\), "
                                         r"before"):
        early.check_record(0.0, 2.0, 0.01, "kf")


def test_the_per_increment_reference_is_rows_at_the_increment_ends():
    t = np.arange(1, 101) * 0.01
    v = np.random.default_rng(0).normal(0, 0.05, (2, 100, 3))
    a = Aiding.from_vref(t, v)
    assert a.is_at_rest()  # noise of 0.05 m/s about zero: a fixed base's reference
    assert np.array_equal(a.dense_velocity(t, 2), v)
    moving = Aiding.from_vref(t, v + [5.0, 0.0, 0.0])
    assert not moving.is_at_rest() and moving.has_velocity and not moving.has_position
    assert moving.dense_velocity(t + 0.001, 2) is None  # not on these increment ends
    assert Aiding.from_vref(t, v, at_rest=False).is_at_rest() is False
    with pytest.raises(ValueError, match=r"expected shape \(runs, 100, 3\) or \(100, 3\)"):
        Aiding.from_vref(t, v[:, :50])


def test_windows_runs_and_gaps():
    t = np.arange(0.0, 10.0, 0.5) + 0.5
    v = np.arange(3 * t.size * 3, dtype=float).reshape(3, t.size, 3) * 1e-3
    a = Aiding(t, velocity=v, delay=0.5)  # valid at 0 .. 9.5 s
    w = a.window(2.0, 4.0)  # valid in (2, 4]: 2.5, 3, 3.5, 4
    assert np.allclose(w.t_valid, [2.5, 3.0, 3.5, 4.0]) and w.velocity.shape == (3, 4, 3)
    assert np.array_equal(a.select_runs([2]).velocity[0], v[2])
    with pytest.raises(ValueError, match="expected rows for 2 recordings, found 3"):
        a.for_runs(2)
    gap = a.rows(np.r_[0:6, 14:20])  # valid 0 .. 2.5, then 7 .. 9.5
    assert gap.longest_gap(0.0, 9.5) == pytest.approx(4.5)
    assert a.rate_hz() == pytest.approx(2.0)


def test_bracket_places_a_time_inside_its_increment():
    t_end = np.array([0.1, 0.2, 0.3])
    k, w = bracket(t_end, 0.0, np.array([0.0, 0.05, 0.1, 0.125, 0.3]))
    assert np.array_equal(k, [0, 0, 0, 1, 2]) and np.allclose(w, [0.0, 0.5, 1.0, 0.25, 1.0])


def test_enu_offset_is_the_curvilinear_offset_pyins_tangent_plane_agrees_with_to_second_order():
    from pyins import transform

    origin = np.array([45.0, 12.0, 100.0])
    near = origin + np.array([[1e-4, 0.0, 5.0], [0.0, 2e-4, -3.0], [-1.5e-4, 1e-4, 0.0]])  # 10-20 m away
    far = origin + np.array([0.0, 0.02, 0.0])  # 1.6 km east
    rad = lambda p: np.column_stack([np.radians(p[..., :2]), p[..., 2]])  # noqa: E731
    o = np.r_[np.radians(origin[:2]), origin[2]]
    ned = transform.lla_to_ned(near, origin)
    # a few metres from the origin the two agree to the square of distance over radius (20 m: 0.03 mm)
    assert np.allclose(enu_offset(rad(near), o), np.column_stack([ned[:, 1], ned[:, 0], -ned[:, 2]]), atol=1e-4)
    # far off they differ at second order: a point due east on the parallel lies d^2 tan L / 2R north of the tangent
    # plane (and d^2 / 2R below it)
    e = enu_offset(rad(far[None]), o)[0]
    ned_far = transform.lla_to_ned(far[None], origin)[0]
    R = earth.radii(np.radians(45.0))[1] + 100.0
    assert ned_far[0] - e[1] == pytest.approx(e[0] ** 2 * np.tan(np.radians(45.0)) / (2 * R), rel=0.01)
    assert e[0] == pytest.approx(ned_far[1], abs=0.01)


def test_the_antenna_terms_are_the_lever_arm_turned_and_its_rotation():
    C = attitude.euler_to_dcm(np.radians([2.0, -3.0, -30.0]))
    lever = np.array([0.3, 1.2, 0.9])
    assert np.allclose(lever_offset(C, lever), C @ lever)
    w = np.array([0.01, -0.02, 0.3])  # rad/s, body
    # finite difference of the antenna's offset as the body turns: d/dt (C l) = C [w x] l
    dt = 1e-6
    C2 = C @ attitude.rotvec_to_dcm(w * dt)
    assert np.allclose(lever_velocity(C, w, lever), (C2 @ lever - C @ lever) / dt, atol=1e-6)


def test_differenced_positions_are_the_velocity_between_them():
    tr = drive.car_drive(LAT, heading=0.3, duration=100.0)
    spec = AidingSpec(1.0, None, (0.0, 0.0, 0.0))
    a = simulate_aiding(tr, spec)
    d = a.velocities_from_positions()
    v_mid = tr.truth(d.t_valid).v_n  # the mean velocity over a second is the mid-point's to second order
    acc = 1.0  # m/s^2 at most on this drive: the chord differs from the mid-point velocity by a''' dt^2 / 24
    assert np.abs(d.velocity[0, :, :2] - v_mid[:, :2]).max() < 0.05 * acc


# ------------------------------------------------------------------------------------------------ the drive
def test_a_perfect_imu_on_a_drive_follows_the_truth():
    tr = drive.car_drive(LAT, 12 * D, 100.0, heading=30 * D, duration=120.0, pitch=1 * D, roll=-2 * D)
    data = imu.simulate(tr, imu.PRESETS["ideal"], 0.02)
    T0 = tr.truth([0.0])
    sd = Strapdown(NavState.broadcast(1, T0.C_bn[0], T0.v_n[0], T0.lat[0], T0.lon[0], T0.h[0]), 0.02)
    out = sd.run(data.gyro, data.accel, record_every=data.t.size)
    T = tr.truth([120.0])
    assert np.abs(attitude.misalignment(out["C_bn"][0, -1], T.C_bn[0])).max() < 1e-4 * units.ARCMIN
    assert np.abs(out["v_n"][0, -1] - T.v_n[0]).max() < 1e-4


def test_a_drive_moves_along_its_heading_and_turns_by_its_legs():
    legs = (drive.Leg(20.0, 0.5), drive.Leg(10.0), drive.Leg(8.0, 0.0, 5.0 * D), drive.Leg(10.0, -0.5))
    tr = drive.drive(LAT, legs=legs, heading=30 * D, duration=60.0)
    T = tr.truth([10.0, 30.0, 38.0, 48.0, 55.0])
    speed = np.linalg.norm(T.v_n, axis=1)
    assert np.allclose(speed, [5.0, 10.0, 10.0, 5.0, 5.0])
    heading = np.degrees(attitude.heading(attitude.dcm_to_euler(T.C_bn)[:, 2]))
    assert np.allclose(heading, [30.0, 30.0, 70.0, 70.0, 70.0])
    # the velocity points along the body's forward axis
    fwd = T.C_bn[:, :, 1]
    assert np.allclose(fwd[:, :2] * speed[:, None], T.v_n[:, :2], atol=1e-9)
    # at the turn's apex (mid-leg, twice the mean rate) the acceleration is centripetal, speed x heading rate
    _, a = tr.velocity([34.0])
    assert np.linalg.norm(a) == pytest.approx(10.0 * 2 * 5.0 * D)
    assert np.dot(a[0], tr.truth([34.0]).C_bn[0, :, 0]) == pytest.approx(10.0 * 2 * 5.0 * D)  # to the right
    # every rate is continuous: at a leg's ends the acceleration and the turn rate are zero
    _, a = tr.velocity([20.0 - 1e-9, 20.0, 30.0, 38.0 - 1e-9])
    assert np.abs(a).max() < 1e-6
    assert not tr.translation.is_static() and drive.Drive().is_static()


# ------------------------------------------------------------------------------------------------ the receiver
def test_the_receivers_velocity_noise_is_the_per_increment_references():
    tr = trajectory.accelerating(34 * D, duration=20.0)
    t = np.arange(1, 201) * 0.1
    vref = imu.simulate_vref(tr, imu.VelocityReferenceSpec((0.1, 0.1, 0.1)), t, runs=3, seed=7, first_run=2)
    a = simulate_aiding(tr, AidingSpec(10.0, (0.1, 0.1, 0.1)), runs=3, seed=7, first_run=2, grid=t)
    assert np.array_equal(a.t, t) and np.array_equal(a.velocity, vref)


def test_the_receiver_measures_the_antenna_late_with_outages():
    tr = drive.car_drive(LAT, heading=0.3, duration=100.0, wait=0.05)
    lever = (0.3, 1.2, 0.9)
    spec = AidingSpec(10.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), lever_arm=lever, delay=0.05, outages=((40.0, 60.0),))
    a = simulate_aiding(tr, spec)
    assert np.allclose(a.t - a.t_valid, 0.05) and not np.any((a.t_valid >= 40.0) & (a.t_valid < 60.0))
    assert a.t_valid[0] == pytest.approx(0.1) and a.t_valid[-1] == pytest.approx(100.0)
    assert a.sigma_v is None and a.at_rest is None  # noise-free rows report no sigma; a moving base is not at rest
    T = tr.truth(a.t_valid)
    _, w_nb = tr.attitude.attitude(a.t_valid)
    v_ant = T.v_n + np.einsum("nij,nj->ni", T.C_bn, np.cross(w_nb, lever))
    assert np.allclose(a.velocity[0], v_ant, atol=1e-12)
    # the antenna sits C_bn l from the IMU: in ENU metres, against the truth's position
    d = enu_offset(a.position[0], np.column_stack([T.lat, T.lon, T.h]))
    assert np.allclose(d, np.einsum("nij,j->ni", T.C_bn, lever), atol=1e-6)


def test_a_fixed_bases_receiver_reports_rest():
    tr = trajectory.moored(LAT, duration=60.0)
    a = simulate_aiding(tr, AidingSpec(5.0, (0.05, 0.05, 0.05)), runs=2, seed=1)
    assert a.is_at_rest() and a.sigma_v.shape == (300, 3)
    assert abs(a.velocity.std() - 0.05) < 0.005 and abs(a.velocity.mean()) < 0.005
