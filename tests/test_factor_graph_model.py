"""Factor-graph alignment: the IMU model as an input, the per-sample weighting of the reference, the
accuracy and calibrated sigmas on a moving base against the Kalman filter, the attitude prior, and the
noise-adaptive graph's variance estimates in seed 001's jump tests."""

from dataclasses import replace

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, V, X

from baselines.factor_graph import FactorGraphAligner, noise_model
from baselines.graph_adaptive import AdaptiveFactorGraphAligner
from baselines.graph_rows import axis_means, tile_error, tile_factors, tile_sums, tiles
from baselines.graph_posterior import Posterior
from baselines.kalman import KalmanAligner
from fusionbench.bench import scenarios
from fusionbench.methods.aligner import Site
from fusionbench.scoring import metrics
from fusionbench.simulation import attitude, earth, trajectory as tj, units
from fusionbench.simulation.aidingsim import simulate_aiding
from fusionbench.simulation.imu import (PRESETS, IMUSpec, NoiseSchedule, SensorErrors, VelocityReferenceSpec, simulate,
                            simulate_vref)
from fusionbench.simulation.translation import Translation, VelocityDisturbance

D = np.pi / 180
LAT = 34 * D


def test_the_noise_figures_come_from_the_imu_model_and_explicit_figures_override_them():
    tac = PRESETS["tactical"]  # 1 deg/h fixed, 0.5 deg/h instability (tau 600 s), 300 ug + 50 ug
    m = noise_model(tac)
    assert m["gyro_noise"] == pytest.approx(np.full(3, 0.1 * units.DEG_PER_SQRT_H))
    assert m["accel_noise"] == pytest.approx(np.full(3, 50.0 * units.UG_PER_SQRT_HZ))
    assert m["gyro_bias_sigma"] == pytest.approx(np.full(3, np.hypot(1.0, 0.5) * units.DEG_PER_H))
    assert m["accel_bias_sigma"] == pytest.approx(np.full(3, np.hypot(300.0, 50.0) * units.UG))
    # the Gauss-Markov instability as the Kalman aligner's random walk, sqrt(2 sigma^2 / tau)
    assert m["gyro_bias_walk"] == pytest.approx(np.full(3, 0.5 * units.DEG_PER_H * np.sqrt(2 / 600.0)))
    # a zero datasheet figure is floored (seed001's preset has no white noise): never a singular model
    s1 = noise_model(PRESETS["seed001"])
    assert s1["gyro_noise"] == pytest.approx(np.full(3, 1e-5 * units.DEG_PER_SQRT_H))
    assert s1["gyro_bias_sigma"] == pytest.approx(np.full(3, np.hypot(0.01, 0.005) * units.DEG_PER_H))
    assert s1["gyro_bias_walk"] == pytest.approx(np.zeros(3))
    fg = FactorGraphAligner(imu=tac, gyro_bias_sigma=2 * units.DEG_PER_H)
    assert fg.gyro_bias_sigma == pytest.approx(2 * units.DEG_PER_H)  # explicit figure wins
    assert fg.accel_bias_sigma == pytest.approx(np.hypot(300.0, 50.0) * units.UG)
    none = FactorGraphAligner(imu=None)  # no model: the seed000-based figures of earlier versions
    assert (none.gyro_noise, none.gyro_bias_sigma, none.imu_model) == pytest.approx(
        (0.005 * units.DEG_PER_SQRT_H, 0.1 * units.DEG_PER_H, "default"))
    default = FactorGraphAligner()  # the stated default, like the Kalman aligner's: the navigation preset
    assert default.imu_model == "navigation" and default.gyro_noise == pytest.approx(0.002 * units.DEG_PER_SQRT_H)
    # a walking bias is held over 30-s segments tied by random-walk factors of sigma sqrt(q T_b)
    seg, walk = fg._bias_segments(np.arange(0.0, 301.0))
    assert seg.max() == 9 and np.bincount(seg).tolist() == [30] * 10
    assert walk[3:] == pytest.approx(m["gyro_bias_walk"] * np.sqrt(30.0))
    seg, walk = FactorGraphAligner(imu=PRESETS["seed000"])._bias_segments(np.arange(0.0, 301.0))
    assert seg.max() == 0 and not walk.any()  # a constant bias
    assert FactorGraphAligner(imu="seed000").imu_model == "seed000"  # a preset name, like the Kalman aligner
    with pytest.raises(ValueError, match="imu"):
        FactorGraphAligner(imu="hal9000")


