"""kf and akf with a receiver's rows (baselines/kalman_aiding.py): a car that turns, velocity or positions at the
receiver's own rate, a lever arm, a latency, an outage; the hand-over from the coarse stage; the measurement model.

The final attitude is judged against the filter's own predicted sigma over RUNS recordings: for a consistent filter
each run's error over its sigma is a unit normal (the sigma holds the biases' prior too, so the fixed biases the
simulation gives every run stay inside it), and the RMS over RUNS runs of that ratio exceeds LIMIT with probability
P(chi2_RUNS > RUNS LIMIT^2) = P(chi2_4 > 25) = 5e-5 per axis. The same data read wrongly (the lever arm ignored, the
rows one epoch late, the latency ignored) must fail that same criterion.
"""

from dataclasses import replace

import numpy as np
import pytest

from baselines.kalman import AdaptiveKalmanAligner, KalmanAligner
from baselines.kalman_aiding import Rows, attitude_at_start, initial_motion, step_measurement
from fusionbench.methods.aligner import Site
from fusionbench.simulation import attitude, imu, units  # noqa: F401  (imu before aidingsim: imusim imports it)
from fusionbench.simulation.aidingsim import AidingSpec, simulate_aiding
from fusionbench.simulation.drive import car_drive
from fusionbench.simulation.imu import PRESETS, simulate
from tests.conftest import agree_to_rounding

D = np.pi / 180
LAT = 34 * D
SITE = Site(LAT, 1.9, 100.0)
RUNS = 4
DT = 0.02
LIMIT = 2.5
SPEC = PRESETS["navigation"]


@pytest.fixture(scope="module")
def car():
    """A car's 300-s drive with 40-deg turns at 5 deg/s (fusionbench.simulation.drive.car_drive), 50 Hz, RUNS
    recordings."""
    tr = car_drive(LAT, 1.9, 100.0, heading=30 * D, duration=300.0)
    data = simulate(tr, SPEC, DT, runs=RUNS, seed=5)
    C_true0 = tr.truth([data.t0]).C_bn[0]
    init = attitude.apply_misalignment(C_true0, [0.5 * D, -0.5 * D, 3 * D])  # a coarse start's errors
    return tr, data, init, tr.truth([data.t[-1]]).C_bn[0]


def rows(car, spec):
    tr, data, _, _ = car
    return simulate_aiding(tr, spec, runs=RUNS, seed=5, grid=data.t)


def normalised(car, aiding, method=KalmanAligner):
    """RMS over the runs of the final misalignment over the filter's final sigma (3,), E, N, U."""
    _, data, init, C_end = car
    res = method(imu=SPEC, vref_sigma=0.05).align(data, SITE, aiding=aiding, init=init)
    phi = attitude.misalignment(res.C_bn_final, C_end)
    return np.sqrt(np.mean((phi / res.sigma_phi[:, -1]) ** 2, axis=0)), res


def late(car, aiding, by):
    """The same rows read ``by`` seconds late (their stamps shifted), those past the record dropped."""
    return replace(aiding, t=aiding.t + by).window(-np.inf, car[1].t[-1])


@pytest.mark.parametrize("spec", [AidingSpec(10.0, (0.05,) * 3), AidingSpec(1.0, (0.05,) * 3),
                                  AidingSpec(1.0, None, (0.5, 0.5, 1.0))], ids=["v10hz", "v1hz", "p1hz"])
def test_rows_at_their_rate_align_within_the_predicted_sigma_and_one_epoch_late_do_not(car, spec):
    aid = rows(car, spec)
    ok, res = normalised(car, aid)
    assert np.all(ok < LIMIT), ok
    # what the rows give: about 1 arcmin of azimuth with 10-Hz velocity, 3 with 1-Hz rows (the filter's sigma)
    assert res.sigma_phi[:, -1, 2].max() < (1.5 if spec.rate_hz == 10.0 else 4.0) * units.ARCMIN
    bad, _ = normalised(car, late(car, aid, 1.0 / spec.rate_hz))
    assert bad.max() > LIMIT, bad


def test_a_lever_arm_is_in_the_model(car):
    # 1.5 m ahead of the IMU: 0.13 m/s across the car in a 5 deg/s turn, 2.6 times the rows' noise
    aid = rows(car, AidingSpec(10.0, (0.05,) * 3, lever_arm=(0.0, 1.5, 0.0)))
    ok, _ = normalised(car, aid)
    assert np.all(ok < LIMIT), ok
    ignored, _ = normalised(car, replace(aid, lever_arm=np.zeros(3)))
    assert ignored.max() > LIMIT, ignored


