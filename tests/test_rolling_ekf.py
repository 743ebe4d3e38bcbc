"""Seed 002's 45-state EKF: analytic Jacobians against central differences, and a filter that starts on
the truth of a noise-free run stays on it, two passes recover a noise-free paper run within 1 %, and the
compiled kernels (sigmas included) equal the NumPy model; the numpy update engine equals filterpy's."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from baselines.rolling import ekf as R
from baselines.rolling import angles, jacobians, model
from baselines.rolling import kernels as K
from baselines.rolling.priors import prior_sigma
from baselines.rolling.scheme import PAPER_SCHEME, Scheme, Segment
from baselines.rolling.simulator import simulate
from tests.conftest import agree_to_rounding

LAT = np.radians(34.0)


def _state(seed, angles_deg):
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 0.3, model.N_STATES) * prior_sigma()
    x[model.ANGLES] = np.radians(angles_deg)
    return x


def _central(fun, x, steps):
    cols = []
    for i in range(x.size):
        d = np.zeros(x.size)
        d[i] = steps[i]
        cols.append((fun(x + d) - fun(x - d)) / (2 * steps[i]))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("angles", [(2.0, 3.0, 5.0), (170.0, -20.0, 95.0)])
def test_jacobians_match_central_differences(angles):
    x = _state(1, angles)
    w = np.radians([0.1, -0.05, 0.02])
    steps = 1e-4 * prior_sigma()
    Hn = _central(lambda s: model.measurement(s, LAT), x, steps)
    Fn = _central(lambda s: model.state_derivative(s, w, LAT), x, steps)
    H, F = jacobians.jacobian_h(x, LAT), jacobians.jacobian_f(x, w, LAT)
    # relative to each column's largest entry: the differences are second-order accurate (1e-8 measured)
    for A, An in ((H, Hn), (F, Fn)):
        scale = np.maximum(np.abs(An).max(axis=0), 1e-300)
        assert np.max(np.abs(A - An) / scale) < 1e-6
        assert np.array_equal(np.abs(A).max(axis=0) > 0, np.abs(An).max(axis=0) > 1e-20)  # same structure


def test_error_state_jacobians_match_central_differences():
    """The covariance's model: e = [c_true - c_est, eta], C_true = (I - [eta x]) C_est. H_e against central
    differences of h; F_e against the misalignment between two attitudes propagated 1 ms apart."""
    from scipy.spatial.transform import Rotation
    x = _state(1, (20.0, 3.0, -40.0))
    w = np.radians([0.1, -0.05, 0.02])
    F, H = jacobians.error_jacobians(x, w, LAT)
    sig = prior_sigma()
    dt = 0.01  # long enough that the propagated misalignment stands well above rounding

    def eta_after(e):
        xt, xe = R._rk4(K.inject(x, e), w, dt, LAT, 0.0), R._rk4(x, w, dt, LAT, 0.0)
        Ct, Ce = angles.angles_to_dcm(xt[model.ANGLES]), angles.angles_to_dcm(xe[model.ANGLES])
        return -Rotation.from_matrix(Ct @ Ce.T).as_rotvec()

    for i in range(model.N_STATES):
        e = np.zeros(model.N_STATES)
        e[i] = 1e-4 * sig[i]
        col = (model.measurement(K.inject(x, e), LAT) - model.measurement(K.inject(x, -e), LAT)) / (2 * e[i])
        assert np.abs(col - H[:, i]).max() <= 1e-6 * np.abs(H).max()  # the azimuth column: rounding only
        e[i] = 1e-2 * sig[i]
        d = (eta_after(e) - eta_after(-e)) / (2 * e[i])
        expect = (np.eye(model.N_STATES)[i, model.ANGLES] if i >= model.N_COEFFS else 0.0) + F[model.ANGLES, i] * dt
        assert np.abs(d - expect).max() <= max(1e-3 * np.abs(F[model.ANGLES, i] * dt).max(), 1e-12)
    # a rotation about the vertical is invisible to the accelerometers, whatever the estimate
    assert np.abs(H[:, model.N_COEFFS + 2]).max() < 1e-12


def test_filter_started_on_the_truth_of_a_noise_free_run_stays_on_it():
    c = _state(2, (0.0, 0.0, 0.0))[:model.N_COEFFS]  # the filter's model is the simulator's (exact G^-1)
    a0 = np.radians([2.0, 3.0, 5.0])
    scheme = Scheme(tuple(PAPER_SCHEME.segments[:2]))  # south 1800 s, east 900 s
    run = simulate(scheme, c, angles.angles_to_dcm(a0), LAT, gyro_noise=0.0, accel_noise=0.0)
    res = R.RollingEKF().calibrate(run.t[:2000], run.y[0, :2000], run.w_cmd[0, :2000], LAT,
                                   x0=np.concatenate([c, a0]))
    err = res.x - run.states[0, :2000]
    # same model, no noise: the estimate stays on the truth to rounding (6e-5 arcsec measured)
    assert np.max(np.abs(err[:, model.ANGLES])) < 1e-3 * np.radians(1 / 3600)
    # no process noise on the coefficients: their sigmas only shrink (the angles' may grow, rotating
    # the poorly observed azimuth uncertainty into the other angles)
    assert np.all(np.diff(res.sigma[:, :model.N_COEFFS], axis=0) <= 1e-12 * res.sigma[:-1, :model.N_COEFFS])


def test_bad_input_is_named():
    ekf = R.RollingEKF()
    with pytest.raises(ValueError, match="y, w_cmd: expected shape"):
        ekf.calibrate(np.arange(1, 11) * 0.2, np.zeros((9, 3)), np.zeros((10, 3)), LAT)
    with pytest.raises(ValueError, match="expected finite"):
        ekf.calibrate(np.arange(1, 11) * 0.2, np.full((10, 3), np.nan), np.zeros((10, 3)), LAT)


def test_noise_free_paper_run_recovers_every_coefficient_within_one_percent():
    """The paper's scheme and Table 1 truths (scenario paper002-rolling, run 0), noise off, started levelled
    with the azimuth 5 deg off. Two passes (EKF, then the linearised filter about its estimate carried back)
    recover every coefficient within 1 % of its true value (worst measured: 1.4e-5 of it, a gyro axis
    angle) and the attitude within 0.1 arcsec (0.03 measured). The causal first pass alone does not:
    its torquer and gyro axis-angle errors are tens of ppm and arcseconds (R inflated while the attitude
    is degrees off), which is why the second pass exists."""
    from fusionbench.bench import scenarios
    from baselines.rolling.spec import draw_truth

    scn = scenarios.get("paper002-rolling")
    c, a = draw_truth(scn.platform, 0, 0)
    run = simulate(scn.platform.scheme, c, angles.angles_to_dcm(a), scn.site.lat, 0.0, 0.0, 0.0)
    res = R.RollingEKF(passes=2).calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat)
    est = res.final()
    assert np.all(np.abs(est[:model.N_COEFFS] - c) < 0.01 * np.abs(c))
    arcsec = np.radians(1 / 3600)
    misalign = Rotation.from_matrix(angles.angles_to_dcm(est[model.ANGLES]) @ run.C_pn[0, -1].T).magnitude()
    assert misalign < 0.1 * arcsec
    # a noise-free run sits well inside the filter's own sigmas (0.06 of them measured)
    assert np.max(np.abs(est[:model.N_COEFFS] - c) / res.sigma[-1, :model.N_COEFFS]) < 0.5
    first = res.first_pass.final()
    assert np.max(np.abs(first[model.KT] - c[model.KT])) > 100 * np.max(np.abs(est[model.KT] - c[model.KT]))


def test_backward_undoes_the_forward_model():
    x0 = _state(3, (2.0, 3.0, 5.0))
    w = np.tile(np.radians([0.1, -0.03, 0.05]), (500, 1))
    x = x0
    for k in range(500):
        x = R._rk4(x, w[k], 0.2, LAT, 0.0)
    assert np.abs(x[model.ANGLES] - x0[model.ANGLES]).max() > np.radians(1.0)  # it moved
    back = R.backward(x, w, 0.2, LAT)
    assert np.abs(back - x0).max() < 1e-12


def test_compiled_kernels_match_the_platform_model():
    """The filter's compiled evaluations (baselines.rolling.kernels) against the NumPy platform model and
    scipy's rotations, on states with large angles and coefficients."""
    from scipy.spatial.transform import Rotation as Rot

    g = 9.79
    wie = np.array([0.0, 6e-5, 4e-5])
    for seed, ang in ((4, (20.0, -35.0, 150.0)), (5, (-170.0, 80.0, -10.0))):
        x = _state(seed, ang)
        w = np.radians([0.1, -0.05, 0.02])
        C = angles.angles_to_dcm(x[model.ANGLES])
        # the compiled code against NumPy's: a DCM entry is a sum of two products of up to three sines and cosines,
        # 4 roundings, and each factor may be up to 4 ulps from the C library's where NumPy evaluates it with its
        # own SIMD code: 16 roundings of |C| = 1. The angles: arcsin and arctan2 (4 ulps each) of entries whose
        # roundings the inverse's slope 1/cos(theta) (5.8 at 80 deg) magnifies: 16 roundings of pi. The
        # measurement (size g) and the Euler rates (1/cos(theta) times three-term sums) carry the DCM's: 16 roundings
        # of their own size. A wrong sign, axis or term moves them by 1e-3 to 1 of it.
        agree_to_rounding(K.dcm(x[model.ANGLES]), C, 16, 1.0)
        agree_to_rounding(K.angles(C), angles.dcm_to_angles(C), 16, np.pi)
        agree_to_rounding(K.measurement(x, g), model.measurement_unchecked(x, g), 16)
        ref = model.state_derivative_unchecked(x, w, g, wie)[model.ANGLES]
        agree_to_rounding(K.angle_derivative(x, w, g, wie), ref, 16)
        e = 1e-3 * np.random.default_rng(seed).standard_normal(model.N_STATES)
        out = K.inject(x, e)
        C_ref = Rot.from_rotvec(-e[model.ANGLES]).as_matrix() @ C
        # through the kernel's angles and back, against scipy's rotation vector and a 3 x 3 product: the DCM's
        # 16 roundings
        agree_to_rounding(angles.angles_to_dcm(out[model.ANGLES]), C_ref, 16, 1.0)
        assert np.abs(out[model.ANGLES] - x[model.ANGLES]).max() < 0.1  # continuous: no jump of 2 pi (at theta 80 deg
        # the angles move up to 1 / cos(theta) times the 2e-3 rad turn)
        assert np.array_equal(out[:model.N_COEFFS], x[:model.N_COEFFS] + e[:model.N_COEFFS])