def test_tiles_split_the_samples_between_the_nearest_keyframes_and_their_sums_run_from_the_keyframe():
    rng = np.random.default_rng(3)
    t = 0.1 * np.arange(1, 101)  # samples at the increment ends, 10 Hz
    counts = np.r_[0, 10 * np.arange(1, 10), 100]
    t_kf = np.r_[0.0, t[counts[1:] - 1]]
    tile = tiles(t, t_kf)
    for k in range(t_kf.size):
        sel = tile == k
        assert np.all(np.abs(t[sel] - t_kf[k]) <= 0.5 + 1e-9)  # the nearest keyframe
    assert np.bincount(tile).tolist() == [5] + [10] * 9 + [5]  # every sample once
    x = rng.standard_normal((100, 3))
    S = tile_sums(x, tile, counts)
    for i in (0, 4, 5, 9, 10, 14, 99):
        k = tile[i]
        c = counts[k] - 1 if k else -1  # the keyframe's own sample (none for the first)
        brute = x[c + 1:i + 1].sum(axis=0) if i > c else -x[i + 1:c + 1].sum(axis=0)
        assert S[i] == pytest.approx(brute, abs=1e-12)
    m = rng.standard_normal((100, 3, 3))
    w = rng.uniform(0.2, 3.0, 100)
    # one weight per row on every axis, then a weight per axis (0: the axis not measured in that row)
    for W in (np.repeat(w[:, None], 3, 1), rng.uniform(0.2, 3.0, (100, 3)) * (rng.uniform(size=(100, 3)) > 0.2)):
        var, (z, mm) = axis_means(tile, t_kf.size, W, per_axis=[x], shared=[m])
        for k in range(t_kf.size):
            sel = tile == k
            for a in range(3):
                assert z[k, a] == pytest.approx(np.average(x[sel, a], weights=W[sel, a]))
                assert mm[k, a] == pytest.approx(np.average(m[sel], axis=0, weights=W[sel, a]))
                assert var[k, a] == pytest.approx(1 / W[sel, a].sum())


@pytest.mark.parametrize("position", [False, True])
def test_the_tile_factor_is_its_error_linearised_in_gtsams_tangent(position):
    # a velocity factor (V + R (U_a - Mb_a b_a) = z) and a position factor (P + dt V + ...), each ENU axis with its
    # own means (rows weighted differently per axis), the vertical axis not measured
    rng = np.random.default_rng(4)
    keys = [(X(3), V(3), B(1))]
    d = {"z": np.array([[1.0, -2.0, 0.5]]), "U": rng.standard_normal((1, 3, 3)),
         "Mb": 0.3 * np.eye(3) + 0.02 * rng.standard_normal((1, 3, 3, 3)),
         "c_v": np.array([[0.2, -0.1, 0.3]]) if position else np.ones((1, 3)), "position": position}
    pose = gtsam.Pose3(gtsam.Rot3.RzRyRx(0.1, -0.2, 0.7), np.array([5.0, 1.0, 2.0]))
    v = np.array([0.4, 0.1, -0.3])
    bias = gtsam.imuBias.ConstantBias(np.array([0.01, -0.02, 0.03]), np.array([1e-5, 2e-5, -1e-5]))
    sigma = np.array([[0.5, 2.0, np.inf]])
    values = gtsam.Values()
    values.insert(keys[0][0], pose)
    values.insert(keys[0][1], v)
    values.insert(keys[0][2], bias)
    states = (pose.rotation().matrix()[None], pose.translation()[None], v[None], bias.accelerometer()[None])
    [(k, f)] = tile_factors(d, sigma, keys, states, values)

    def error(p, vel, b):
        return tile_error(d, p.rotation().matrix()[None], p.translation()[None], vel[None], b.accelerometer()[None])[0]

    e0 = error(pose, v, bias)
    R, Ub = pose.rotation().matrix(), d["U"][0] - np.einsum("aij,j->ai", d["Mb"][0], bias.accelerometer())
    direct = d["c_v"][0] * v + np.array([R[a] @ Ub[a] for a in range(3)]) - d["z"][0]
    # two orders of the same sums: rounding of a few ulps of the largest term
    tol = 16 * np.finfo(float).eps * (np.abs(v).max() + np.abs(Ub).sum(axis=1).max() + 5.0)
    assert e0 == pytest.approx(direct + (pose.translation() if position else 0.0), abs=tol)
    A, b = f.linearize(values).jacobian()
    assert k == 0 and A.shape == (2, 15)  # the up axis is not measured: no row
    assert -b == pytest.approx(e0[:2] / sigma[0, :2], abs=tol / sigma.min())
    num = np.zeros((3, 15))  # the nonlinear error's derivative along gtsam's retractions
    for j in range(15):
        dx = np.zeros(15)
        dx[j] = 1e-6
        num[:, j] = (error(pose.retract(dx[:6]), v + dx[6:9], bias.retract(dx[9:])) - e0) / 1e-6
    assert A == pytest.approx(num[:2] / sigma[0, :2, None], abs=1e-5)
    # moved away from the linearisation point, the factor follows the error to first order
    moved = gtsam.Values()
    dx = np.r_[1e-3, -2e-3, 1e-3, 0.1, 0.0, -0.1]
    moved.insert(keys[0][0], pose.retract(dx))
    moved.insert(keys[0][1], v)
    moved.insert(keys[0][2], bias)
    e1 = error(pose.retract(dx), v, bias)[:2] / sigma[0, :2]
    assert f.error(moved) == pytest.approx(0.5 * e1 @ e1, rel=1e-3)
    # its point read from the solver's whole container (other keyframes' keys beside its own): the same factor
    whole = gtsam.Values(values)
    whole.insert(X(4), pose.retract(-dx))
    whole.insert(V(4), -v)
    [(_, g)] = tile_factors(d, sigma, keys, states, whole)
    assert g.error(moved) == f.error(moved) and g.error(values) == f.error(values)
    assert np.array_equal(g.linearize(moved).jacobian()[1], f.linearize(moved).jacobian()[1])