def test_rows_are_used_at_their_time_of_validity(car):
    aid = rows(car, AidingSpec(10.0, (0.05,) * 3, delay=0.05))  # stamped 50 ms after they measure
    ok, _ = normalised(car, aid)
    assert np.all(ok < LIMIT), ok
    # read at their stamps: 50 ms at the turns' 0.9 m/s^2 (braking 1 m/s^2) is 0.05 m/s, the rows' noise, every row
    ignored, _ = normalised(car, replace(aid, delay=0.0).window(-np.inf, car[1].t[-1]))
    assert ignored.max() > LIMIT, ignored


def test_an_outage_is_bridged_by_prediction(car):
    aid = rows(car, AidingSpec(10.0, (0.05,) * 3, outages=((150.0, 210.0),)))
    ok, res = normalised(car, aid)
    assert np.all(ok < LIMIT), ok
    # no update in the outage, prediction only: the level sigma grows (the accelerometers' and gyros' noise), the
    # azimuth's stays (60 s of 0.002 deg/sqrt(h) gyro noise add 0.016 arcmin in quadrature to 1.4: 7e-5 of it);
    # the first seconds of rows after it bring both down
    sig = res.sigma_phi[0]
    at = lambda t: sig[np.searchsorted(res.t, t)]  # noqa: E731
    assert np.all(at(209.9)[:2] > at(150.0)[:2])
    assert at(209.9)[2] == pytest.approx(at(150.0)[2], rel=1e-3)
    assert np.all(at(230.0) < at(209.9))


def test_akf_with_a_lever_arm_and_positions(car):
    aid = rows(car, AidingSpec(10.0, (0.05,) * 3, (0.5, 0.5, 1.0), lever_arm=(0.5, 1.2, 0.73)))
    ok, _ = normalised(car, aid, AdaptiveKalmanAligner)
    assert np.all(ok < LIMIT), ok


def test_the_coarse_start_hands_over_on_a_moving_base(car):
    # from its own coarse stage (velocity at every increment, which the coarse stage reads), the filter re-running
    # the coarse stage's span from the attitude carried back to the start
    tr, data, _, C_end = car
    aid = simulate_aiding(tr, AidingSpec(1.0 / DT, (0.05,) * 3), runs=RUNS, seed=5, grid=data.t)
    res = KalmanAligner(imu=SPEC, vref_sigma=0.05).align(data, SITE, aiding=aid)
    assert res.t[0] < 60.0 < res.t[np.isfinite(res.sigma_phi[0, :, 0])][0] < 60.0 + 0.2  # reported from the hand-over
    phi = attitude.misalignment(res.C_bn_final, C_end)
    ratio = np.sqrt(np.mean((phi / res.sigma_phi[:, -1]) ** 2, axis=0))
    assert np.all(ratio < LIMIT), ratio


def test_the_attitude_carried_back_to_the_start_is_the_true_one():
    # a perfect IMU: the carry-back is the strapdown's own turn of the body and the frame's of the earth and the
    # transport rate; what it leaves out is 6e-7 rad (0.002 arcmin) over a minute
    tr = car_drive(60 * D, 1.9, 100.0, heading=30 * D, duration=70.0)
    data = simulate(tr, SPEC.perfect(), DT, runs=1)
    aid = simulate_aiding(tr, AidingSpec(10.0, (0.0,) * 3), runs=1, grid=data.t)
    t, dth, dv = data.increments()
    k = int(round(60.0 / DT))
    C0 = attitude_at_start(tr.truth([t[k - 1]]).C_bn, dth[:, :k], dv[:, :k], DT, Site(60 * D, 1.9, 100.0), aid,
                           data.t0, t[k - 1])
    err = attitude.misalignment(C0[0], tr.truth([data.t0]).C_bn[0])
    assert np.abs(err).max() < 0.005 * units.ARCMIN, err / units.ARCMIN


@pytest.mark.parametrize("kind", ["velocity", "position"])
def test_the_hand_over_velocity_is_the_imus_within_its_sigma(car, kind):
    # in a turn (from 34 s at 5 deg/s, 6 m/s), 1.5 m of lever arm: the antenna moves 0.13 m/s faster across than the IMU
    tr, data, _, _ = car
    spec = AidingSpec(10.0, (0.05,) * 3, lever_arm=(0.0, 1.5, 0.0)) if kind == "velocity" else \
        AidingSpec(1.0, None, (0.5, 0.5, 1.0), lever_arm=(0.0, 1.5, 0.0))
    aid = simulate_aiding(tr, spec, runs=RUNS, seed=5, grid=data.t)
    t_h = 38.0
    truth = tr.truth([t_h])
    k = int(round(t_h / DT)) - 1
    v0, sigma, p0, sp = initial_motion(aid, t_h, np.broadcast_to(truth.C_bn[0], (RUNS, 3, 3)),
                                       data.increments()[1][:, k] / DT, LAT, RUNS, 0.05, 2.0, 3 * D)
    err = v0[:, :2] - truth.v_n[0, :2]
    assert np.all(np.abs(err) < 3 * sigma), (err, sigma)
    if kind == "velocity":  # 10-Hz rows: the rows' noise and 2 m/s^2 over a quarter of 0.1 s, 0.07 m/s
        assert np.all(sigma < 0.08) and p0 is None
    else:  # differenced 1-Hz positions: 0.7 m/s of noise
        assert np.all(sigma < 1.0)
        dp = (p0[:, :2] - [truth.lat[0], truth.lon[0]]) * [6.36e6, 6.39e6 * np.cos(LAT)]  # m, north and east
        assert np.all(np.abs(dp) < 3 * sp[::-1]), (dp, sp)


