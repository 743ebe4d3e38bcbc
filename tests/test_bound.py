"""metrics.attainable_bound: closed-form asymptotes, the project's Kalman filter, sway and moving bases, bad input."""


import numpy as np
import pytest

from baselines.kalman import KalmanAligner
from fusionbench.methods.aligner import Site
from fusionbench.scoring import metrics
from fusionbench.simulation import attitude, earth, trajectory as tj, units
from fusionbench.simulation.imu import (
    PRESETS,
    IMUSpec,
    SensorErrors,
    VelocityReferenceSpec,
    simulate,
    simulate_vref,
)

D = np.pi / 180
LAT = 34 * D
SITE = Site(LAT, 1.9, 450.0)
W_N = earth.OMEGA_IE * np.cos(LAT)  # horizontal earth rate, rad/s
G = SITE.g
SEED000 = PRESETS["seed000"]
ARW = SEED000.gyro.white[0]  # 0.005 deg/sqrt(h) in rad/sqrt(s)
VRW = SEED000.accel.white[0]  # 6 ug/sqrt(Hz) in m/s/sqrt(s)
# white noise only: no fixed bias (limit 0), no random bias, no scale factor
WHITE = IMUSpec(gyro=SensorErrors(white=SEED000.gyro.white), accel=SensorErrors(white=SEED000.accel.white))


def static(duration, heading_deg=123.0):
    return tj.Trajectory(LAT, 1.9, 450.0, tj.EulerSway(mean=(1 * D, -2 * D, -heading_deg * D)), duration=duration)


# ----------------------------------------------------------------------------- 1. static closed forms
def test_azimuth_approaches_the_gyrocompassing_asymptote_with_an_exact_reference():
    # Azimuth is seen only through the drift it gives the east tilt, phiE' = -W_N phiU + ARW noise;
    # with the tilt tracked far better than the azimuth, the drift of a random walk observed over T has
    # variance ARW^2 / T, so sigma_U -> ARW / (W_N sqrt(T)) (4.77 arcmin at 300 s). What is not yet
    # asymptotic is the time the level loop takes to converge and its tracking error at both ends of
    # the record: O(VRW / (g ARW)) = 4 s of lost record, so the ratio is about 1 + 5 s / T.
    ratio = {}
    for T in (300.0, 1200.0):
        t, s = metrics.attainable_bound(SEED000, T, site=SITE, step_s=1.0)
        assert t[-1] == pytest.approx(T) and s.shape == (t.size, 3)
        ratio[T] = s[-1, 2] / (ARW / (W_N * np.sqrt(T)))
        if T == 300.0:
            assert s[-1, 2] / units.ARCMIN == pytest.approx(4.8, abs=0.1)
            s300 = s[-1, 2]
        else:
            s1200 = s[-1, 2]
    # tends to 1 from above as 1/T: within 3 % at 300 s and 1 % at 1200 s (a sqrt(2) error fails both)
    assert 1.0 < ratio[1200.0] < ratio[300.0] < 1.03, ratio
    assert ratio[1200.0] < 1.01, ratio
    assert 2.0 < (ratio[300.0] - 1) / (ratio[1200.0] - 1) < 5.0, ratio  # 1/T: 4
    # 1/sqrt(T): four times the record, half the sigma
    assert s1200 / s300 == pytest.approx(0.5, rel=0.015)


def test_level_settles_at_the_random_walk_tracking_limit_with_gyro_noise():
    # With gyro white noise the tilt is a random walk (ARW) seen through exactly known velocity with
    # accelerometer noise (VRW): the Kalman-Bucy steady state P = sqrt(q r) / g gives
    # sigma = sqrt(ARW VRW / g) = 0.0101 arcmin, reached after a few VRW / (g ARW) = 4 s. The law
    # VRW / (g sqrt(T)) of a constant tilt holds only for T << 4 s here (it would give 0.0012 arcmin at 300 s).
    _, s = metrics.attainable_bound(SEED000, 1200.0, site=SITE, step_s=1.0)
    ss = np.sqrt(ARW * VRW / G)
    assert s[-1, :2] / ss == pytest.approx([1.0, 1.0], rel=0.01)
    assert s[-1, 0] > 5 * VRW / (G * np.sqrt(1200.0))