def test_a_perfect_imu_on_a_wobbling_vehicle_with_a_perfect_reference_is_aligned():
    # 0.5 m/s rms of velocity between 0.1 and 2 Hz, all of it in the reference: a velocity that changes
    # within a keyframe interval. Comparing the keyframe velocity with a mean (or a line fit) of the
    # reference over the interval left 20 to 190 arcmin; each sample compared with the velocity the IMU
    # predicts at its own time leaves nothing (the Kalman filter: 0.002 arcmin)
    trans = Translation(disturbance=VelocityDisturbance((0.5, 0.5, 0.1), (0.1, 2.0)))
    tr = tj.Trajectory(LAT, 0.3, 50.0, tj.EulerSway(mean=(1 * D, -1 * D, -60 * D)), trans, duration=120.0)
    data = simulate(tr, IMUSpec(), 0.01)
    vref = tr.truth(data.increments()[0]).v_n
    guess = attitude.euler_platform_to_dcm(np.radians([0.5, -0.5, 2.0])) @ tr.truth([0.0]).C_bn[0]
    res = FactorGraphAligner(marginals=False).align(data, Site(LAT, 0.3, 50.0), vref=vref, init=guess)
    phi = attitude.misalignment(res.C_bn_final[0], tr.truth([120.0]).C_bn[0])
    assert np.abs(phi).max() < 0.01 * units.ARCMIN


def _small_graph(smart):
    """Seven keyframes of a stationary IMU, velocity priors, an attitude prior, two bias keys tied by a
    random-walk factor whose gyro sigma (5e-10) gtsam's smart constructor makes a Constrained model."""
    rng = np.random.default_rng(0)
    p = gtsam.PreintegrationParams.MakeSharedU(9.8)
    p.setGyroscopeCovariance(np.eye(3) * 1e-10)
    p.setAccelerometerCovariance(np.eye(3) * 1e-6)
    p.setIntegrationCovariance(np.eye(3) * 1e-12)
    p.setOmegaCoriolis(np.array([0.0, 6e-5, 4e-5]))
    K, seg = 7, [0, 0, 0, 1, 1, 1]
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for k in range(1, K):
        pim = gtsam.PreintegratedImuMeasurements(p, gtsam.imuBias.ConstantBias())
        for _ in range(100):
            pim.integrateMeasurement(np.array([0, 0, 9.8]) + 1e-3 * rng.standard_normal(3),
                                     np.array([0, 6e-5, 4e-5]) + 1e-5 * rng.standard_normal(3), 0.01)
        graph.add(gtsam.ImuFactor(X(k - 1), V(k - 1), X(k), V(k), B(seg[k - 1]), pim))
    for k in range(K):
        noise = gtsam.noiseModel.Isotropic.Sigma(3, 0.01)
        graph.add(gtsam.PriorFactorVector(V(k), 0.01 * rng.standard_normal(3), noise))
        values.insert(X(k), gtsam.Pose3())
        values.insert(V(k), np.zeros(3))
    graph.add(gtsam.GPSFactor(X(0), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    attitude_prior = gtsam.noiseModel.Diagonal.Sigmas(np.r_[0.01, 0.01, 0.1, 1e3, 1e3, 1e3])
    graph.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(), attitude_prior))
    zero = gtsam.imuBias.ConstantBias()
    bias_prior = gtsam.noiseModel.Diagonal.Sigmas(np.r_[[1e-3] * 3, [1e-6] * 3])
    graph.add(gtsam.PriorFactorConstantBias(B(0), zero, bias_prior))
    walk = gtsam.noiseModel.Diagonal.Sigmas(np.r_[[1e-5] * 3, [5e-10] * 3], smart)
    graph.add(gtsam.BetweenFactorConstantBias(B(0), B(1), zero, walk))
    values.insert(B(0), zero)
    values.insert(B(1), zero)
    return graph, gtsam.LevenbergMarquardtOptimizer(graph, values).optimize(), K


