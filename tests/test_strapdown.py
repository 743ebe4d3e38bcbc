"""A perfect IMU run through the strapdown reproduces the simulator's truth; cross-checks with pyins."""

import numpy as np
import pytest

from fusionbench.files.imufiles import read_psins
from fusionbench.simulation import attitude, earth, strapdown, trajectory as tj, units
from fusionbench.simulation.strapdown import NavState, Strapdown
from fusionbench.simulation.translation import Segment, Translation
from tests.conftest import DATA, agree_to_rounding, load_fixture
from tests.oracles.strapdown import integrate_numpy

D = np.pi / 180
LAT, LON, H = 34 * D, 108 * D, 450.0


def run_perfect(tr, dt, record_every=100, **kw):
    """Strapdown of the trajectory's exact increments from its true initial state; errors vs truth."""
    n = int(round(tr.duration / dt))
    t, dth, dv = tr.increments(0.0, dt, n)
    s0 = tr.truth([0.0])
    sd = Strapdown(NavState.broadcast(1, s0.C_bn[0], s0.v_n[0], s0.lat[0], s0.lon[0], s0.h[0]), dt, **kw)
    out = sd.run(dth[None], dv[None], record_every=record_every)
    tt = t[record_every - 1::record_every]
    truth = tr.truth(tt)
    phi = attitude.misalignment(out["C_bn"][0], truth.C_bn)
    return tt, out, truth, phi


def test_static_one_hour_is_exact():
    tr = tj.Trajectory(LAT, LON, H, tj.EulerSway(mean=(1 * D, -2 * D, 123 * D)), duration=3600.0)
    _, out, truth, phi = run_perfect(tr, 0.01, position_fixed=True)
    assert np.abs(phi).max() < 0.01 * units.ARCSEC
    assert np.abs(out["v_n"][0]).max() < 1e-6


def test_sway_one_hour_at_100hz_is_exact():
    # the pyins cross-check motion: 1/1.5/2 deg at 0.2/0.1/0.05 Hz on roll/pitch/yaw
    sway = tj.EulerSway(mean=(0, 0, 30 * D), amplitude=(1.5 * D, 1.0 * D, 2.0 * D), frequency=(0.1, 0.2, 0.05))
    _, _, _, phi = run_perfect(tj.Trajectory(LAT, LON, H, sway, duration=3600.0), 0.01, position_fixed=True)
    assert np.abs(phi).max() < 0.01 * units.ARCSEC


def test_seed000_sway_ten_minutes(record_property):
    sway = tj.EulerSway(mean=(0, 0, 30 * D), amplitude=(5 * D, 7 * D, 9 * D), frequency=(0.5, 0.3, 0.2))
    _, _, _, phi = run_perfect(tj.Trajectory(LAT, LON, H, sway, duration=600.0), 0.01, position_fixed=True)
    worst = np.abs(phi).max() / units.ARCSEC
    record_property("seed000_sway_attitude_error_arcsec", worst)  # measured 0.0013 arcsec
    assert worst < 0.01


def test_moving_base_with_turns_and_accelerations_follows_truth():
    sway = tj.EulerSway(mean=(0, 0, 30 * D), amplitude=(1 * D, 1 * D, 1 * D), frequency=(0.1, 0.2, 0.05))
    motion = Translation(segments=(Segment((0.98, 0, 0), 100.0), Segment((0, 0.5, 0), 100.0)))
    tt, out, truth, phi = run_perfect(tj.Trajectory(LAT, LON, H, sway, motion, duration=600.0), 0.01, height_fixed=True)
    assert np.abs(phi).max() < 0.01 * units.ARCSEC
    assert np.abs(out["v_n"][0] - truth.v_n).max() < 1e-4
    rm, rn = earth.radii(LAT)
    assert np.abs(out["lat"][0] - truth.lat).max() * rm < 1e-2  # metres after 60 km of travel
    assert np.abs(out["lon"][0] - truth.lon).max() * rn * np.cos(LAT) < 1e-2