@pytest.mark.parametrize("T", [60.0, 300.0])
def test_accelerometer_noise_only_gives_the_least_squares_line_fits(T):
    # No gyro noise: phi is deterministic, the exact velocity gives its increments dv = g phi dt + VRW
    # noise (first sample at t = step only fixes the initial velocity error: T' = T - step of data).
    # phiN constant: sigma = VRW / (g sqrt(T')). phiE a line (slope -W_N phiU): end point of a line fit,
    # twice that; its slope gives phiU: sigma = sqrt(12) VRW / (g W_N T'^1.5).
    spec = IMUSpec(accel=SensorErrors(white=SEED000.accel.white))
    step = 0.5
    _, s = metrics.attainable_bound(spec, T, site=SITE, step_s=step)
    Te = T - step
    base = VRW / (G * np.sqrt(Te))
    assert s[-1] == pytest.approx([2 * base, base, np.sqrt(12) * VRW / (G * W_N * Te**1.5)], rel=1e-3)


# ------------------------------------------------------------------------ 2. the project's Kalman filter
def test_kalman_monte_carlo_error_matches_the_bound():
    # White noise only (fixed and random biases zero, so the limit is 0). The filter updates at 10 Hz
    # with the five reference samples of each 0.1-s step averaged (R = vref_sigma^2 / 5): the bound with step
    # 0.1 s and vref_dt 0.02 s has that measurement model. The filter also carries bias states with floored
    # priors (0.01 deg/h, 10 ug) that the data cannot separate from the misalignment; with the true
    # biases zero its phiU estimate is the one of phiU + eps_E / W_N, whose error is the noise part,
    # the bound. Its own predicted sigma includes the bias priors: it must equal the bound computed
    # for the filter's model (bias_sigma = those priors, its initial sigmas), an independent check
    # of the bound's discretisation and update on the same error model.
    runs, T, vs = 96, 240.0, 0.01
    tr = static(T)
    data = simulate(tr, WHITE, 0.02, runs=runs, seed=11)
    vref = simulate_vref(tr, VelocityReferenceSpec((vs,) * 3), data.t, runs=runs, seed=11)
    C0 = tr.truth([0.0]).C_bn[0]
    init = attitude.apply_misalignment(C0, np.random.default_rng(5).normal(0.0, 3 * units.ARCMIN, (runs, 3)))
    res = KalmanAligner(imu=WHITE, vref_sigma=vs).align(data, SITE, vref=vref, init=init)
    phi = attitude.misalignment(res.C_bn_final, tr.truth([T]).C_bn[0])
    _, bound = metrics.attainable_bound(WHITE, T, trajectory=tr, vref_sigma=vs, vref_dt=0.02, step_s=0.1)
    # the RMS of N Gaussian errors has a relative std of 1/sqrt(2N) = 0.072: accept 3 of those
    tol = 3 / np.sqrt(2 * runs)
    eff = np.sqrt(np.mean(phi[:, 2] ** 2)) / bound[-1, 2]
    assert abs(eff - 1) < tol, (eff, tol)
    assert tol < np.sqrt(2) - 1 and tol < 1 - 1 / np.sqrt(2)  # a sqrt(2) error would be caught

    kf_model = IMUSpec(gyro=SensorErrors(bias_sigma=(0.01 * units.DEG_PER_H,) * 3, white=WHITE.gyro.white),
                       accel=SensorErrors(bias_sigma=(10 * units.UG,) * 3, white=WHITE.accel.white))
    _, b_kf = metrics.attainable_bound(kf_model, T, trajectory=tr, vref_sigma=vs, vref_dt=0.02, step_s=0.1,
                                       initial_sigma=(1 * D, 1 * D, 5 * D, 0.1, 0.1))
    assert res.sigma_phi[0, -1] == pytest.approx(b_kf[-1], rel=0.01)
    assert b_kf[-1, 2] > 1.05 * bound[-1, 2]  # the bias priors matter: this is not the same number


# ------------------------------------------------------------------------------ 3. sway and moving bases
def test_sway_with_isotropic_noise_gives_the_static_bound():
    # pure rotation about the sensor: f^n stays [0, 0, g], and C diag(q) C^T = q I for isotropic
    # noise, so the error model, hence the bound, does not change
    T = 300.0
    _, s_static = metrics.attainable_bound(WHITE, T, site=SITE)
    sway = tj.Trajectory(LAT, 1.9, 450.0, tj.EulerSway(mean=(1 * D, -2 * D, -123 * D), amplitude=(5 * D, 7 * D, 9 * D),
                                                        frequency=(0.5, 0.3, 0.2)), duration=T)
    _, s_sway = metrics.attainable_bound(WHITE, T, trajectory=sway)
    assert s_sway == pytest.approx(s_static, rel=0.01)


