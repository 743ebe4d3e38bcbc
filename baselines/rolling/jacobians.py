"""Analytic Jacobians of seed 002's (Ding, rolling-platform self-calibration) rolling-EKF model
(:mod:`baselines.rolling.ekf`), in two forms.

State ``x = [42 error coefficients (SI), phi, theta, psi (rad)]``; model in the :mod:`baselines.rolling.ekf`
and :mod:`baselines.rolling` module notes (``f^p = g M^T e_U``, ``M = P C_pn = Rx(phi) Ry(theta)
Rz(psi)``, exact platform rate ``w_ip = G^-1 ((I + diag KT) w_cmd + eps)``, E the inverse Euler-rate matrix).

Angle space (:func:`jacobian_h`, :func:`jacobian_f`: the derivatives of ``h(x)`` and ``f(x)`` themselves)
and error state (:func:`error_H`, :func:`error_F`: the covariance's model, ``e = [c_true - c_est, eta]``
with ``C_true = (I - [eta x]) C_est``; the filter uses these, compiled in :mod:`baselines.rolling.kernels`).

Jacobians (analytic; tests compare them with central finite differences):

* ``H = dh/dx``: I on K0; ``a_j`` on K1_j; ``a_j^2`` on K2_j; ``s_j f_i`` on the accelerometer
  axis angles (``s = 1 + K1 + 2 K2 a``); ``diag(s) A df^p/dangles`` on the angles, with
  ``df^p/dalpha = g (dM/dalpha)^T e_U``, ``dM/dphi = [e1 x] M``, ``dM/dtheta = Rx [e2 x] Ry Rz``,
  ``dM/dpsi = M [e3 x]``.
* ``F = df/dx`` (angle rows only): ``E dw/dc`` on the coefficients (``G^-1`` times: I on D0, the
  specific-force terms on D1, D2, ``diag(w_cmd)`` on KT; ``-G^-1 e_i w_j`` on the axis angle G_ij) and
  ``E dw/dangles + (dE/dangles) w`` on the angles, with ``dw/dangles = G^-1 J_eps df^p/dangles -
  (dM/dalpha)^T P w_ie^n`` and the explicit derivatives of the rate relation
  ``dphi'/dtheta = phi' tan theta``, ``dphi'/dpsi = -theta' / cos theta``, ``dtheta'/dpsi = phi' cos theta``,
  ``dpsi'/dtheta = -phi' / cos theta``, ``dpsi'/dpsi = theta' tan theta``.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import earth

from . import kernels as K
from . import angles, model

_E1, _E2, _E3 = np.eye(3)


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
    return M, (K.skew(_E1) @ M, Rx @ K.skew(_E2) @ Ry @ Rz, M @ K.skew(_E3))


def rate_inverse(angles):
    """E (3 x 3) with ``[phi', theta', psi'] = E w``: the inverse of the Euler-rate matrix B of the
    :mod:`baselines.rolling` module notes, for the angles ``[phi, theta, psi]`` (rad); w = ``w_np^p`` (rad/s, p)."""
    st, ct = np.sin(angles[1]), np.cos(angles[1])
    ss, cs = np.sin(angles[2]), np.cos(angles[2])
    return np.array([[cs / ct, -ss / ct, 0.0], [ss, cs, 0.0], [-st * cs / ct, st * ss / ct, 1.0]])


def jacobian_h(x, lat, h=0.0):
    """dh/dx (3 x 45) at the 45-vector ``x`` (module notes)."""
    c, ang = x[:model.N_COEFFS], x[model.ANGLES]
    g = float(earth.gravity(lat, h))
    M, dM = _dM(ang)
    H = K.error_H(np.asarray(x, dtype=float), g)  # the coefficient columns are the error state's
    A = model.accel_matrix(c)
    s = 1.0 + c[model.K1] + 2.0 * c[model.K2] * (A @ (g * M[1]))  # dy/da; f^p = g M^T e_U (e_U = NUE y)
    df = np.stack([g * d[1] for d in dM], axis=1)  # columns d f^p / d alpha
    H[:, model.ANGLES] = (s[:, None] * A) @ df
    return H


def jacobian_f(x, w_cmd, lat, h=0.0):
    """df/dx (45 x 45) at ``x`` under the command ``w_cmd`` (rad/s, p frame); rows of the coefficients are zero."""
    c, ang = x[:model.N_COEFFS], x[model.ANGLES]
    g = float(earth.gravity(lat, h))
    w_ie_nue = angles.P_NUE @ earth.earth_rate_n(lat)
    M, dM = _dM(ang)
    f = g * M[1]
    w_ip, dw_dc, dw_df = K.rate_partials(np.asarray(c, dtype=float), f, np.asarray(w_cmd, dtype=float))
    w = w_ip - M.T @ w_ie_nue
    E = rate_inverse(ang)
    rates = E @ w
    dw_da = np.stack([dw_df @ (g * d[1]) - d.T @ w_ie_nue for d in dM], axis=1)
    st, ct = np.sin(ang[1]), np.cos(ang[1])
    explicit = np.zeros((3, 3))  # d(E w)/d angles with w held
    explicit[0, 1], explicit[0, 2] = rates[0] * st / ct, -rates[1] / ct
    explicit[1, 2] = rates[0] * ct
    explicit[2, 1], explicit[2, 2] = -rates[0] / ct, rates[1] * st / ct
    F = np.zeros((model.N_STATES, model.N_STATES))
    F[model.ANGLES, :model.N_COEFFS] = E @ dw_dc
    F[model.ANGLES, model.ANGLES] = E @ dw_da + explicit
    return F


def error_jacobians(x, w_cmd, lat, h=0.0):
    """Jacobians of the error-state model the filter's covariance lives in, ``(F_e (45, 45), H_e (3, 45))``.

    Error state ``e = [c_true - c_est (42), eta (3)]`` with ``C_true = (I - [eta x]) C_est`` (eta a small
    rotation in n, rad); see the module notes, "Error-state covariance"."""
    return error_F(x, w_cmd, lat, h), error_H(x, lat, h)


def error_F(x, w_cmd, lat, h=0.0):
    """d e / dt = F_e e (45 x 45): ``eta' = -C dw/dc dc + C dw/df C^T [f^n x] eta - [w_ie^n x] eta``
    (``dw/dc``, ``dw/df``: partials of the exact platform rate, :func:`baselines.rolling.kernels.rate_partials`)."""
    F = np.zeros((model.N_STATES, model.N_STATES))
    F[model.ANGLES] = K.error_F_rows(np.asarray(x, dtype=float), np.asarray(w_cmd, dtype=float),
                                  float(earth.gravity(lat, h)), earth.earth_rate_n(lat))
    return F


def error_H(x, lat, h=0.0):
    """Output error = H_e e (3 x 45): the coefficient columns of :func:`jacobian_h`, and
    ``-diag(s) A C^T [f^n x]`` on eta (its vertical column is zero: a turn about the vertical is unseen)."""
    return K.error_H(np.asarray(x, dtype=float), float(earth.gravity(lat, h)))
