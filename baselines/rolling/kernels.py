"""Compiled (numba) model evaluations for the inner loop of :mod:`baselines.rolling.ekf`.

One filter step evaluates the state derivative four times (RK4), the error-state Jacobians, the
measurement, the error injection and the 45 sigmas on a single 45-vector. In NumPy each of these costs
tens of small array operations (about 0.9 ms a step in all); compiled, a few microseconds. The equations are those of
:mod:`baselines.rolling.ekf` (module notes) and :mod:`baselines.rolling`; the element formulas of the
attitude matrix, the angle rates, the drifts and the accelerometer outputs are the platform model's own
plain-arithmetic functions, compiled here, so there is one copy of each.

Arguments are float64 arrays: ``x`` (45,) state ``[42 coefficients (SI), phi, theta, psi (rad)]``,
``w`` (3,) torque command (rad/s, p frame), ``g`` gravity (m/s^2), ``wie`` (3,) earth rate in ENU (rad/s).
"""

from __future__ import annotations

import numba
import numpy as np

from .terms import accel_terms, dcm_terms, drift_terms, rate_terms

_drift = numba.njit(cache=True)(drift_terms)
_accel = numba.njit(cache=True)(accel_terms)
_dcm_t = numba.njit(cache=True)(dcm_terms)
_rates_t = numba.njit(cache=True)(rate_terms)
_MOUNT = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))  # (row, column) of G for coefficients 21..26


@numba.njit(cache=True)
def dcm(a):
    """``C_pn`` (3 x 3, p to ENU) from the angles ``a`` (3,), rad."""
    m = _dcm_t(np.sin(a[0]), np.cos(a[0]), np.sin(a[1]), np.cos(a[1]), np.sin(a[2]), np.cos(a[2]))
    C = np.empty((3, 3))
    for j in range(3):  # C_pn = P_NUE^T M: rows E, N, U are M's rows 2, 0, 1
        C[0, j], C[1, j], C[2, j] = m[6 + j], m[j], m[3 + j]
    return C


@numba.njit(cache=True)
def angles(C):
    """Angles ``[phi, theta, psi]`` (rad) of ``C_pn`` (:func:`baselines.rolling.angles.dcm_to_angles`)."""
    # M = P_NUE C: rows N, U, E of C
    theta = np.arctan2(C[1, 2], np.hypot(C[1, 0], C[1, 1]))
    psi = np.arctan2(-C[1, 1], C[1, 0])
    phi = np.arctan2(-C[2, 2], C[0, 2])
    return np.array([phi, theta, psi])