def test_acceleration_that_starts_mid_record_makes_the_azimuth_observable():
    # Velocity measures the tilt of phi about the specific force; a rotation about f^n is seen only
    # through gyrocompassing. Static until T/2, then 0.1 g east: phi about Up is known before, phi
    # about the tilted f = [a, 0, g] after, so at the switch phiU = (g phiE - c) / a with phiE and
    # c = g phiE - a phiU each known to the level tracking limit s = sqrt(ARW VRW / g):
    # sigma_U ~ (g / a) sqrt(2) s, plus the unobserved ARW walk about f after the switch,
    # ARW sqrt(T / 2): about 0.16 arcmin against 4.9 static, a ratio near 30.
    T = 300.0
    _, s_static = metrics.attainable_bound(WHITE, T, site=SITE)
    acc = tj.accelerating(LAT, 1.9, 450.0, start=T / 2, duration=T)
    _, s_move = metrics.attainable_bound(WHITE, T, trajectory=acc)
    a = 0.1 * units.G
    rough = np.hypot(G / a * np.sqrt(2 * ARW * VRW / G), ARW * np.sqrt(T / 2))
    assert s_move[-1, 2] == pytest.approx(rough, rel=0.1)
    assert s_static[-1, 2] / s_move[-1, 2] > 10.0


def test_constant_acceleration_from_the_start_helps_only_through_the_transport_rate():
    # With f^n = [a, 0, g] from t = 0 the rotation about f is again seen only through gyrocompassing,
    # at the rate |w_in x u| ~ W_N + v_E / R_N: the transport rate of the growing east velocity adds to
    # the earth rate. The information grows as the mean of that rate squared:
    # static/moving = sqrt(mean((W_N + a t / R_N)^2)) / W_N ~ 1.41 at 300 s (not 'much smaller').
    # The Coriolis acceleration 2 W_U v_E turns f^n a little (3e-3 rad): a few % more.
    T = 300.0
    _, s_static = metrics.attainable_bound(WHITE, T, site=SITE)
    _, s_move = metrics.attainable_bound(WHITE, T, trajectory=tj.accelerating(LAT, 1.9, 450.0, duration=T))
    a = 0.1 * units.G
    _, rn = earth.radii(LAT)
    t = np.linspace(0.0, T, 10001)
    v = a * t  # east velocity, m/s
    u_e, u_u = a / np.hypot(a, G), G / np.hypot(a, G)  # direction of f^n
    w_n = W_N + v / (rn + 450.0)  # north earth + transport rate
    w_u = earth.OMEGA_IE * np.sin(LAT) + v * np.tan(LAT) / (rn + 450.0)
    rate2 = w_n**2 + (w_u * u_e) ** 2  # |w_in x u|^2
    expect = np.sqrt(np.mean(rate2)) / W_N / u_u  # phiU = u_U times the angle about f
    ratio = s_static[-1, 2] / s_move[-1, 2]
    assert 0.99 * expect < ratio < 1.08 * expect, (ratio, expect)


# ------------------------------------------------------------------------------------------ 4. bad input
@pytest.mark.parametrize("kw, match", [
    ({"site": SITE, "trajectory": static(10.0)}, r"^site, trajectory: expected exactly one of them, found both$"),
    ({}, r"^site, trajectory: expected exactly one of them, found neither$"),
    ({"site": SITE, "duration": 0.0}, r"^duration: expected a positive number of s, found 0.0$"),
    ({"site": SITE, "duration": -5.0}, r"^duration: expected a positive number of s, found -5.0$"),
    ({"site": SITE, "step_s": 0.0}, r"^step_s: expected a positive number of s, found 0.0$"),
    ({"site": SITE, "vref_dt": -0.01}, r"^vref_dt: expected a positive number of s, found -0.01$"),
    ({"site": SITE, "vref_sigma": -0.1}, r"^vref_sigma: expected non-negative m/s, found \[-0.1, -0.1, -0.1\]$"),
    ({"site": SITE, "vref_sigma": (0.1, -0.1, 0.0)}, r"^vref_sigma: expected non-negative m/s"),
    ({"site": SITE, "initial_sigma": (1, 1, 0, 1, 1)}, r"^initial_sigma: expected positive finite stds"),
])
def test_bad_input_is_one_clear_line(kw, match):
    args = {"duration": 10.0}
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        metrics.attainable_bound(SEED000, **args)


def test_bad_spec_is_named():
    with pytest.raises(ValueError, match=r"^spec: expected an IMUSpec, found str$"):
        metrics.attainable_bound("seed000", 10.0, site=SITE)