def test_posterior_covariances_equal_a_dense_inverse_and_survive_a_constrained_noise_model():
    graph, values, K = _small_graph(smart=False)
    post = Posterior(graph, values, K, [B(0), B(1)])
    keys = [X(2), V(2), X(3), V(3), B(0)]
    # independent: the whitened Jacobian of the whole graph, its covariance by SVD (no Cholesky)
    order, all_keys = gtsam.Ordering(), [X(k) for k in range(K)] + [V(k) for k in range(K)] + [B(0), B(1)]
    for k in all_keys:
        order.push_back(k)
    A, _ = graph.linearize(values).jacobian(order)
    off = np.cumsum([0] + [6] * K + [3] * K + [6, 6])

    def dense(cols):
        _, s, vt = np.linalg.svd(A[:, :cols], full_matrices=False)
        return (vt.T / s**2) @ vt

    idx = np.concatenate([np.arange(off[all_keys.index(k)], off[all_keys.index(k) + 1]) for k in keys])
    for P, ref in ((post.cov(keys), dense(off[-1])[np.ix_(idx, idx)]),
                   (post.cov(keys[:4], bias=False), dense(off[2 * K])[np.ix_(idx[:18], idx[:18])])):
        d = np.sqrt(np.diag(ref))
        assert np.abs((P - ref) / np.outer(d, d)).max() < 1e-5
    # gtsam turns a sigma below 1e-9 into a Constrained model, whose QR conditional keeps its sigmas:
    # the same Gaussian, the same covariances (they were NaN before)
    graph_c, values_c, _ = _small_graph(smart=True)
    assert any(isinstance(graph_c.at(i).noiseModel(), gtsam.noiseModel.Constrained) for i in range(graph_c.size()))
    P_c = Posterior(graph_c, values_c, K, [B(0), B(1)]).cov(keys)
    d = np.sqrt(np.diag(post.cov(keys)))
    assert np.abs((P_c - post.cov(keys)) / np.outer(d, d)).max() < 1e-6


@pytest.fixture(scope="module")
def moving_base_runs():
    """12 runs of paper001's moving base (0.1 g east, 10 Hz, reference 0.1 m/s per sample), 300 s."""
    scn = scenarios.get("paper001-moving-base")
    traj = scn.trajectory(300.0)
    data = simulate(traj, scn.imu_spec, scn.dt, runs=12, seed=1)
    aid = simulate_aiding(traj, scn.aiding_spec, 300.0, runs=12, seed=1, grid=data.increments()[0])  # 0.1 m/s
    init = scn.initial_guess(traj.truth([0.0]).C_bn[0])
    kf = KalmanAligner(imu="seed001", vref_sigma=0.1).align(data, scn.site, aiding=aid, init=init)
    fg = FactorGraphAligner(imu=scn.imu_spec, vref_sigma=0.1).align(data, scn.site, aiding=aid, init=init)
    C_end = traj.truth([300.0]).C_bn[0]
    err = {name: np.stack([attitude.misalignment(C, C_end) for C in res.C_bn_final]) for name, res in
           (("kf", kf), ("gtsam", fg))}
    return scn, fg, err


