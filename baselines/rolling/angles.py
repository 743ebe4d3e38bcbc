"""The attitude angles of the floated platform (seed 002, Ding, rolling-platform self-calibration): the direction
cosine matrix ``C_pn`` (ENU to platform) of ``[phi, theta, psi]`` (rad) and back, and the angles' rates for a relative
rate of the platform (rad/s); the equations are in the :mod:`baselines.rolling` module notes."""

from __future__ import annotations

import numpy as np

from .terms import dcm_terms, rate_terms

#: ``v_NUE = P_NUE @ v_ENU``.
P_NUE = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def _check_vec(v, name):
    v = np.asarray(v, dtype=float)
    if v.ndim < 1 or v.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (..., 3), found {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: expected finite values, found NaN or inf")
    return v



def angles_to_dcm(angles):
    """``C_pn`` from the attitude angles ``[phi, theta, psi]`` (rad), ``(..., 3)`` -> ``(..., 3, 3)``.

    ``P_NUE @ C_pn = Rx(phi) Ry(theta) Rz(psi)`` (see the module notes).
    """
    return _angles_dcm(_check_vec(angles, "angles"))


def _angles_dcm(a):
    """:func:`angles_to_dcm` without input checks (for the filter's inner loop)."""
    M = np.stack(dcm_terms(np.sin(a[..., 0]), np.cos(a[..., 0]), np.sin(a[..., 1]), np.cos(a[..., 1]),
                           np.sin(a[..., 2]), np.cos(a[..., 2])), axis=-1).reshape(a.shape[:-1] + (3, 3))
    return P_NUE.T @ M


def dcm_to_angles(C_pn):
    """Attitude angles ``[phi, theta, psi]`` (rad) of ``C_pn``, ``(..., 3, 3)`` -> ``(..., 3)``.

    ``theta`` lies in [-pi/2, pi/2], ``phi`` and ``psi`` in (-pi, pi].
    """
    C = np.asarray(C_pn, dtype=float)
    if C.ndim < 2 or C.shape[-2:] != (3, 3):
        raise ValueError(f"C_pn: expected shape (..., 3, 3), found {C.shape}")
    M = P_NUE @ C
    theta = np.arctan2(M[..., 0, 2], np.hypot(M[..., 0, 0], M[..., 0, 1]))
    psi = np.arctan2(-M[..., 0, 1], M[..., 0, 0])
    phi = np.arctan2(-M[..., 1, 2], M[..., 2, 2])
    return np.stack([phi, theta, psi], axis=-1)


def euler_rate_matrix(angles):
    """``B`` with ``w_np^p = B @ [phi', theta', psi']`` (see the module notes), ``(..., 3, 3)``."""
    a = _check_vec(angles, "angles")
    st, ct = np.sin(a[..., 1]), np.cos(a[..., 1])
    ss, cs = np.sin(a[..., 2]), np.cos(a[..., 2])
    B = np.zeros(a.shape[:-1] + (3, 3))
    B[..., 0, 0], B[..., 0, 1] = cs * ct, ss
    B[..., 1, 0], B[..., 1, 1] = -ss * ct, cs
    B[..., 2, 0], B[..., 2, 2] = st, 1.0
    return B


def angle_rates(angles, w_np_p):
    """Rates ``[phi', theta', psi']`` (rad/s) of the attitude angles for the relative rate ``w_np^p``.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        ``[phi, theta, psi]``, rad (``|theta|`` < 90 deg).
    w_np_p : array_like, shape (..., 3)
        Angular rate of p relative to n, resolved in p, rad/s.
    """
    return _angle_rates(_check_vec(angles, "angles"), _check_vec(w_np_p, "w_np_p"))


def _angle_rates(a, w):
    """:func:`angle_rates` without input checks."""
    return np.stack(rate_terms(np.sin(a[..., 1]), np.cos(a[..., 1]), np.sin(a[..., 2]), np.cos(a[..., 2]),
                               w[..., 0], w[..., 1], w[..., 2]), axis=-1)
