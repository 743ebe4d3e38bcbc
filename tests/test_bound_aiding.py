"""bound.attainable_bound with a receiver's rows and bound.bias_limit: a Monte Carlo of the optimal filter on an
independently built linear model, the per-increment reference as a receiver at its rate, an outage, the fixed-base
limit, bad input."""

import numpy as np
import pytest
from scipy.linalg import expm

from fusionbench.scoring import bound, metrics
from fusionbench.simulation import attitude, earth, units
# fusionbench.simulation.imu before fusionbench.simulation.aidingsim: imported first, aidingsim's imports are circular
from fusionbench.simulation.imu import PRESETS, IMUSpec, NoiseSchedule, SensorErrors

from fusionbench.methods.aligner import Site
from fusionbench.simulation.aiding_geometry import lever_offset, lever_velocity  # noqa: I001
from fusionbench.simulation.aidingsim import AidingSpec
from fusionbench.simulation.drive import car_drive

D = np.pi / 180
LAT = 34 * D
SITE = Site(LAT, 1.9, 450.0)
C_STATIC = attitude.euler_to_dcm(np.array([1 * D, -2 * D, -123 * D]))
NAV = PRESETS["navigation"]
ARW = NAV.gyro.white[0]  # rad/sqrt(s)
W_N = earth.OMEGA_IE * np.cos(LAT)  # horizontal earth rate, rad/s
WHITE = IMUSpec(gyro=SensorErrors(white=NAV.gyro.white), accel=SensorErrors(white=NAV.accel.white))


# ---------------------------------------------------------------- 1. the per-increment reference as a receiver
@pytest.mark.parametrize("rate, step_s", [(10.0, 0.5), (1.0, 0.5), (0.5, 0.3)])
def test_rows_at_rest_equal_the_per_increment_reference_at_their_rate(rate, step_s):
    # A fixed base's velocity rows at r Hz with sigma s are the per-increment reference with one sample per step
    # of 1/r s (vref_dt = step = 1/r). The receiver's steps are 1/(k r) s (k = 1, 1 and 7 here); k steps without
    # an update between rows compose exactly into one: the same filter to rounding. The lever arm plays no part at
    # rest (the IMU's velocity is zero whatever it is).
    s = 0.03
    _, ref = metrics.attainable_bound(NAV, 120.0, site=SITE, C_bn=C_STATIC, vref_sigma=s, vref_dt=1 / rate,
                                      step_s=1 / rate)
    t, rows = metrics.attainable_bound(NAV, 120.0, site=SITE, C_bn=C_STATIC, step_s=step_s,
                                       aiding=AidingSpec(rate, (s,) * 3, lever_arm=(0.5, 1.5, 1.0)))
    k = int(np.ceil(1 / (rate * step_s)))
    assert t.size == 120.0 * rate * k and t[-1] == 120.0
    assert rows[k - 1::k] == pytest.approx(ref, rel=1e-7)
    assert rows[-1, 2] / units.ARCMIN > 1.0  # the azimuth of a 2-minute gyrocompass: not a trivial zero


def test_a_receiver_schedule_scales_the_rows_variance_and_the_latency_changes_nothing():
    # factor 4 on the variance after 100 s: the rows' sigma doubled there; the rows count at their valid time
    car = car_drive(LAT, 1.9, 450.0, duration=150.0)
    sched = AidingSpec(2.0, (0.02,) * 3, lever_arm=(0.3, 1.2, 0.9), delay=0.15,
                       schedules=(NoiseSchedule(100.25, 1e9, 4.0),))
    _, s = metrics.attainable_bound(NAV, 150.0, trajectory=car, aiding=sched)
    _, s_to_100 = metrics.attainable_bound(NAV, 100.0, trajectory=car, aiding=AidingSpec(2.0, (0.02,) * 3,
                                                                                         lever_arm=(0.3, 1.2, 0.9)))
    _, s_wide = metrics.attainable_bound(NAV, 150.0, trajectory=car, aiding=AidingSpec(2.0, (0.04,) * 3,
                                                                                       lever_arm=(0.3, 1.2, 0.9)))
    assert s[199] == pytest.approx(s_to_100[-1], rel=1e-9)
    assert s[-1] != pytest.approx(s_wide[-1], rel=0.01)  # the first 100 s had the narrow rows
    _, s_all = metrics.attainable_bound(NAV, 150.0, trajectory=car, aiding=AidingSpec(
        2.0, (0.02,) * 3, lever_arm=(0.3, 1.2, 0.9), schedules=(NoiseSchedule(0.0, 1e9, 4.0),)))
    assert s_all == pytest.approx(s_wide, rel=1e-9)