def test_turntable_sequence_reaches_the_analytic_attitude():
    seq = tj.RotationSequence(initial=(0.0, 0.0, 0.0), segments=(
        tj.Rotation((1, 0, 0), 10 * D, 9.0), tj.Rotation((0, 0, 1), -20 * D, 4.5, frame="nav"),
        tj.Rotation((0, 1, 0), 30 * D, 6.0)))
    tr = tj.Trajectory(LAT, LON, H, seq, duration=30.0)
    # body x +90 deg, then nav up -90 deg, then body y +180 deg
    C = attitude.rotvec_to_dcm([0, 0, -np.pi / 2]) @ attitude.rotvec_to_dcm([np.pi / 2, 0, 0])
    C = C @ attitude.rotvec_to_dcm([0, np.pi, 0])
    assert tr.truth([25.0]).C_bn[0] == pytest.approx(C, abs=1e-12)
    _, _, _, phi = run_perfect(tr, 0.01, record_every=10, position_fixed=True)
    # The coning term dth_{k-1} x dth_k / 12 assumes a smooth rate; at each step of the turntable's
    # rate it adds its own size once. Theory: the error is that sum, nothing more.
    _, dth, _ = tr.increments(0.0, 0.01, 3000)
    coning = np.linalg.norm(np.cross(dth[:-1], dth[1:]), axis=1).sum() / 12
    err = np.linalg.norm(phi[-1])
    assert err < coning + 0.01 * units.ARCSEC
    assert err > 0.5 * coning


def test_static_kinematics_are_gravity_and_earth_rate():
    C = attitude.euler_to_dcm([1 * D, -2 * D, 123 * D])
    tr = tj.Trajectory(LAT, LON, H, tj.EulerSway(mean=(1 * D, -2 * D, 123 * D)), duration=10.0)
    w, f = tr.kinematics(np.array([0.0, 5.0]))
    assert w[1] == pytest.approx(C.T @ earth.earth_rate_n(LAT), abs=1e-18)
    assert f[1] == pytest.approx(C.T @ [0, 0, earth.gravity(LAT, H)], abs=1e-14)


def test_euler_rates_match_finite_differences_of_attitude():
    sway = tj.EulerSway(mean=(0.1, 0.2, 0.3), amplitude=(0.1, 0.2, 0.3), frequency=(0.3, 0.2, 0.1), phase=(0.1, 0.5, 1))
    t = np.array([1.3])
    h = 1e-5
    C0, w = sway.attitude(t)
    Cp, _ = sway.attitude(t + h)
    Cm, _ = sway.attitude(t - h)
    W = C0[0].T @ (Cp[0] - Cm[0]) / (2 * h)  # = [w_nb^b x]
    assert [W[2, 1], W[0, 2], W[1, 0]] == pytest.approx(w[0], abs=1e-8)


def test_the_compiled_kernel_agrees_with_its_numpy_oracle(monkeypatch):
    rng = np.random.default_rng(3)
    th = rng.standard_normal((3, 400, 3)) * 1e-3
    dv = rng.standard_normal((3, 400, 3)) * 1e-2 + [0, 0, 0.098]
    cmd = rng.standard_normal((3, 400, 3)) * 1e-4
    outs, calls = [], []
    for oracle in (False, True):
        if oracle:
            monkeypatch.setattr(strapdown, "_integrate_numba", lambda *a: calls.append(integrate_numpy(*a)))
        sd = Strapdown(NavState.broadcast(3, np.eye(3), lat=0.6, h=100.0), 0.01)
        outs.append(sd.run(th, dv, omega_cmd=cmd, record_every=7))
    # The kernel and its oracle round differently in each sample's attitude update: the two rotation matrices (NumPy's I + a K +
    # b K K against the closed form: about 5 roundings an entry each) and the two 3x3 products (3 each, summed in
    # BLAS's order and with its fused multiply-adds): 16 roundings of |C| = 1 a sample, n samples in all. Every later
    # velocity increment is turned by that attitude, so the velocity differs by as many roundings of the sum of the
    # increments' sizes (the specific force's and gravity's); the position by as many of its own size (one addition
    # a sample) and of the distance that velocity size covers over the record (m for the height; over the earth's
    # radius, rad, for latitude and longitude). 6.4e3 roundings: 1.4e-12 of the attitude, 1e-9 of the velocity's
    # gross size, where a sample's turn here is 1e-3.
    n, dt = th.shape[1], 0.01
    moved = n * (np.abs(dv).max() + earth.gravity(0.6, 100.0) * dt)  # m/s: all the velocity increments' sizes
    for key, size in (("C_bn", 1.0), ("v_n", moved), ("lat", 0.6 + moved * n * dt / earth.A),
                      ("lon", moved * n * dt / earth.A), ("h", 100.0 + moved * n * dt)):
        agree_to_rounding(outs[0][key], outs[1][key], 16 * n, size)
    assert len(calls) == 1  # the second run went through the oracle