def test_on_a_moving_base_gtsam_is_as_accurate_as_kf_and_its_sigma_matches_its_spread(moving_base_runs):
    scn, fg, err = moving_base_runs
    rms = {k: np.sqrt(np.mean(e**2, axis=0)) for k, e in err.items()}
    # same data, same model: the smoother is not worse than the filter (beyond the Monte Carlo noise of
    # 12 correlated runs); the graph before the per-sample weighting and the model's bias priors was
    # 1.8 to 2.6 times worse in azimuth on these data
    assert np.all(rms["gtsam"] <= 1.25 * rms["kf"]), rms
    assert rms["gtsam"][2] < 4 * units.ARCMIN
    assert fg.imu_model == scn.imu_spec.name
    # the spread about the mean (the fixed 0.01 deg/h bias is common to all runs) against the sigma with
    # the bias known: chi-square with 11 degrees of freedom (99 % of it between 0.24 and 2.25); with the
    # earlier graph's bias priors (0.1 deg/h, 100 ug) it is 10 to 16 on these data
    dev = err["gtsam"] - err["gtsam"].mean(axis=0)
    chi2 = np.sum((dev / fg.extra["sigma_phi_noise"][:, -1]) ** 2, axis=0) / 11
    assert np.all((chi2 > 0.2) & (chi2 < 2.5)), chi2
    # and the full sigma covers the common part too: the rms over runs stays within it
    assert np.all(rms["gtsam"] < 2 * np.sqrt(np.mean(fg.sigma_phi[:, -1] ** 2, axis=0)))


def test_an_attitude_prior_on_init_enters_with_its_weight_like_the_kalman_filters():
    # heading north, an east gyro bias of 1 deg/h: the azimuth limit -eps_E / (W cos L) is -276 arcmin,
    # the heading and the bias are inseparable, and a prior on the guess splits the difference
    spec = IMUSpec(gyro=SensorErrors(bias=(1 * units.DEG_PER_H, 1 * units.DEG_PER_H, 0.0)))
    tr = tj.Trajectory(LAT, 0.3, 50.0, tj.EulerSway(mean=(0.0, 0.0, 0.0)), duration=300.0)
    data, site = simulate(tr, spec, 0.01), Site(LAT, 0.3, 50.0)
    C0, C_end = tr.truth([0.0]).C_bn[0], tr.truth([300.0]).C_bn[0]
    guess = attitude.euler_platform_to_dcm(np.radians([0.3333, 0.3333, 0.6667])) @ C0  # 20', 20', 40'
    lim = metrics.theoretical_limits(spec.gyro.bias, spec.accel.bias, C_end, LAT, 50.0)
    free = FactorGraphAligner(imu=spec).align(data, site, init=guess)
    assert attitude.misalignment(free.C_bn_final[0], C_end)[2] == pytest.approx(lim[2], rel=0.1)
    s_eps = 1 * units.DEG_PER_H / (earth.OMEGA_IE * np.cos(LAT))  # the bias prior, as an angle
    for s_az in (1.0, 5.0):
        fg = FactorGraphAligner(imu=spec, init_sigma_deg=(1.0, 1.0, s_az)).align(data, site, init=guess)
        kf = KalmanAligner(imu=spec, vref_sigma=0.01, att_sigma_deg=(1.0, 1.0, s_az)).align(data, site, init=guess)
        s_p = np.radians(s_az)
        # the marginal: prior and bias prior combined, 1 / sqrt(1/s_p^2 + 1/s_eps^2)
        assert fg.sigma_phi[0, -1, 2] == pytest.approx(1 / np.sqrt(s_p**-2 + s_eps**-2), rel=0.02)
        phi_fg = attitude.misalignment(fg.C_bn_final[0], C_end)
        phi_kf = attitude.misalignment(kf.C_bn_final[0], C_end)
        assert phi_fg[2] == pytest.approx(phi_kf[2], rel=0.05)
        assert abs(phi_fg[2]) < 0.5 * abs(lim[2])


def test_the_adaptive_graph_finds_the_reference_variance_jump_of_seed001():
    # paper001-r-jump, one run: reference variance x100 from 200 to 400 s
    scn = scenarios.get("paper001-r-jump")
    traj = scn.trajectory()
    data = simulate(traj, scn.imu_spec, scn.dt, runs=1, seed=4)
    aid = simulate_aiding(traj, scn.aiding_spec, runs=1, seed=4, grid=data.increments()[0])  # 0.1 m/s, x100 inside
    init = scn.initial_guess(traj.truth([0.0]).C_bn[0])
    fg = AdaptiveFactorGraphAligner(imu=replace(scn.imu_spec, schedules=()), vref_sigma=0.1)
    res = fg.align(data, scn.site, aiding=aid, init=init)
    t, lam = res.extra["adapt_window_t"], res.extra["reference_variance_scale"][0]
    inside, outside = (t > 210) & (t < 390), (t < 190) | (t > 410)
    # each 10-s window holds about 240 degrees of freedom: the variance to about 10 %
    assert np.median(lam[inside]) == pytest.approx(100.0, rel=0.15)
    assert np.all((lam[inside] > 60) & (lam[inside] < 160))
    assert np.all((lam[outside] > 0.7) & (lam[outside] < 1.4))
    # the IMU noise is nominal here (and invisible to a 0.1-m/s reference): its factors stay near 1
    assert np.all(np.abs(np.log(res.extra["imu_variance_scale"][0])) < np.log(1.5))
    C_end = traj.truth([traj.duration]).C_bn[0]
    assert abs(attitude.misalignment(res.C_bn_final[0], C_end)[2]) < 5 * units.ARCMIN