def test_compiled_sigmas_match_numpy():
    """kernels.state_sigmas (the filter's per-step sigmas) against the NumPy formula: the coefficients'
    sqrt(P_ii) D_i, the angles' sqrt(diag(J P_aa J^T)) with J = -E C^T diag(D_a)."""
    D = prior_sigma()
    rng = np.random.default_rng(6)
    for seed, ang in ((4, (20.0, -35.0, 150.0)), (5, (-170.0, 80.0, -10.0))):
        x = _state(seed, ang)
        M = rng.standard_normal((model.N_STATES, model.N_STATES))
        P = M @ M.T / model.N_STATES + 0.1 * np.eye(model.N_STATES)
        a = x[model.ANGLES]
        J = -jacobians.rate_inverse(a) @ angles.angles_to_dcm(a).T * D[None, model.ANGLES]
        ref = np.sqrt(np.diag(P)) * D
        ref[model.ANGLES] = np.sqrt(np.diag(J @ P[model.ANGLES, model.ANGLES] @ J.T))
        # the coefficients' sqrt(P_ii) D_i: two roundings of the sigma; the angles' quadratic forms, summed in the
        # kernel's order against BLAS's: 2 x 3 + 1 roundings of (|J| |P| |J|^T)_ii (no more than the form itself
        # unless its terms cancel), halved by the square root: 8 roundings of (|J| |P| |J|^T)_ii / (2 sigma_i)
        scale = ref.copy()
        aJ = np.abs(J)
        scale[model.ANGLES] = np.diag(aJ @ np.abs(P[model.ANGLES, model.ANGLES]) @ aJ.T) / (2 * ref[model.ANGLES])
        agree_to_rounding(K.state_sigmas(x, P, D), ref, 8, scale)