def test_chunked_equals_one_piece():
    rng = np.random.default_rng(4)
    th = rng.standard_normal((2, 300, 3)) * 1e-3
    dv = rng.standard_normal((2, 300, 3)) * 1e-2 + [0, 0, 0.098]
    a = Strapdown(NavState.broadcast(2, np.eye(3), lat=0.6), 0.01)
    whole = a.run(th, dv)
    b = Strapdown(NavState.broadcast(2, np.eye(3), lat=0.6), 0.01)
    parts = [b.run(th[:, i:i + 70], dv[:, i:i + 70]) for i in range(0, 300, 70)]
    v = np.concatenate([p["v_n"] for p in parts], axis=1)
    # the same kernel, but each run ends re-orthonormalising the attitude, which moves it by its non-orthogonality
    # so far: at most the attitude's roundings, 16 a sample (test_the_compiled_kernel_agrees_with_its_numpy_oracle), turning every
    # later velocity increment by as much: 16 n roundings of the increments' summed sizes (1e-9 of them)
    n, dt = th.shape[1], 0.01
    agree_to_rounding(v, whole["v_n"], 16 * n, n * (np.abs(dv).max() + earth.gravity(0.6) * dt))


def test_one_arcmin_tilt_oscillates_with_the_schuler_period():
    dt = 0.1
    tr = tj.Trajectory(LAT, LON, 0.0, tj.EulerSway(mean=(0, 0, 0)), duration=3 * 3600.0)
    n = int(tr.duration / dt)
    t, dth, dv = tr.increments(0.0, dt, n)
    C0 = attitude.apply_misalignment(np.eye(3), [units.ARCMIN, 0, 0])
    sd = Strapdown(NavState.broadcast(1, C0, lat=LAT, lon=LON, h=0.0), dt, height_fixed=True)
    out = sd.run(dth[None], dv[None], record_every=10)
    tt = t[9::10]
    vn = out["v_n"][0, :, 1]
    # upward zero crossings of the north velocity error, interpolated
    i = np.nonzero((vn[:-1] < 0) & (vn[1:] >= 0))[0]
    tz = tt[i] - vn[i] * (tt[i + 1] - tt[i]) / (vn[i + 1] - vn[i])
    period = np.diff(tz).mean()
    assert period / 60 == pytest.approx(earth.schuler_period(LAT) / 60, rel=5e-3)
    assert period / 60 == pytest.approx(84.4, abs=0.6)  # Foucault modulation shifts single cycles slightly
    # amplitude of the velocity error: g * phi / omega_s
    assert np.abs(vn).max() == pytest.approx(earth.gravity(LAT) * units.ARCMIN / earth.schuler_frequency(LAT), rel=0.05)