def test_an_outage_at_the_end_is_the_unaided_propagation():
    # Rows at 1 Hz until 240 s, none after. Unaided, the north tilt is a random walk of the gyro's white noise,
    # phiN' = -wU phiE - w_g: its variance grows by ARW^2 tau over tau = 60 s (the wU phiE coupling adds 1e-5 of
    # that): 0.016 arcmin on the 0.018 of the rows' tracking limit; the azimuth, phiU' = wN phiE - w_g, gains
    # ARW^2 tau against (4.3 arcmin)^2: 1e-5 of it.
    aid = AidingSpec(1.0, (0.02,) * 3)
    _, s240 = metrics.attainable_bound(WHITE, 240.0, site=SITE, aiding=aid)
    _, s300 = metrics.attainable_bound(WHITE, 300.0, site=SITE, aiding=AidingSpec(1.0, (0.02,) * 3,
                                                                                  outages=((240.5, 301.0),)))
    tau = 60.0
    assert s300[-1, 1] == pytest.approx(np.sqrt(s240[-1, 1] ** 2 + ARW**2 * tau), rel=2e-4)
    assert s300[-1, 1] > 1.25 * s240[-1, 1]
    assert s300[-1, 2] == pytest.approx(np.hypot(s240[-1, 2], ARW * np.sqrt(tau)), rel=2e-4)
    # and the bound with the outage agrees with the record's first 240 s up to then
    assert s300[479, :] == pytest.approx(s240[-1], rel=1e-9)


# ------------------------------------------------------------------------------- 2. the limit on a fixed base
def _isotropic_gyro(bias_enu, C, prior, white):
    """Gyro errors with the fixed bias ``bias_enu`` (ENU, rad/s) at attitude C and a prior of ``prior`` on every axis
    (bias_sigma^2 = prior^2 - bias^2: the limit filter's prior is isotropic, so no ENU component leans on another)."""
    b = C.T @ np.asarray(bias_enu)
    return SensorErrors(bias=tuple(b), bias_sigma=tuple(np.sqrt(prior**2 - b**2)), white=white)


def test_the_fixed_base_limit_is_the_closed_form_and_half_a_record_of_azimuth_drift():
    # The closed form is a steady state (level velocity errors and east tilt at rest), but at its limit the azimuth
    # still turns, phiU' = wN phiE - eps_U. Gyrocompassing sees the azimuth through the east tilt's drift over the
    # record, i.e. at mid-record on the average (a random walk's drift is best estimated by its end points), so
    # the optimal filter lands on the closed form plus half a record of that turn, (wN phiE - eps_U) T / 2. Here
    # the east gyro bias and the accelerometer biases give an azimuth limit of 1.2 arcmin and that turn 3e-4 of
    # it: within 1e-4 with a diffuse attitude prior (the bias prior's weight, (eps / wN)^2 / 1 rad^2, is 1e-7).
    # The level limits within 1 % (the level loop's lag behind the tilts' drift).
    ab = np.array([30.0, -20.0, 50.0]) * units.UG
    spec = IMUSpec(gyro=_isotropic_gyro([0.004 * units.DEG_PER_H, 0, 0], C_STATIC, 0.006 * units.DEG_PER_H,
                                        NAV.gyro.white),
                   accel=SensorErrors(bias=tuple(ab), white=NAV.accel.white))
    cf = metrics.theoretical_limits(spec.gyro.bias, ab, C_STATIC, LAT, SITE.h)
    T = 300.0
    turn = W_N * cf[0] * T / 2
    assert abs(cf[2]) / units.ARCMIN > 1.0 and abs(turn) > 3e-4 * abs(cf[2])
    for aid in (None, AidingSpec(1.0, (0.05,) * 3, lever_arm=(1.0, 2.0, 0.5))):
        r = bound.bias_limit(spec, T, site=SITE, C_bn=C_STATIC, aiding=aid)
        assert r.limit[-1, :2] == pytest.approx(cf[:2], rel=0.01)
        assert r.limit[-1, 2] == pytest.approx(cf[2] + turn, rel=1e-4)
        # the biases are unobservable: the spread about the limit is the bound of known biases
        _, b = metrics.attainable_bound(spec, T, site=SITE, C_bn=C_STATIC, aiding=aid)
        assert r.sigma[-1, 2] == pytest.approx(b[-1, 2], rel=1e-3)


