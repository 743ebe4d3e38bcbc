"""Seed 002's 45-state EKF: analytic Jacobians against central differences, and a filter that starts on
the truth of a noise-free run stays on it."""

import numpy as np
import pytest

from baselines import rolling_ekf as R
from fusionbench import platform as pf

LAT = np.radians(34.0)


def _state(seed, angles_deg):
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 0.3, pf.N_STATES) * R.prior_sigma()
    x[pf.ANGLES] = np.radians(angles_deg)
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
    steps = 1e-4 * R.prior_sigma()
    Hn = _central(lambda s: pf.measurement(s, LAT), x, steps)
    Fn = _central(lambda s: pf.state_derivative(s, w, LAT), x, steps)
    H, F = R.jacobian_h(x, LAT), R.jacobian_f(x, w, LAT)
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
    F, H = R.error_jacobians(x, w, LAT)
    sig = R.prior_sigma()
    dt = 0.01  # long enough that the propagated misalignment stands well above rounding

    def eta_after(e):
        xt, xe = R._rk4(R._apply(x, e), w, dt, LAT, 0.0), R._rk4(x, w, dt, LAT, 0.0)
        Ct, Ce = pf.angles_to_dcm(xt[pf.ANGLES]), pf.angles_to_dcm(xe[pf.ANGLES])
        return -Rotation.from_matrix(Ct @ Ce.T).as_rotvec()

    for i in range(pf.N_STATES):
        e = np.zeros(pf.N_STATES)
        e[i] = 1e-4 * sig[i]
        col = (pf.measurement(R._apply(x, e), LAT) - pf.measurement(R._apply(x, -e), LAT)) / (2 * e[i])
        assert np.abs(col - H[:, i]).max() <= 1e-6 * np.abs(H).max()  # the azimuth column: rounding only
        e[i] = 1e-2 * sig[i]
        d = (eta_after(e) - eta_after(-e)) / (2 * e[i])
        expect = (np.eye(pf.N_STATES)[i, pf.ANGLES] if i >= pf.N_COEFFS else 0.0) + F[pf.ANGLES, i] * dt
        assert np.abs(d - expect).max() <= max(1e-3 * np.abs(F[pf.ANGLES, i] * dt).max(), 1e-12)
    # a rotation about the vertical is invisible to the accelerometers, whatever the estimate
    assert np.abs(H[:, pf.N_COEFFS + 2]).max() < 1e-12


def test_filter_started_on_the_truth_of_a_noise_free_run_stays_on_it():
    c = _state(2, (0.0, 0.0, 0.0))[:pf.N_COEFFS]
    # without gyro axis angles the filter's first-order platform rate (eq. 19) is exact; with them the
    # dropped products move the open-loop attitude by 0.14 arcsec in 400 s (measured), the filter by 1
    c[pf.GYRO_MOUNT] = 0.0
    a0 = np.radians([2.0, 3.0, 5.0])
    scheme = pf.Scheme(tuple(pf.PAPER_SCHEME.segments[:2]))  # south 1800 s, east 900 s
    run = pf.simulate(scheme, c, pf.angles_to_dcm(a0), LAT, gyro_noise=0.0, accel_noise=0.0)
    res = R.RollingEKF().calibrate(run.t[:2000], run.y[0, :2000], run.w_cmd[0, :2000], LAT,
                                   x0=np.concatenate([c, a0]))
    err = res.x - run.states[0, :2000]
    # same model, no noise: the estimate stays on the truth to rounding (6e-5 arcsec measured)
    assert np.max(np.abs(err[:, pf.ANGLES])) < 1e-3 * np.radians(1 / 3600)
    # no process noise on the coefficients: their sigmas only shrink (the angles' may grow, rotating
    # the poorly observed azimuth uncertainty into the other angles)
    assert np.all(np.diff(res.sigma[:, :pf.N_COEFFS], axis=0) <= 1e-12 * res.sigma[:-1, :pf.N_COEFFS])


def test_bad_input_is_named():
    ekf = R.RollingEKF()
    with pytest.raises(ValueError, match="y, w_cmd: expected shape"):
        ekf.calibrate(np.arange(1, 11) * 0.2, np.zeros((9, 3)), np.zeros((10, 3)), LAT)
    with pytest.raises(ValueError, match="expected finite"):
        ekf.calibrate(np.arange(1, 11) * 0.2, np.full((10, 3), np.nan), np.zeros((10, 3)), LAT)


def test_noise_free_paper_run_recovers_every_coefficient_within_its_sigma():
    """The paper's scheme and Table 1 truths (scenario paper002-rolling, run 0), noise off: every coefficient
    ends within 4 of the filter's own sigmas (2.4 measured, the torquer X worst; with the second-order term
    weighted 1 instead of 3 it was 27: overconfident), and the accelerometer bias and scale factor within
    the paper's 1 ug and 1 ppm (0.08 ug and 0.16 ppm measured). The weakest terms (torquer, gyro axis
    angles) stay up to 30 % off: the 1 % of the issue is not reached (see the issue note)."""
    from fusionbench import scenarios
    from fusionbench.calibration import draw_truth

    scn = scenarios.get("paper002-rolling")
    c, a = draw_truth(scn.platform, 0, 0)
    run = pf.simulate(scn.platform.scheme, c, pf.angles_to_dcm(a), scn.site.lat, 0.0, 0.0, 0.0)
    res = R.RollingEKF().calibrate(run.t, run.y[0], run.w_cmd[0], scn.site.lat)
    est = res.final()
    z = (est[:pf.N_COEFFS] - c) / res.sigma[-1, :pf.N_COEFFS]
    assert np.max(np.abs(z)) < 4.0
    err = pf.to_customary(est[:pf.N_COEFFS] - c)
    assert np.max(np.abs(err[pf.K0])) < 1.0 and np.max(np.abs(err[pf.K1])) < 1.0