def test_the_adaptive_graph_weights_an_imu_noise_jump_and_its_sigma_says_so():
    # stationary, white gyro and accelerometer noise only (the limits are zero), PSD x100 from 100 to
    # 250 s of 400 s, a zero-velocity reference of 0.01 m/s per sample: the heading comes from
    # gyrocompassing, whose noise sigma with noise density q over an effective time T_eff is
    # q / (W cos L sqrt(T_eff)); weighting the noisy part right, T_eff = 250 + 150/100 s, and a
    # variance factor anywhere above 25 there loses less than 5 % of it. The fixed model weighs the
    # noisy part like the rest: its sigma believes 400 s of nominal noise, its errors are far larger.
    white = SensorErrors(white=(0.005 * units.DEG_PER_SQRT_H,) * 3)
    awhite = SensorErrors(white=(6.0 * units.UG_PER_SQRT_HZ,) * 3)
    spec = IMUSpec(gyro=white, accel=awhite, name="white")
    noisy = replace(spec, schedules=(NoiseSchedule(100.0, 250.0, 100.0),))
    tr = tj.Trajectory(LAT, 0.3, 50.0, tj.EulerSway(mean=(1 * D, -2 * D, -123 * D)), duration=400.0)
    data, site = simulate(tr, noisy, 0.01, runs=2, seed=5), Site(LAT, 0.3, 50.0)
    vref = simulate_vref(tr, VelocityReferenceSpec(sigma=(0.01,) * 3), data.increments()[0], runs=2, seed=5)
    init = attitude.euler_platform_to_dcm(np.radians([0.3333, 0.3333, 0.6667])) @ tr.truth([0.0]).C_bn[0]
    res = AdaptiveFactorGraphAligner(imu=spec).align(data, site, vref=vref, init=init)
    fixed = FactorGraphAligner(imu=spec).align(data, site, vref=vref, init=init)
    t, lam = res.extra["adapt_window_t"], res.extra["imu_variance_scale"]
    inside, outside = (t > 120) & (t < 230), (t < 80) | (t > 270)
    # a 10-s window holds 1 to 15 degrees of freedom of IMU noise: the factors are coarse, and shrunk
    # towards the nominal model (10 pseudo-degrees of freedom), but they find the jump
    assert np.all((np.median(lam[:, inside], axis=1) > 20) & (np.median(lam[:, inside], axis=1) < 300))
    assert np.all((np.median(lam[:, outside], axis=1) > 0.5) & (np.median(lam[:, outside], axis=1) < 2))
    assert np.all(np.abs(np.log(res.extra["reference_variance_scale"])) < np.log(1.3))
    wcl = earth.OMEGA_IE * np.cos(LAT)
    ideal = white.white[0] / (wcl * np.sqrt(250.0 + 1.5))
    assert res.extra["sigma_phi_noise"][:, -1, 2] == pytest.approx(np.full(2, ideal), rel=0.5)
    assert fixed.extra["sigma_phi_noise"][:, -1, 2] == pytest.approx(
        np.full(2, white.white[0] / (wcl * np.sqrt(400.0))), rel=0.1)
    C_end = tr.truth([400.0]).C_bn[0]
    e_ad = np.array([attitude.misalignment(C, C_end)[2] for C in res.C_bn_final])
    e_fx = np.array([attitude.misalignment(C, C_end)[2] for C in fixed.C_bn_final])
    assert np.all(np.abs(e_ad) < 3 * res.extra["sigma_phi_noise"][:, -1, 2])
    assert np.sqrt(np.mean(e_fx**2)) > 3 * ideal  # 35 arcmin against 5
    assert np.sqrt(np.mean(e_ad**2)) < 0.25 * np.sqrt(np.mean(e_fx**2))