def test_second_pass_reaches_the_information_bound():
    """Without process noise the second pass is a linear Kalman filter, so its final coefficient sigmas
    are the inverse of prior + information: equal to ``bound()`` (1.0000 measured). That bound in turn
    agrees with the scheme's PWCS information matrix computed independently along the commanded path
    (baselines.rolling.observability, expm per step) to 3.4 % (the paths differ by the truths' drift)."""
    from fusionbench.bench import scenarios
    from baselines.rolling.spec import draw_truth
    from baselines.rolling.observability import information_matrix

    scn = scenarios.get("paper002-rolling")
    spec = scn.platform.scaled(1800.0)
    c, a = draw_truth(spec, 0, 0)
    run = simulate(spec.scheme, c, angles.angles_to_dcm(a), scn.site.lat, 0.0, 0.0, 0.0)
    res = R.RollingEKF(gyro_noise=0.0).calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat)
    bound = res.bound()[:model.N_COEFFS]
    assert np.abs(res.sigma[-1, :model.N_COEFFS] / bound - 1.0).max() < 1e-3
    M = information_matrix(spec.scheme, scn.site.lat, C0=angles.angles_to_dcm(a), coeffs=c, step_s=spec.scheme.filter_s)
    pwcs = prior_sigma() * np.sqrt(np.diag(np.linalg.inv(np.eye(model.N_STATES) + M)))
    assert np.abs(bound / pwcs[:model.N_COEFFS] - 1.0).max() < 0.05
    # the gyros' white drift (paper level) raises the sigmas above that bound, by up to 40 % here
    noisy = R.RollingEKF().calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat)
    ratio = noisy.sigma[-1, :model.N_COEFFS] / noisy.bound()[:model.N_COEFFS]
    assert ratio.min() > 0.999 and ratio.max() > 1.1