def test_pyins_sway_file_strapdown_reaches_its_last_attitude():
    t, g, a, meta = load_fixture("pyins_sway_lat30s")
    dt = t[1] - t[0]
    th = 0.5 * (g[1:] + g[:-1]) * dt  # instantaneous samples: trapezoid increments
    dv = 0.5 * (a[1:] + a[:-1]) * dt
    s = NavState.broadcast(1, np.array(meta["C_bn_first"]), lat=np.radians(meta["lat_deg"]), h=meta["height_m"])
    out = Strapdown(s, dt, position_fixed=True).run(th[None], dv[None])
    err = attitude.misalignment(out["C_bn"][0, -1], np.array(meta["C_bn_last"]))
    assert np.abs(err).max() < 0.05 * units.ARCSEC


def test_psins_copy_reaches_the_same_attitude_within_its_quantisation():
    t, g, a, meta = load_fixture("pyins_sway_lat30s")
    imu, hdr = read_psins(DATA / "pyins_sway_lat30s.imu")
    C0 = attitude.euler_to_dcm(hdr["attitude0"])
    assert attitude.misalignment(C0, np.array(meta["C_bn_first"])) == pytest.approx(np.zeros(3), abs=1e-6 * D)
    _, dth, dv = imu.increments()
    out = Strapdown(NavState.broadcast(1, C0, lat=hdr["lat"], h=hdr["h"]), imu.dt, position_fixed=True).run(dth, dv)
    err = attitude.misalignment(out["C_bn"][0, -1], np.array(meta["C_bn_last"]))
    # the file rounds each trapezoid increment to 0.01 arcsec without carrying the remainder, so the
    # attitude drifts by the summed rounding errors (rotated by at most a few degrees of sway)
    dt = t[1] - t[0]
    exact = 0.5 * (g[1:] + g[:-1]) * dt
    drift = np.abs((dth[0] - exact).sum(axis=0))
    bound = np.linalg.norm(drift) + 0.05 * units.ARCSEC + 0.1 * np.linalg.norm(drift)
    assert np.linalg.norm(err) < bound
    assert np.linalg.norm(err) > 0.5 * np.linalg.norm(drift)  # the drift is really there


def test_ship_profile_position_after_20_hours_matches_the_closed_form():
    lat = 35 * D
    tr = tj.ship(lat, 241 * D, accel=0.05)
    t_acc = 20.0 / 0.05
    s = tr.truth([tr.duration, 12 * 3600.0 + t_acc / 2])
    distance = 0.5 * 0.05 * t_acc**2 + 20.0 * (tr.duration - 12 * 3600.0 - t_acc)
    _, rn = earth.radii(lat)
    assert s.lat[0] == pytest.approx(lat, abs=1e-14)
    assert (s.lon[0] - 241 * D) * rn * np.cos(lat) == pytest.approx(distance, rel=1e-10)
    assert s.v_n[0] == pytest.approx([20.0, 0.0, 0.0], abs=1e-12)
    assert s.v_n[1, 0] == pytest.approx(10.0, rel=1e-12)
    # sea sway: pitch 1.2 deg sin(2 pi t / 7)
    e = attitude.dcm_to_euler(tr.truth([1.75]).C_bn[0])
    assert np.degrees(e[0]) == pytest.approx(1.2, abs=1e-9)


def test_moored_profile_is_seed000_table1():
    tr = tj.moored(LAT, duration=60.0)
    v, _ = tr.velocity(np.linspace(0, 600, 60001))
    assert v.std(axis=0) == pytest.approx([0.05] * 3, rel=0.1)  # RMS of the 16-tone multisine
    # pitch 5 deg sin(2 pi 0.5 t) peaks at t = 0.5 s, roll 7 deg sin(2 pi 0.3 t) at t = 5/6 s
    assert np.degrees(attitude.dcm_to_euler(tr.truth([0.5]).C_bn[0])[0]) == pytest.approx(5.0, abs=1e-9)
    assert np.degrees(attitude.dcm_to_euler(tr.truth([5 / 6]).C_bn[0])[1]) == pytest.approx(7.0, abs=1e-9)