@numba.njit(cache=True)
def skew(v):
    """``[v x]`` (3 x 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@numba.njit(cache=True)
def gyro_inverse(c):
    """``G^-1`` of the gyro input-axis matrix (coefficients 21..26)."""
    G = np.eye(3)
    for k in range(6):
        G[_MOUNT[k][0], _MOUNT[k][1]] = c[21 + k]
    return np.linalg.inv(G)


@numba.njit(cache=True)
def drift_jacobian_f(c, f):
    """``d eps / d f^p`` (3 x 3) of the drift terms (:func:`baselines.rolling.model.gyro_drift`)."""
    f0, f1, f2 = f[0], f[1], f[2]
    return np.array([
        [c[3] + c[12] * f1 + c[13] * f2, c[4] + c[12] * f0 + c[14] * f2, c[5] + c[13] * f0 + c[14] * f1],
        [c[8] + c[16] * f1 + c[17] * f2, c[6] + c[15] * f2 + c[16] * f0, c[7] + c[15] * f1 + c[17] * f0],
        [c[10] + c[18] * f2 + c[20] * f1, c[11] + c[19] * f2 + c[20] * f0, c[9] + c[18] * f0 + c[19] * f1],
    ])


@numba.njit(cache=True)
def platform_rate(c, f, w):
    """Exact ``w_ip^p = G^-1 ((I + diag KT) w + eps(c, f))`` (rad/s) and ``G^-1``."""
    Gi = gyro_inverse(c)
    e = _drift(c, f[0], f[1], f[2])
    u = np.array([(1.0 + c[39]) * w[0] + e[0], (1.0 + c[40]) * w[1] + e[1], (1.0 + c[41]) * w[2] + e[2]])
    return Gi @ u, Gi


@numba.njit(cache=True)
def rate_partials(c, f, w):
    """Exact platform rate and its partials: ``(w_ip (3,), d w_ip / d coefficients (3 x 42),
    d w_ip / d f^p (3 x 3))``. ``dw/dc = G^-1 du/dc`` on the drift and torquer terms (u the right-hand side
    above), ``-G^-1 e_i w_j`` on the axis angle in row i, column j of G (``d(G^-1) = -G^-1 dG G^-1``), and
    ``dw/df = G^-1 d eps / d f``."""
    w_ip, Gi = platform_rate(c, f, w)
    f0, f1, f2 = f[0], f[1], f[2]
    J = np.zeros((3, 42))
    for i in range(3):
        J[i, i] = 1.0
        J[i, 39 + i] = w[i]
    J[0, 3], J[0, 4], J[0, 5] = f0, f1, f2
    J[1, 6], J[1, 7], J[1, 8] = f1, f2, f0
    J[2, 9], J[2, 10], J[2, 11] = f2, f0, f1
    J[0, 12], J[0, 13], J[0, 14] = f0 * f1, f0 * f2, f1 * f2
    J[1, 15], J[1, 16], J[1, 17] = f1 * f2, f1 * f0, f2 * f0
    J[2, 18], J[2, 19], J[2, 20] = f2 * f0, f2 * f1, f0 * f1
    J = Gi @ J
    for k in range(6):
        i, j = _MOUNT[k]
        for r in range(3):
            J[r, 21 + k] = -Gi[r, i] * w_ip[j]
    return w_ip, J, Gi @ drift_jacobian_f(c, f)


@numba.njit(cache=True)
def angle_derivative(x, w, g, wie):
    """``[phi', theta', psi']`` (rad/s): the angle part of the filter's ``f(x)`` (exact platform rate)."""
    a = x[42:45]
    C = dcm(a)
    w_ip, _ = platform_rate(x, g * C[2], w)
    w_np = w_ip - C.T @ wie
    r = _rates_t(np.sin(a[1]), np.cos(a[1]), np.sin(a[2]), np.cos(a[2]), w_np[0], w_np[1], w_np[2])
    return np.array([r[0], r[1], r[2]])


@numba.njit(cache=True)
def rk4(x, w, dt, g, wie):
    """The 45-vector after one RK4 step of ``dt`` (s) under the held command ``w``; coefficients constant."""
    out = x.copy()
    k1 = angle_derivative(x, w, g, wie)
    out[42:45] = x[42:45] + 0.5 * dt * k1
    k2 = angle_derivative(out, w, g, wie)
    out[42:45] = x[42:45] + 0.5 * dt * k2
    k3 = angle_derivative(out, w, g, wie)
    out[42:45] = x[42:45] + dt * k3
    k4 = angle_derivative(out, w, g, wie)
    out[42:45] = x[42:45] + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return out


@numba.njit(cache=True)
def error_F_rows(x, w, g, wie):
    """The angle rows (3 x 45) of the error-state ``F_e``; the coefficient rows are zero."""
    C = dcm(x[42:45])
    _, dw_dc, dw_df = rate_partials(x, g * C[2], w)
    rows = np.zeros((3, 45))
    rows[:, :42] = -C @ dw_dc
    rows[:, 42:45] = C @ dw_df @ C.T @ skew(np.array([0.0, 0.0, g])) - skew(wie)
    return rows


@numba.njit(cache=True)
def measurement(x, g):
    """Accelerometer outputs ``h(x)`` (3,), m/s^2."""
    C = dcm(x[42:45])
    y = _accel(x, g * C[2, 0], g * C[2, 1], g * C[2, 2])
    return np.array([y[0], y[1], y[2]])


@numba.njit(cache=True)
def error_H(x, g):
    """Output error = ``H_e e`` (3 x 45): the accelerometer partials, and ``-diag(s) A C^T [f^n x]`` on eta."""
    c = x
    C = dcm(x[42:45])
    f = g * C[2]
    A = np.eye(3)
    A[1, 0], A[2, 0], A[2, 1] = c[36], c[37], c[38]
    a = A @ f
    H = np.zeros((3, 45))
    s = np.empty(3)
    for j in range(3):
        s[j] = 1.0 + c[30 + j] + 2.0 * c[33 + j] * a[j]
        H[j, 27 + j] = 1.0
        H[j, 30 + j] = a[j]
        H[j, 33 + j] = a[j] * a[j]
    H[1, 36] = s[1] * f[0]
    H[2, 37], H[2, 38] = s[2] * f[0], s[2] * f[1]
    sA = A.copy()
    for j in range(3):
        sA[j] *= s[j]
    H[:, 42:45] = -(sA @ C.T) @ skew(np.array([0.0, 0.0, g]))
    return H


@numba.njit(cache=True)
def inject(x, e):
    """Nominal state corrected by the error ``e`` (45,): coefficients added, attitude turned by
    ``C <- R(-eta) C`` (Rodrigues); the angles stay continuous (no wrap at +-180 deg)."""
    out = x.copy()
    out[:42] += e[:42]
    v = -e[42:45]
    th = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    K = skew(v)
    if th < 1e-8:
        Rm = np.eye(3) + K + 0.5 * K @ K
    else:
        Rm = np.eye(3) + np.sin(th) / th * K + (1.0 - np.cos(th)) / (th * th) * K @ K
    a = angles(Rm @ dcm(x[42:45]))
    for i in range(3):
        out[42 + i] = x[42 + i] + (a[i] - x[42 + i] + np.pi) % (2.0 * np.pi) - np.pi
    return out


@numba.njit(cache=True)
def state_sigmas(x, P, D):
    """Standard deviations of the 45 states at the estimate ``x`` from the error covariance ``P`` (45 x 45)
    scaled by ``D`` (45,) (``e = D z``): the coefficients' ``sqrt(P_ii) D_i``, the angles' through
    ``d angles = -E C^T eta`` (a rotation eta in n seen by the Euler angles; E the inverse of the Euler-rate
    matrix, its columns the angle rates of unit ``w``)."""
    sig = np.empty(45)
    for i in range(42):
        sig[i] = np.sqrt(P[i, i]) * D[i]
    a = x[42:45]
    st, ct, ss, cs = np.sin(a[1]), np.cos(a[1]), np.sin(a[2]), np.cos(a[2])
    E = np.empty((3, 3))
    for j in range(3):
        E[0, j], E[1, j], E[2, j] = _rates_t(st, ct, ss, cs, 1.0 * (j == 0), 1.0 * (j == 1), 1.0 * (j == 2))
    J = -(E @ dcm(a).T)
    for j in range(3):
        J[:, j] *= D[42 + j]
    for i in range(3):
        s = 0.0
        for j in range(3):
            for k in range(3):
                s += J[i, j] * P[42 + j, 42 + k] * J[i, k]
        sig[42 + i] = np.sqrt(s)
    return sig