def test_the_rows_of_a_step_make_their_weighted_mean():
    # three velocity rows at rest in a step of 5 increments, with their own sigmas, valid 0.06, 0.03 and 0 s before the
    # step's end: one measurement per channel, the weighted mean of the rows, its variance 1 / sum(1 / sigma^2), and
    # H shifted by the weighted mean time (H (I - F s))
    R, m, nx = 2, 5, 11
    rng = np.random.default_rng(0)
    v = rng.normal(size=(R, m + 1, 3))
    F = rng.normal(size=(R, nx, nx))
    k = np.array([1, 2, 4])
    sv = np.array([[0.1, 0.2], [0.2, 0.2], [0.05, 0.4]])
    meas = rng.normal(size=(R, 3, 2))
    z_rows = v[:, k + 1, :2] - meas
    rows = Rows(k, np.ones(3), np.array([0.04, 0.07, 0.1]), np.ones(3, bool), np.ones(3, bool), np.zeros(3, bool),
                meas, None, sv, np.ones((3, 2)), np.zeros(3))
    rows.before_end(np.arange(1, m + 1) * 0.02 + 0.0, m)
    assert rows.s == pytest.approx([0.06, 0.03, 0.0], abs=1e-12)
    z, H, r, chan = step_measurement(rows, 0, 3, 0, lambda name, j: v[:, j], np.zeros((R, m, 3)), F)
    w = 1 / sv**2
    assert z == pytest.approx(np.sum(w * z_rows, axis=1) / w.sum(0), rel=1e-12)
    assert r == pytest.approx(1 / w.sum(0), rel=1e-12)
    s_mean = np.sum(w * rows.s[:, None], axis=0) / w.sum(0)
    H_expected = np.zeros((R, 2, nx))
    H_expected[:, 0, 3] = H_expected[:, 1, 4] = 1.0
    H_expected -= s_mean[None, :, None] * F[:, 3:5, :]
    assert H == pytest.approx(H_expected, rel=1e-12, abs=1e-15)
    assert chan.tolist() == [0, 1]


@pytest.mark.parametrize("method", [KalmanAligner, AdaptiveKalmanAligner])
def test_the_batched_filters_give_filterpys_estimates_with_positions_and_a_lever_arm(method):
    # 13 states, rows between the sample ends (10 Hz on a 30-Hz record), the lever arm in H: the engines agree to
    # what rounding leaves after 1000 steps
    tr = car_drive(LAT, 1.9, 100.0, heading=30 * D, duration=100.0)
    data = simulate(tr, SPEC, 1 / 30, runs=2, seed=2)
    aid = simulate_aiding(tr, AidingSpec(10.0, (0.05,) * 3, (0.5, 0.5, 1.0), lever_arm=(0.5, 1.2, 0.73)), runs=2,
                          seed=2, grid=data.t)
    aid = replace(aid, t=aid.t + 0.005).window(-np.inf, data.t[-1])  # off the sample grid
    init = attitude.apply_misalignment(tr.truth([data.t0]).C_bn[0], [0.3 * D, -0.2 * D, 2 * D])
    a = method(imu=SPEC).align(data, SITE, aiding=aid, init=init)
    b = method(imu=SPEC, engine="filterpy").align(data, SITE, aiding=aid, init=init)
    # einsum's matrix-vector products against filterpy's BLAS calls, through the feedback into the covariance:
    # steps x n^2 roundings of each quantity's size (n = 13 states; tests/test_kalman.py), 3.7e-11 of it
    roundings = a.t.size * 13**2
    agree_to_rounding(a.C_bn, b.C_bn, roundings)
    agree_to_rounding(a.sigma_phi, b.sigma_phi, roundings)


def test_a_bad_position_sigma_is_one_line_naming_the_option():
    with pytest.raises(ValueError, match=r"^kf: option aiding_position_sigma: expected a number >= 0, found -1"):
        KalmanAligner(aiding_position_sigma=-1.0)