@pytest.mark.parametrize("T", [300.0, 1200.0])
def test_the_vertical_gyro_bias_turns_the_azimuth_after_mid_record(T):
    # The same law with a gyro bias on every ENU axis: eps_U turns the azimuth by -eps_U T / 2 (0.05 arcmin at
    # 1200 s against 1.7 arcmin of limit); the north gyro bias only makes the level loop lag.
    eps = np.array([0.004, -0.003, 0.005]) * units.DEG_PER_H
    spec = IMUSpec(gyro=_isotropic_gyro(eps, C_STATIC, 0.008 * units.DEG_PER_H, NAV.gyro.white),
                   accel=SensorErrors(bias=(30 * units.UG, -20 * units.UG, 50 * units.UG), white=NAV.accel.white))
    cf = metrics.theoretical_limits(spec.gyro.bias, spec.accel.bias, C_STATIC, LAT, SITE.h)
    r = bound.bias_limit(spec, T, site=SITE, C_bn=C_STATIC)
    assert r.limit[-1, 2] == pytest.approx(cf[2] + (W_N * cf[0] - eps[2]) * T / 2, rel=1e-4)
    assert abs(eps[2] * T / 2) > 5e-3 * abs(cf[2])


# ----------------------------------------------- 3. Monte Carlo of the optimal filter on an independent model
MC_SPEC = IMUSpec(
    gyro=SensorErrors(bias=(1.0 * units.DEG_PER_H,) * 3, bias_sigma=(0.5 * units.DEG_PER_H,) * 3,
                      white=(0.05 * D / 60,) * 3),
    accel=SensorErrors(bias=(200 * units.UG, -150 * units.UG, 100 * units.UG), bias_sigma=(100 * units.UG,) * 3,
                       white=(50 * units.UG,) * 3))
MC_AID = AidingSpec(2.0, (0.05,) * 3, (0.5,) * 3, lever_arm=(0.4, 1.5, 1.0), outages=((60.0, 80.0),))
MC_S0 = np.array([2 * D, 2 * D, 20 * D, 1.0, 1.0, 10.0, 10.0])
MC_T, MC_STEP = 120.0, 0.5


