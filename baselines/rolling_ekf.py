"""Seed 002's 45-state EKF for continuous rolling self-calibration and self-alignment (method ``rolling-ekf``).

State ``x = [42 error coefficients (SI), phi, theta, psi (rad)]`` of :mod:`fusionbench.platform`: the
attitude enters as the platform's Euler angles from North-Up-East, not as small misalignment angles,
so initial attitude errors of several degrees are allowed. Measurements: the three accelerometer
outputs (m/s^2) every ``filter_s`` (0.2 s). The filter knows its torque commands.

Model (``fusionbench.platform`` module notes)::

    x' = f(x, w_cmd) = [0 (42);  E(angles) w_np^p]
    w_np^p = w_cmd + KT w_cmd - M_g w_cmd + eps(c, f^p) - C_pn^T w_ie^n        (first order, eq. 19)
    f^p = g M^T e_U,   M = P C_pn = Rx(phi) Ry(theta) Rz(psi)
    y = h(x) = K0 + (1 + K1) a + K2 a^2,   a = A(c) f^p

with E the inverse of the Euler-rate matrix B (``w = B [phi', theta', psi']``)::

    phi' = (cos psi w_x - sin psi w_y) / cos theta
    theta' = sin psi w_x + cos psi w_y
    psi' = w_z - sin theta phi'

Jacobians (analytic; tests compare them with central finite differences):

* ``H = dh/dx``: I on K0; ``a_j`` on K1_j; ``a_j^2`` on K2_j; ``s_j f_i`` on the accelerometer
  axis angles (``s = 1 + K1 + 2 K2 a``); ``diag(s) A df^p/dangles`` on the angles, with
  ``df^p/dalpha = g (dM/dalpha)^T e_U``, ``dM/dphi = [e1 x] M``, ``dM/dtheta = Rx [e2 x] Ry Rz``,
  ``dM/dpsi = M [e3 x]``.
* ``F = df/dx`` (angle rows only): ``E dw/dc`` on the coefficients (I on D0; the specific-force terms
  on D1, D2; ``-w_cmd`` components on the gyro axis angles; ``diag(w_cmd)`` on KT) and
  ``E dw/dangles + (dE/dangles) w`` on the angles, with ``dw/dangles = J_eps df^p/dangles -
  (dM/dalpha)^T P w_ie^n`` and the explicit derivatives of the rate relation
  ``dphi'/dtheta = phi' tan theta``, ``dphi'/dpsi = -theta' / cos theta``, ``dtheta'/dpsi = phi' cos theta``,
  ``dpsi'/dtheta = -phi' / cos theta``, ``dpsi'/dpsi = theta' tan theta``.

Filter (filterpy :class:`~filterpy.kalman.ExtendedKalmanFilter`, Joseph-form update) on the states
scaled by their prior standard deviations (``x = D z``; the raw states span 1e-12 rad/s to 0.1 rad,
too wide for the covariance in float64): the state is propagated over each filter step with 4th-order Runge-Kutta of ``f`` (command held), the covariance
with ``Phi = I + F T + (F T)^2 / 2``; process noise only on the angles, from the gyros' white drift
(``E q T E^T``, q the rate noise density, rad^2/s); measurement noise the accelerometers' white noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.spatial.transform import Rotation
from threadpoolctl import threadpool_limits

from pathlib import Path

from fusionbench import earth
from fusionbench import platform as pf

#: Prior standard deviation of each coefficient group in its customary unit (filter starts at zero),
#: and of the attitude angles (deg): wide enough for seed 002's Table 1 spreads and a coarse start.
PRIOR_SIGMA = {"D0": 2.0, "D1": 2.0, "D2": 0.5, "GYRO_MOUNT": 300.0, "K0": 1000.0, "K1": 1000.0, "K2": 50.0,
               "ACCEL_MOUNT": 300.0, "KT": 1000.0}
ANGLE_SIGMA_DEG = 5.0
_E1, _E2, _E3 = np.eye(3)


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rot(axis, a):
    c, s = np.cos(a), np.sin(a)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _dM(angles):
    """M = Rx(phi) Ry(theta) Rz(psi) and its three partial derivatives."""
    Rx, Ry, Rz = _rot(0, angles[0]), _rot(1, angles[1]), _rot(2, angles[2])
    M = Rx @ Ry @ Rz
    return M, (_skew(_E1) @ M, Rx @ _skew(_E2) @ Ry @ Rz, M @ _skew(_E3))


def _drift_jacobian_f(c, f):
    """d eps / d f^p (3 x 3) of the drift terms (see :func:`fusionbench.platform.gyro_drift`)."""
    f0, f1, f2 = f
    return np.array([
        [c[3] + c[12] * f1 + c[13] * f2, c[4] + c[12] * f0 + c[14] * f2, c[5] + c[13] * f0 + c[14] * f1],
        [c[8] + c[16] * f1 + c[17] * f2, c[6] + c[15] * f2 + c[16] * f0, c[7] + c[15] * f1 + c[17] * f0],
        [c[10] + c[18] * f2 + c[20] * f1, c[11] + c[19] * f2 + c[20] * f0, c[9] + c[18] * f0 + c[19] * f1],
    ])


def _rate_wrt_coeffs(f, w_cmd):
    """d w_np^p / d coefficients (3 x 42)."""
    f0, f1, f2 = f
    J = np.zeros((3, pf.N_COEFFS))
    J[:, 0:3] = np.eye(3)
    J[0, 3:6] = f0, f1, f2
    J[1, 6:9] = f1, f2, f0
    J[2, 9:12] = f2, f0, f1
    J[0, 12:15] = f0 * f1, f0 * f2, f1 * f2
    J[1, 15:18] = f1 * f2, f1 * f0, f2 * f0
    J[2, 18:21] = f2 * f0, f2 * f1, f0 * f1
    J[0, 21], J[0, 22] = -w_cmd[1], -w_cmd[2]
    J[1, 23], J[1, 24] = -w_cmd[0], -w_cmd[2]
    J[2, 25], J[2, 26] = -w_cmd[0], -w_cmd[1]
    J[:, 39:42] = np.diag(w_cmd)
    return J


def _rate_inverse(angles):
    """E with [phi', theta', psi'] = E w."""
    st, ct = np.sin(angles[1]), np.cos(angles[1])
    ss, cs = np.sin(angles[2]), np.cos(angles[2])
    return np.array([[cs / ct, -ss / ct, 0.0], [ss, cs, 0.0], [-st * cs / ct, st * ss / ct, 1.0]])


def _accel_partials(c, f):
    """Output partials on the accelerometer coefficients at specific force ``f`` (p), with A and
    ``s = dy/da = 1 + K1 + 2 K2 a``: (H (3 x 45, angle columns zero), A, s)."""
    A = pf.accel_matrix(c)
    a = A @ f
    s = 1.0 + c[pf.K1] + 2.0 * c[pf.K2] * a
    H = np.zeros((3, pf.N_STATES))
    H[:, pf.K0] = np.eye(3)
    H[:, pf.K1] = np.diag(a)
    H[:, pf.K2] = np.diag(a * a)
    H[1, 36] = s[1] * f[0]
    H[2, 37], H[2, 38] = s[2] * f[0], s[2] * f[1]
    return H, A, s


def jacobian_h(x, lat, h=0.0):
    """dh/dx (3 x 45) at the 45-vector ``x`` (module notes)."""
    c, ang = x[:pf.N_COEFFS], x[pf.ANGLES]
    g = float(earth.gravity(lat, h))
    M, dM = _dM(ang)
    f = g * M[1]  # f^p = g M^T e_U (e_U = NUE y)
    H, A, s = _accel_partials(c, f)
    df = np.stack([g * d[1] for d in dM], axis=1)  # columns d f^p / d alpha
    H[:, pf.ANGLES] = (s[:, None] * A) @ df
    return H


def jacobian_f(x, w_cmd, lat, h=0.0):
    """df/dx (45 x 45) at ``x`` under the command ``w_cmd`` (rad/s, p frame); rows of the coefficients are zero."""
    c, ang = x[:pf.N_COEFFS], x[pf.ANGLES]
    g = float(earth.gravity(lat, h))
    w_ie_nue = pf.P_NUE @ earth.earth_rate_n(lat)
    M, dM = _dM(ang)
    f = g * M[1]
    eps = pf.gyro_drift(c, f)
    w = (1.0 + c[pf.KT]) * w_cmd - (pf.gyro_matrix(c) - np.eye(3)) @ w_cmd + eps - M.T @ w_ie_nue
    E = _rate_inverse(ang)
    rates = E @ w
    dw_da = np.stack([_drift_jacobian_f(c, f) @ (g * d[1]) - d.T @ w_ie_nue for d in dM], axis=1)
    st, ct = np.sin(ang[1]), np.cos(ang[1])
    explicit = np.zeros((3, 3))  # d(E w)/d angles with w held
    explicit[0, 1], explicit[0, 2] = rates[0] * st / ct, -rates[1] / ct
    explicit[1, 2] = rates[0] * ct
    explicit[2, 1], explicit[2, 2] = -rates[0] / ct, rates[1] * st / ct
    F = np.zeros((pf.N_STATES, pf.N_STATES))
    F[pf.ANGLES, :pf.N_COEFFS] = E @ _rate_wrt_coeffs(f, w_cmd)
    F[pf.ANGLES, pf.ANGLES] = E @ dw_da + explicit
    return F


def error_jacobians(x, w_cmd, lat, h=0.0):
    """Jacobians of the error-state model the filter's covariance lives in, ``(F_e (45, 45), H_e (3, 45))``.

    Error state ``e = [c_true - c_est (42), eta (3)]`` with ``C_true = (I - [eta x]) C_est`` (eta a small
    rotation in n, rad); see the module notes, "Error-state covariance"."""
    return error_F(x, w_cmd, lat, h), error_H(x, lat, h)


def error_F(x, w_cmd, lat, h=0.0):
    """d e / dt = F_e e (45 x 45): ``eta' = -C J_c dc + C J_eps C^T [f^n x] eta - [w_ie^n x] eta``."""
    c, ang = x[:pf.N_COEFFS], x[pf.ANGLES]
    g = float(earth.gravity(lat, h))
    C = pf.angles_to_dcm(ang)
    f = C.T @ np.array([0.0, 0.0, g])
    F = np.zeros((pf.N_STATES, pf.N_STATES))
    F[pf.ANGLES, :pf.N_COEFFS] = -C @ _rate_wrt_coeffs(f, w_cmd)
    F[pf.ANGLES, pf.ANGLES] = C @ _drift_jacobian_f(c, f) @ C.T @ _skew([0.0, 0.0, g]) - _skew(earth.earth_rate_n(lat))
    return F


def error_H(x, lat, h=0.0):
    """Output error = H_e e (3 x 45): the coefficient columns of :func:`jacobian_h`, and
    ``-diag(s) A C^T [f^n x]`` on eta (its vertical column is zero: a turn about the vertical is unseen)."""
    c, ang = x[:pf.N_COEFFS], x[pf.ANGLES]
    g = float(earth.gravity(lat, h))
    C = pf.angles_to_dcm(ang)
    f = C.T @ np.array([0.0, 0.0, g])
    H, A, s = _accel_partials(c, f)
    H[:, pf.ANGLES] = -(s[:, None] * A) @ C.T @ _skew([0.0, 0.0, g])
    return H


def informed_directions(M, threshold=1.0):
    """Directions of a prior-scaled information matrix in which the data outweigh the prior: eigenvalues
    above ``threshold`` (1: the posterior variance ``(I + M)^-1`` is below half the prior's). Unlike the
    rank (:func:`baselines.rolling_observability.information_rank`, a structural property) this depends
    on the noise and the priors: how many directions a run actually calibrates."""
    ev = np.linalg.eigvalsh(0.5 * (np.asarray(M) + np.asarray(M).T))
    return int(np.sum(ev > threshold))


def level(y_mean):
    """Attitude angles levelled from the mean accelerometer outputs ``y_mean`` (m/s^2, ~ f^p), azimuth
    theta = 0: phi and psi put gravity on ``y_mean``'s direction.

    Why: gravity fixes two of the three angles; started from angles off in tilt by degrees, the EKF
    linearises the unobservable rotation about the true vertical at the wrong tangent, reads the azimuth
    as observed and locks it degrees off with a tiny sigma (measured: theta 3 deg off, sigma 0.005 deg
    after 1 s). Levelled first, only the azimuth is off, along the direction the filter sees as unobserved.
    With theta = 0, ``f^p / g = [sin psi cos phi, cos psi cos phi, -sin phi]``.
    """
    u = np.asarray(y_mean, dtype=float)
    u = u / np.linalg.norm(u)
    return np.array([-np.arcsin(np.clip(u[2], -1, 1)), 0.0, np.arctan2(u[0], u[1])])


def prior_sigma(angle_sigma_deg=ANGLE_SIGMA_DEG, groups=None):
    """Prior standard deviations of the 45 states, SI (from :data:`PRIOR_SIGMA` in customary units)."""
    groups = {**PRIOR_SIGMA, **(groups or {})}
    sig = np.empty(pf.N_STATES)
    for name, val in groups.items():
        sl = getattr(pf, name)
        sig[sl] = val * pf.COEFF_SCALE[sl]
    sig[pf.ANGLES] = np.radians(angle_sigma_deg)
    return sig


@dataclass
class CalibrationResult:
    """What :meth:`RollingEKF.calibrate` returns.

    Attributes
    ----------
    t : ndarray, shape (M,)
        Filter times, s.
    x : ndarray, shape (M, 45)
        State estimate after each update: 42 coefficients (SI) and the angles (rad).
    sigma : ndarray, shape (M, 45)
        Its standard deviations (square roots of the diagonal of P).
    figures : dict
        ``information_rank``: rank of the information matrix the run gathered (below; SVD, relative
        tolerance :data:`baselines.rolling_observability.RTOL`), ``informed_directions``
        (:func:`informed_directions`).
    information : ndarray, shape (45, 45)
        Information matrix of the run in prior-scaled error coordinates (e = D z):
        ``sum_k Phi(t_k, 0)^T H_k^T R^-1 H_k Phi(t_k, 0)`` with the filter's own F and H along its
        estimate and R the accelerometer noise (the piecewise-constant-system information matrix).
    """

    t: np.ndarray
    x: np.ndarray
    sigma: np.ndarray
    figures: dict = None
    information: np.ndarray = None

    def final(self, last_s=100.0):
        """The paper's readout, (45,): coefficients averaged over the last ``last_s`` seconds; the angles
        at the last filter time (they move with the platform, an average would mix attitudes)."""
        sel = self.t >= self.t[-1] - last_s
        out = self.x[sel].mean(axis=0)
        out[pf.ANGLES] = self.x[-1, pf.ANGLES]
        return out


class RollingEKF:
    """Seed 002's rolling self-calibration and self-alignment EKF (method ``rolling-ekf``).

    Parameters
    ----------
    gyro_noise : float
        Gyro white drift, standard deviation per simulator sample (rad/s), as in
        :func:`fusionbench.platform.simulate`.
    sample_s : float
        The sample time that ``gyro_noise`` refers to, s (rate noise density ``gyro_noise^2 sample_s``).
    accel_noise : float
        Accelerometer output noise, m/s^2 per output.
    angle_sigma_deg : float
        Prior standard deviation of the attitude angles, deg.
    prior : dict, optional
        Overrides of :data:`PRIOR_SIGMA` (customary units).
    level_s : float
        Seconds of outputs averaged for the initial levelling when no ``x0`` is given.
    second_order : float
        Weight of the second-order output term added to R, ``g^2 (s_h^2 s_v^2 + s_h^4)`` (s_h^2, s_v^2 the
        tilt and azimuth error variances). 3 by default: on three draws of ``paper002-rolling`` the largest
        |error| / sigma of the coefficients was 2.8 with 3 against 27 with 1 (overconfident), and 1.3 with
        10 at the price of accuracy (azimuth 130 against 35-90 arcsec); 0.1 diverges.
    """

    name = "rolling-ekf"
    description = "seed 002's 45-state EKF: 42 platform error coefficients and the attitude angles from rolling"

    def __init__(self, gyro_noise=pf.PAPER_GYRO_NOISE, sample_s=0.002, accel_noise=pf.PAPER_ACCEL_NOISE,
                 angle_sigma_deg=ANGLE_SIGMA_DEG, prior=None, level_s=1.0, second_order=3.0):
        self.q_rate = float(gyro_noise) ** 2 * float(sample_s)
        self.r = float(accel_noise) ** 2
        self.sigma0 = prior_sigma(angle_sigma_deg, prior)
        self.level_s = float(level_s)
        self.second_order = float(second_order)

    def calibrate(self, t, y, w_cmd, lat, h=0.0, x0=None):
        """Run the filter over one recording.

        Parameters
        ----------
        t : array_like, shape (M,)
            Filter times, s, uniformly spaced (the first is one step after the initial state).
        y : array_like, shape (M, 3)
            Accelerometer outputs at ``t``, m/s^2.
        w_cmd : array_like, shape (M, 3)
            Torque command (p frame, rad/s) held over the step ending at each ``t``.
        lat, h : float
            Latitude (rad) and height (m).
        x0 : array_like, shape (45,), optional
            Initial estimate. Default: zero coefficients (the paper's start) and the attitude levelled
            from the first ``level_s`` of outputs with theta (azimuth) 0 (:func:`level`).

        Returns
        -------
        CalibrationResult
        """
        t = np.asarray(t, dtype=float)
        y = np.asarray(y, dtype=float)
        w_cmd = np.asarray(w_cmd, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"t: expected at least two filter times, found shape {t.shape}")
        if y.shape != (t.size, 3) or w_cmd.shape != (t.size, 3):
            raise ValueError(f"y, w_cmd: expected shape ({t.size}, 3), found {y.shape} and {w_cmd.shape}")
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(w_cmd))):
            raise ValueError("y, w_cmd: expected finite values, found NaN or inf")
        with threadpool_limits(1):  # 45 x 45 products gain nothing from BLAS threads, and one thread keeps
            return self._run(t, y, w_cmd, lat, h, x0)  # the sums in a fixed order: identical numbers

    def _run(self, t, y, w_cmd, lat, h, x0):
        dt = float(t[1] - t[0])
        if x0 is None:
            x0 = np.zeros(pf.N_STATES)
            x0[pf.ANGLES] = level(y[t - t[0] < self.level_s].mean(axis=0))
        x = np.array(x0, dtype=float)
        # covariance of the error state, scaled by the prior sigmas (e = D z): the raw errors span 1e-12
        # rad/s to 0.1 rad, too wide for a positive-definite covariance in float64
        D = self.sigma0
        kf = ExtendedKalmanFilter(dim_x=pf.N_STATES, dim_z=3)
        kf.P = np.eye(pf.N_STATES)
        kf.R = self.r * np.eye(3)
        I = np.eye(pf.N_STATES)
        q_eta = self.q_rate * dt / D[pf.ANGLES] ** 2  # gyro white drift as rotation noise in n
        g = float(earth.gravity(lat, h))
        xs = np.empty((t.size, pf.N_STATES))
        sig = np.empty((t.size, pf.N_STATES))
        info = np.zeros((pf.N_STATES, pf.N_STATES))
        Phi_0 = np.eye(pf.N_STATES)
        for k in range(t.size):
            Fe = error_F(x, w_cmd[k], lat, h)
            Fs = Fe * dt * D[None, :] / D[:, None]
            Phi = I + Fs + 0.5 * Fs @ Fs
            Phi_0 = Phi @ Phi_0
            x = _rk4(x, w_cmd[k], dt, lat, h)
            kf.P = Phi @ kf.P @ Phi.T
            kf.P[pf.ANGLES, pf.ANGLES] += np.diag(q_eta)
            He = error_H(x, lat, h)
            Hs = He * D[None, :]
            HP = Hs @ Phi_0
            info += HP.T @ HP / self.r
            kf.x = np.zeros((pf.N_STATES, 1))
            # second-order term of h in the attitude error eta (the second-order EKF's added variance):
            # f^p changes by C^T (eta x (eta x f^n)) / 2 = g C^T (eta_h eta_U - |eta_h|^2 e_U) / 2 (eta_h the
            # tilt, eta_U the azimuth part); while the attitude is degrees off this is tens of ug, and
            # without it the 1-ug outputs make the filter trust the wrong linearisation (it diverges)
            Pe = kf.P[pf.ANGLES, pf.ANGLES] * np.outer(D[pf.ANGLES], D[pf.ANGLES])
            s_h2, s_v2 = Pe[0, 0] + Pe[1, 1], Pe[2, 2]
            kf.R = (self.r + self.second_order * g * g * (s_h2 * s_v2 + s_h2 * s_h2)) * np.eye(3)
            kf.update((y[k] - pf.measurement_unchecked(x, g)).reshape(3, 1), lambda z: Hs, lambda z: Hs @ z)
            kf.P = 0.5 * (kf.P + kf.P.T)
            x = _apply(x, kf.x[:, 0] * D)
            xs[k] = x
            sig[k] = _sigmas(x, kf.P, D)
        from .rolling_observability import information_rank  # it builds on this module's Jacobians

        figures = {"information_rank": information_rank(info), "informed_directions": informed_directions(info)}
        return CalibrationResult(t, xs, sig, figures, info)

    def report_figures(self, folder, scheme, lat, h=0.0):
        """The output-sensitivity curves of ``scheme`` (seed 002 Figs. 4-7) into ``folder``; [(file, caption)]."""
        from .rolling_observability import sensitivity_curves, sensitivity_figure

        times, S = sensitivity_curves(scheme, lat, h)
        sensitivity_figure(times, S, path=Path(folder) / "sensitivity.png")
        return [("sensitivity.png", "output sensitivity of the coefficients along the scheme (seed 002 Figs. 4-7)")]


