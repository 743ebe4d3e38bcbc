"""coarse-i0 with aiding at a receiver's epochs: velocity or position rows, a lever arm, a latency, outages and rows at
rest, on a car that turns (fusionbench.simulation.drive.car_drive) and on seed 001's accelerating base (0.1 g for 300
s)."""

from dataclasses import replace

import numpy as np
import pytest

from fusionbench.methods import coarse_i0
from fusionbench.methods.aligner import Site
from fusionbench.methods.coarse import InertialCoarseAligner
from fusionbench.methods.coarse_aided import aiding_rows, fit_blocks, place
from fusionbench.methods.coarse_inertial import c_n_i0, cumulative_trapezoid, velocity_integral_inertial
from fusionbench.simulation import attitude, trajectory as tj, units
from fusionbench.simulation.aiding import Aiding
from fusionbench.simulation.aidingsim import AidingSpec, simulate_aiding
from fusionbench.simulation.drive import car_drive
from fusionbench.simulation.imu import IMUSpec, simulate
from fusionbench.simulation.imudata import IMUData
from tests.conftest import agree_to_rounding

D = np.pi / 180
LAT, T = 34 * D, 300.0
LEVER = (0.3, 1.5, 0.8)  # m, body RFU: 1.5 m ahead, 0.13 m/s of lever velocity in a 5 deg/s turn
#: A perfect IMU and noise-free rows: the model is exact but for the trapezoid rule over the rows and the IMU's
#: bridges (second order in their interval: below 1e-4 m/s of V_i0), the lever velocity's residual after two
#: corrections (1e-4 arcmin) and the relevelling's frame average (2e-3 arcmin on the accelerating base); measured
#: at most 2e-3 arcmin. The per-increment reference's test uses the same figure.
EXACT = 0.01 * units.ARCMIN


def _data(traj, dt=0.01, runs=1, seed=0):
    return simulate(traj, IMUSpec(), dt, runs=runs, seed=seed)


@pytest.fixture(scope="module")
def car():
    # the drive starts 0.05 s in, so that no receiver epoch (whole tenths of a second) falls on a leg boundary, where
    # the turn rate jumps and the lever velocity has no single value
    traj = car_drive(LAT, 0.3, 100.0, heading=30 * D, duration=T, pitch=0.5 * D, roll=-1 * D, wait=0.05)
    return traj, _data(traj)


@pytest.fixture(scope="module")
def accel():
    traj = tj.accelerating(LAT, mean=(0.5 * D, -1 * D, -30 * D), duration=T)
    return traj, _data(traj)


def _error(traj, data, aiding, **options):
    """Misalignment (R, 3) rad at the last sample."""
    res = InertialCoarseAligner(**options).align(data, Site(traj.lat, traj.lon, traj.h), aiding=aiding)
    assert res.t_end == pytest.approx(data.t_last)
    return attitude.misalignment(res.C_bn_final, traj.truth([data.t_last]).C_bn[0])


def _rows(traj, data, rate, kind="velocity", sigma=0.0, runs=1, seed=0, **spec):
    v, p = ((sigma,) * 3, None) if kind == "velocity" else (None, (sigma,) * 3)
    return simulate_aiding(traj, AidingSpec(rate, v, p, **spec), runs=runs, seed=seed, grid=data.increments()[0])