def _independent_model(traj):
    """The psi-angle model of the bound's docstring built here from the truth at each step's middle: states phi (3),
    dv (2), dp (2), gyro and accel random constants (3 + 3, body), transitions and noise by scipy's expm (Van Loan)
    for each 0.5 s step; rows at 2 Hz outside the outage, their phi columns by perturbing the attitude in
    the lever-arm functions (linear in phi)."""
    M, n = int(MC_T / MC_STEP), 13
    tm = (np.arange(M) + 0.5) * MC_STEP
    tr = traj.truth(tm)
    _, f_b = traj.kinematics(tm)
    C = tr.C_bn
    w_ie, w_en = earth.earth_rate_n(tr.lat), earth.transport_rate_n(tr.v_n, tr.lat, tr.h)
    F = np.zeros((M, n, n))
    F[:, :3, :3] = -attitude.skew(w_ie + w_en)
    F[:, :3, 7:10] = -C
    F[:, 3:5, :3] = attitude.skew(np.einsum("mij,mj->mi", C, f_b))[:, :2]
    F[:, 3:5, 3:5] = -attitude.skew(2 * w_ie + w_en)[:, :2, :2]
    F[:, 3:5, 10:13] = C[:, :2]
    F[:, 5:7, 3:5] = np.eye(2)
    Qc = np.zeros((M, n, n))
    Qc[:, :3, :3] = C @ np.diag(np.square(MC_SPEC.gyro.white)) @ np.swapaxes(C, 1, 2)
    Qc[:, 3:5, 3:5] = (C @ np.diag(np.square(MC_SPEC.accel.white)) @ np.swapaxes(C, 1, 2))[:, :2, :2]
    Phi, Qd = np.empty((M, n, n)), np.empty((M, n, n))
    for j in range(M):
        E = expm(np.block([[-F[j], Qc[j]], [np.zeros((n, n)), F[j].T]]) * MC_STEP)
        Phi[j] = E[n:, n:].T
        Qd[j] = Phi[j] @ E[:n, n:]
    t_row = np.arange(1, M + 1) * MC_STEP
    has_row = ~((t_row >= 60.0) & (t_row < 80.0))
    C_row, w_nb = traj.attitude.attitude(t_row)
    H = np.zeros((M, 4, n))
    H[:, 0, 3] = H[:, 1, 4] = H[:, 2, 5] = H[:, 3, 6] = 1.0
    v0, p0 = lever_velocity(C_row, w_nb, MC_AID.lever_arm), lever_offset(C_row, MC_AID.lever_arm)
    for i in range(3):
        C_est = (np.eye(3) - attitude.skew(np.eye(3)[i])) @ C_row  # phi = e_i (the model is linear in phi)
        H[:, 0:2, i] = (lever_velocity(C_est, w_nb, MC_AID.lever_arm) - v0)[:, :2]
        H[:, 2:4, i] = (lever_offset(C_est, MC_AID.lever_arm) - p0)[:, :2]
    R = np.diag([0.05**2, 0.05**2, 0.5**2, 0.5**2])
    return Phi, Qd, H, has_row, R


def _monte_carlo(model, prior, bias_true, bias_sd, runs, seed):
    """The optimal (covariance-form) Kalman filter, its bias states' initial std ``prior`` (6,), on ``runs``
    simulations of the model, the biases ``bias_true`` + N(0, bias_sd): its error truth - estimate (runs, 3) in phi
    at the end, its own phi variances, and the same for one noise-free run with the fixed biases alone (its
    mean)."""
    Phi, Qd, H, has_row, R = model
    P0 = np.diag(np.concatenate([MC_S0, prior]) ** 2)
    rng = np.random.default_rng(seed)
    n = P0.shape[0]
    x = np.zeros((runs + 1, n))
    x[:runs, :7] = rng.standard_normal((runs, 7)) * np.sqrt(np.diag(P0)[:7])
    x[:, 7:] = bias_true
    x[:runs, 7:] += rng.standard_normal((runs, 6)) * bias_sd
    xh = np.zeros((runs + 1, n))
    P = P0.copy()
    noisy = np.arange(runs + 1) < runs  # the last run is the noise-free one
    for j in range(Phi.shape[0]):
        Lq = np.zeros((n, n))
        Lq[:7, :7] = np.linalg.cholesky(Qd[j][:7, :7])  # the random constants have no process noise
        x = x @ Phi[j].T + noisy[:, None] * (rng.standard_normal((runs + 1, n)) @ Lq.T)
        xh = xh @ Phi[j].T
        P = Phi[j] @ P @ Phi[j].T + Qd[j]
        if has_row[j]:
            z = x @ H[j].T + noisy[:, None] * rng.standard_normal((runs + 1, 4)) * np.sqrt(np.diag(R))
            K = P @ H[j].T @ np.linalg.inv(H[j] @ P @ H[j].T + R)
            xh = xh + (z - xh @ H[j].T) @ K.T
            IKH = np.eye(n) - K @ H[j]
            P = IKH @ P @ IKH.T + K @ R @ K.T
    e = (x - xh)[:, :3]
    return e[:runs], np.diag(P)[:3], e[runs]