def _apply(x, e):
    """Nominal state corrected by the estimated error ``e`` (coefficients added, attitude turned by
    ``C <- (I - [eta x]) C``); the angles stay continuous (no wrap at +-180 deg)."""
    out = x.copy()
    out[:pf.N_COEFFS] += e[:pf.N_COEFFS]
    C = Rotation.from_rotvec(-e[pf.ANGLES]).as_matrix() @ pf.angles_to_dcm(x[pf.ANGLES])
    a = pf.dcm_to_angles(C)
    out[pf.ANGLES] = x[pf.ANGLES] + (a - x[pf.ANGLES] + np.pi) % (2 * np.pi) - np.pi
    return out


def _sigmas(x, P, D):
    """Standard deviations of the 45 states from the scaled error covariance; the angles' through
    ``d angles = -E C^T eta`` (a rotation eta in n seen by the Euler angles)."""
    sig = np.sqrt(np.diag(P)) * D
    J = -_rate_inverse(x[pf.ANGLES]) @ pf.angles_to_dcm(x[pf.ANGLES]).T * D[None, pf.ANGLES]
    sig[pf.ANGLES] = np.sqrt(np.diag(J @ P[pf.ANGLES, pf.ANGLES] @ J.T))
    return sig


def _rk4(x, w_cmd, dt, lat, h):
    g, w_ie = float(earth.gravity(lat, h)), earth.earth_rate_n(lat)
    f = lambda s: pf.state_derivative_unchecked(s, w_cmd, g, w_ie)  # noqa: E731
    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