def test_auto_passes_iterate_until_the_linearisation_point_is_the_answer():
    """A 10-deg initial azimuth error (the filter starts at 0): two passes end far outside their sigmas
    (1682 measured on this draw), because the first pass ends outside the linear range; passes="auto"
    keeps relinearising (5 passes here) and lands within 4 sigmas (2.2 measured)."""
    from fusionbench.bench import scenarios
    from baselines.rolling.spec import draw_truth

    scn = scenarios.get("paper002-rolling")
    c, a = draw_truth(scn.platform, 0, 2)
    a[1] = np.radians(10.0)
    run = simulate(scn.platform.scheme, c, angles.angles_to_dcm(a), scn.site.lat, seed=12)
    two = R.RollingEKF().calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat)
    auto = R.RollingEKF(passes="auto").calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat)
    z = lambda res: np.max(np.abs(res.final()[:model.N_COEFFS] - c) / res.sigma[-1, :model.N_COEFFS])  # noqa: E731
    assert two.figures["passes"] == 2 and z(two) > 20
    assert 3 <= auto.figures["passes"] <= R.AUTO_MAX_PASSES and z(auto) < 4
    assert two.figures["last_pass_move_sigma"] > 20
    with pytest.raises(ValueError, match="passes: expected a whole number >= 1 or 'auto', found 0"):
        R.RollingEKF(passes=0)


def test_numpy_engine_matches_filterpy():
    """engine="numpy" (the update on the arrays, the default) against engine="filterpy" (the reference) on a
    noisy run of the paper's scheme cut to 1/12 (150, 75, 150, 75 s: 2 250 filter steps), started levelled
    with the azimuth off: both passes' estimate and sigma histories and the final estimate agree to rounding
    (identical bits measured: the same operations in the same order)."""
    from fusionbench.bench import scenarios
    from baselines.rolling.spec import draw_truth

    scn = scenarios.get("paper002-rolling")
    base = scn.platform.scheme
    scheme = Scheme(tuple(Segment(s.axis, s.rate, s.duration / 12) for s in base.segments),
                    command_period_s=base.command_period_s, sample_s=base.sample_s, filter_s=base.filter_s)
    c, a = draw_truth(scn.platform, 0, 0)
    run = simulate(scheme, c, angles.angles_to_dcm(a), scn.site.lat, seed=3)
    ref, new = (R.RollingEKF(engine=e).calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat)
                for e in ("filterpy", "numpy"))
    assert new.figures["passes"] == ref.figures["passes"] == 2
    # NumPy's products against filterpy's BLAS dot may sum in another order: n terms an element, n^2 per step once a
    # difference has gone through the covariance's n x n products (n = 45 states), carried by the filter without
    # growing beyond each state's size over the run, over both passes' steps (the second starts where the first
    # ended): 9e6 roundings, 2e-9 of each state's size (a one-step shift moves the angles by 1e-3 of theirs)
    roundings = 2 * new.x.shape[0] * model.N_STATES**2
    for n, f in ((new, ref), (new.first_pass, ref.first_pass)):
        x_size, s_size = np.abs(f.x).max(axis=0), np.abs(f.sigma).max(axis=0)  # each state's
        agree_to_rounding(n.x, f.x, roundings, x_size)
        agree_to_rounding(n.sigma, f.sigma, roundings, s_size)
        agree_to_rounding(n.final(), f.final(), roundings, x_size)
    # and the run is a real one: the filter converged (final errors within a few sigmas)
    assert np.max(np.abs(new.final()[:model.N_COEFFS] - c) / new.sigma[-1, :model.N_COEFFS]) < 4


def test_bad_engine_is_named():
    with pytest.raises(ValueError, match=r"^rolling-ekf: option engine: expected one of \('numpy', 'filterpy'\), "
                                         r"found 'x'$"):
        R.RollingEKF(engine="x")
    assert R.RollingEKF().engine == "numpy"