def test_monte_carlo_of_the_optimal_filter_matches_the_bound_and_the_limit():
    # A car drive with turns, velocity and position at 2 Hz from an antenna 1.9 m away, a 20-s outage over the
    # second turn. The model is built here independently (truth at the step middles, scipy's expm, the lever-arm
    # rows by perturbing the attitude); the filter's own variance must equal the bound (within the midpoint rule's
    # O(step^2) difference from the bound's 4-point means: 1e-3; 3e-5 found), and the spread of its simulated
    # errors must match it within the Monte Carlo's uncertainty: the std of N Gaussian samples has a relative std of
    # 1/sqrt(2N) (1.6 % for N = 2000): accept 3.5 of those. The limit: the same with the fixed biases unknown
    # (prior bias^2 + bias_sigma^2) and drawn about their fixed values: the errors' mean is the limit (within
    # 3.5 sigma / sqrt(N)), their spread bias_limit's sigma.
    runs = 2000
    traj = car_drive(LAT, 1.9, 450.0, heading=0.3, duration=MC_T)
    sd = np.concatenate([MC_SPEC.gyro.bias_sigma, MC_SPEC.accel.bias_sigma])
    fixed = np.concatenate([MC_SPEC.gyro.bias, MC_SPEC.accel.bias])
    kw = dict(trajectory=traj, aiding=MC_AID, step_s=MC_STEP, initial_sigma=MC_S0)
    tol = 3.5 / np.sqrt(2 * runs)

    _, b = metrics.attainable_bound(MC_SPEC, MC_T, **kw)
    model = _independent_model(traj)
    e, var, _ = _monte_carlo(model, sd, np.zeros(6), sd, runs, seed=3)
    assert np.sqrt(var) == pytest.approx(b[-1], rel=1e-3)
    assert np.std(e, axis=0) / b[-1] == pytest.approx(np.ones(3), abs=tol)
    assert np.all(np.abs(np.mean(e, axis=0)) < 3.5 * b[-1] / np.sqrt(runs))

    r = bound.bias_limit(MC_SPEC, MC_T, **kw)
    e, var, mean_free = _monte_carlo(model, np.hypot(fixed, sd), fixed, sd, runs, seed=4)
    assert mean_free == pytest.approx(r.limit[-1], rel=1e-3)
    assert np.all(np.abs(np.mean(e, axis=0) - r.limit[-1]) < 3.5 * r.sigma[-1] / np.sqrt(runs))
    assert np.std(e, axis=0) / r.sigma[-1] == pytest.approx(np.ones(3), abs=tol)
    # not a trivial limit: the mean's test tells the azimuth's from zero, and it is far from the fixed base's
    # closed form (6.4 deg against 0.9 arcmin: the turns make the biases observable)
    assert abs(r.limit[-1, 2]) > 2 * 3.5 * r.sigma[-1, 2] / np.sqrt(runs)
    C_end = traj.truth([MC_T]).C_bn[0]
    static = metrics.theoretical_limits(MC_SPEC.gyro.bias, MC_SPEC.accel.bias, C_end, LAT, 450.0)
    assert abs(static[2]) > 10 * abs(r.limit[-1, 2])


# ------------------------------------------------------------------------------------------ 4. bad input
@pytest.mark.parametrize("kw, match", [
    ({"aiding": "gnss"}, r"^aiding: expected an AidingSpec, found str$"),
    ({"aiding": AidingSpec(1.0), "vref_sigma": 0.1},
     r"^vref_sigma: expected 0 with aiding \(the rows' sigmas are the aiding's\), found \[0.1, 0.1, 0.1\]$"),
    ({"aiding": AidingSpec(0.01)}, r"^aiding: expected a rate giving at least one row in 10 s, found 0.01 Hz$"),
    ({"initial_sigma": (1, 1, 1)}, r"^initial_sigma: expected 5 stds .* found shape \(3,\)$"),
])
def test_bad_input_is_one_clear_line(kw, match):
    for f in (metrics.attainable_bound, bound.bias_limit):
        with pytest.raises(ValueError, match=match):
            f(NAV, 10.0, site=SITE, **kw)