CASES = {  # rate Hz, kind, receiver
    "velocity-10hz": (10.0, "velocity", {}),
    "velocity-1hz": (1.0, "velocity", {}),
    "position-1hz": (1.0, "position", {}),
    "velocity-10hz-lever-delay-outage": (10.0, "velocity", dict(lever_arm=LEVER, delay=0.05, outages=((100.0, 160.0),))),
    "velocity-1hz-lever-delay-outage": (1.0, "velocity", dict(lever_arm=LEVER, delay=0.05, outages=((100.0, 160.0),))),
    "position-1hz-lever-delay-outage": (1.0, "position", dict(lever_arm=LEVER, delay=0.05, outages=((100.0, 160.0),))),
    "velocity-1hz-cold-start-and-lost-at-the-end": (1.0, "velocity", dict(outages=((0.0, 45.0), (240.0, 301.0)))),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("base", ["car", "accel"])
def test_noise_free_rows_align_a_perfect_imu_exactly(case, base, request):
    # a receiver's rows at its own epochs, from an antenna 1.5 m away, 50 ms late, with a 60-s outage (the IMU
    # bridges it; on the rows alone, a straight line across it cost 1.2 arcmin of azimuth on the car), a first fix
    # after 45 s and none over the last 60 s: what the method models, exactly
    traj, data = request.getfixturevalue(base)
    rate, kind, spec = CASES[case]
    assert np.abs(_error(traj, data, _rows(traj, data, rate, kind, **spec))).max() < EXACT


@pytest.mark.parametrize("misread", ["lever arm ignored", "delay ignored", "read one epoch late"])
def test_rows_misread_cost_arcminutes_on_a_turning_car(car, misread):
    # the same rows read right are exact (above); read wrong, the car's turns and speed changes show it. The error
    # velocity: the lever velocity omega x l = 0.13 m/s in the turns; a 50-ms delay or a 0.1-s epoch times the
    # car's acceleration (0.5 m/s^2 centripetal, 1 m/s^2 braking): 0.03-0.1 m/s, against horizontal V_i0 signals of
    # 10-30 m/s and averaged over the fit's blocks (measured 1.3, 2.2 and 4.5 arcmin of azimuth)
    traj, data = car
    aid = _rows(traj, data, 10.0, lever_arm=LEVER, delay=0.05)
    assert np.abs(_error(traj, data, aid)).max() < EXACT
    if misread == "lever arm ignored":
        bad = replace(aid, lever_arm=np.zeros(3))
    elif misread == "delay ignored":
        bad = replace(aid, delay=0.0).window(-np.inf, data.t_last)
    else:  # each row's values at the next row's time
        bad = replace(aid.rows(np.arange(1, aid.t.size)), velocity=aid.velocity[:, :-1])
    assert abs(_error(traj, data, bad)[0, 2]) > 30 * EXACT


def _linear_fit_cov(U, S):
    """Covariance (3, 3) of the rotation theta (rad) that a least-squares fit of vectors U (n, 3) takes from their
    errors of covariance S (3n, 3n): to first order the fit solves ``dU_k = -[U_k x] theta``."""
    A = np.concatenate([-attitude.skew(u) for u in U])
    M = np.linalg.solve(A.T @ A, A.T)
    return M @ S @ M.T


def _check_spread(err, sigma):
    """Errors (runs, 3) rad against the predicted sigma (3,): within 4 sigma, their rms within [0.4, 1.6] sigma
    (8 runs: the rms of 8 normal draws is within [0.52, 1.40] sigma 95 % of the time)."""
    assert np.all(np.abs(err) < 4 * sigma)
    rms = np.sqrt(np.mean(err**2, axis=0))
    assert np.all(rms > 0.4 * sigma) and np.all(rms < 1.6 * sigma)


@pytest.mark.parametrize("kind", ["velocity", "position"])
def test_noisy_rows_cost_what_the_linearized_fit_leaves(car, kind):
    # 1-Hz rows on the car, 8 runs of a perfect IMU: the rows' white noise passes through the fit as a linear
    # least-squares problem, so the attitude's spread is predicted from the noise-free fit vectors (at the end, in n).
    # Velocity (0.05 m/s): the rows' noise C_n^i0 dv in each block mean and in the anchor's (common to all blocks);
    # predicted 0.037, 0.013, 3.9 arcmin, measured rms 0.025, 0.011, 3.3. Position (0.5 m): the position form's
    # displacements carry each row's noise once (their sum telescopes), less the constant and the line projected
    # out; predicted 0.017, 0.003, 1.8, measured 0.017, 0.002, 1.8.
    traj, _ = car
    runs = 8
    data = _data(traj, 0.02, runs=runs, seed=2)
    t_end = data.increments()[0]
    clean = _rows(traj, data, 1.0, kind)
    truth = _rows(traj, data, 10.0)  # the true velocity at 10 Hz: V_i0 of the truth, for the position form's signal
    C_end = c_n_i0(np.array([T - data.t0]), LAT, np.full((1, 1), LAT), np.zeros((1, 1)))[0, 0]
    if kind == "velocity":
        sigma = 0.05
        rows = aiding_rows(clean, 1, "test")
        starts, stops = fit_blocks(place(t_end, data.t0, rows).k, 50, t_end, "test")
        V, _ = velocity_integral_inertial(rows.tau, data.t0, rows.v, LAT, 0.0)
        means = np.array([V[0, a:b].mean(axis=0) for a, b in zip(starts, stops)])
        n = (stops - starts).astype(float)
        S = sigma**2 * (np.kron(np.diag(1 / n[1:]), np.eye(3)) + np.kron(np.ones((n.size - 1,) * 2), np.eye(3)) / n[0])
        cov = _linear_fit_cov(means[1:] - means[0], S)
    else:
        sigma = 0.5
        tp = clean.t_valid
        V, _ = velocity_integral_inertial(truth.t_valid, data.t0, truth.velocity, LAT, 0.0)
        Dfull = cumulative_trapezoid(V, truth.t_valid)[0]  # int V_i0, m, at 10 Hz (the position rows are on it)
        Dp = Dfull[np.searchsorted(truth.t_valid, tp)]
        B, _ = np.linalg.qr(np.column_stack([np.ones_like(tp), tp - tp.mean()]))
        Pi = np.eye(tp.size) - B @ B.T
        cov = _linear_fit_cov(Pi @ Dp, sigma**2 * np.kron(Pi, np.eye(3)))
    pred = np.sqrt(np.diag(C_end.T @ cov @ C_end))
    err = _error(traj, data, _rows(traj, data, 1.0, kind, sigma, runs=runs, seed=2))
    _check_spread(err, pred)


@pytest.mark.parametrize("case", ["velocity-1hz-lever-delay-outage", "position-1hz-lever-delay-outage"])
def test_the_fit_on_the_rows_a_run_at_a_time_gives_the_whole_batchs(car, case, monkeypatch):
    # a 50-run batch with a velocity row on every sample held the fit's (R, rows, 3, 3) frames at once (0.73 GB):
    # coarse-i0 fits a few runs at a time. Each run's fit is its own (noisy rows and IMU of its own: a run's track or
    # rotation given to another moves its attitude by arcminutes), so one run per chunk gives the batch's attitudes
    # and residuals to rounding (the same operations on arrays of another length: bit for bit here, an ulp or so per
    # step of the 300-s track on another CPU's vector loops)
    traj, _ = car
    data = _data(traj, 0.02, runs=3, seed=4)
    rate, kind, spec = CASES[case]
    aid = _rows(traj, data, rate, kind, 0.05 if kind == "velocity" else 0.5, runs=3, seed=4, **spec)
    site = Site(traj.lat, traj.lon, traj.h)
    whole = InertialCoarseAligner().align(data, site, aiding=aid)
    monkeypatch.setattr(coarse_i0, "CHUNK_SAMPLES", 1)  # one run at a time, in the pass and in the fit
    parts = InertialCoarseAligner().align(data, site, aiding=aid)
    assert np.ptp(attitude.misalignment(whole.C_bn_final, whole.C_bn_final[:1]), axis=0).max() > units.ARCMIN
    agree_to_rounding(parts.C_bn, whole.C_bn, roundings=1e4, scale=1.0)
    for key in ("fit_residual_mps", "gravity_excess"):
        agree_to_rounding(parts.extra[key], whole.extra[key], roundings=1e4)


def test_a_coarse_stage_on_the_rows_of_part_of_a_record(car):
    # coarse_then_fine gives coarse-i0 the first part of the record and the rows valid in it: 60 s of the car (its
    # start, a stretch, a braking and a turn) with 1-Hz rows from an antenna on a lever arm, late by 50 ms
    traj, data = car
    aid = _rows(traj, data, 1.0, lever_arm=LEVER, delay=0.05)
    t, dth, dv = data.increments()
    k0 = int(round(60.0 / data.dt))
    part = IMUData(t[:k0], dth[:, :k0], dv[:, :k0], "increment")
    res = InertialCoarseAligner(caller="kf").align(part, Site(traj.lat, traj.lon, traj.h),
                                                   aiding=aid.window(-np.inf, t[k0 - 1]))
    assert np.abs(attitude.misalignment(res.C_bn_final, traj.truth([t[k0 - 1]]).C_bn[0])).max() < EXACT


def test_rows_at_rest_are_the_imus_zero_velocity_whatever_the_lever_arm(car):
    # a car waiting 60.5 s at a light before it drives (its turn rates jump off the receiver's epochs): 1-Hz rows
    # that say "at rest" (no velocity) while it waits, the antenna's velocity after; a static base given rows at rest
    traj = car_drive(LAT, heading=-100 * D, wait=60.5, duration=T)
    data = _data(traj, 0.02)
    aid = _rows(traj, data, 1.0, lever_arm=LEVER)
    rest = aid.t_valid <= 60.5
    v = aid.velocity.copy()
    v[:, rest] = np.nan
    aid = replace(aid, velocity=v, at_rest=rest)
    assert np.abs(_error(traj, data, aid)).max() < EXACT
    still = tj.Trajectory(LAT, 0.0, 0.0, tj.EulerSway(mean=(0.5 * D, -1 * D, -30 * D)), duration=120.0)
    data = _data(still, 0.02)
    tv = np.arange(1.0, 121.0)
    assert np.abs(_error(still, data, Aiding(tv, at_rest=np.ones(tv.size, bool)))).max() < EXACT


def test_too_few_rows_are_refused_in_one_line_naming_the_method_and_the_field(car):
    traj, data = car
    site = Site(traj.lat)
    pos = _rows(traj, data, 1.0, "position")
    with pytest.raises(ValueError, match=r"^coarse-i0: aiding: expected velocity rows or at least 4 position rows "
                                         r"with consecutive pairs, found 3 position rows and no velocity$"):
        InertialCoarseAligner().align(data, site, aiding=pos.rows([10, 11, 12]))
    vel = _rows(traj, data, 1.0)
    with pytest.raises(ValueError, match=r"^kf \(coarse-i0 start\): aiding: expected at least 3 rows, found 2 from "
                                         r"100\.000 to 200\.000 s$"):
        InertialCoarseAligner(caller="kf").align(data, site, aiding=vel.rows([99, 199]))
