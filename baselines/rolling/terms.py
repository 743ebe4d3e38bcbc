"""Element formulas of the platform model, in plain arithmetic: one copy read by the NumPy model
(:mod:`baselines.rolling.model`), the compiled simulator (:mod:`baselines.rolling.simulator`) and the filter's
compiled kernels (:mod:`baselines.rolling.kernels`).

Each function takes scalars or arrays and uses only ``+ - * /`` and indexing, so the same source runs under NumPy
(arrays broadcast over leading axes) and under ``numba.njit`` (floats in a compiled loop); the callers compile
it themselves. The equations are those of the :mod:`baselines.rolling` module notes. Units: angles in rad,
rates in rad/s, specific force and accelerometer outputs in m/s^2, coefficients in SI (order of
:data:`baselines.rolling.model.COEFF_NAMES`); frames: p the platform, n East-North-Up.
"""

from __future__ import annotations


def dcm_terms(sf, cf, st, ct, ss, cs):
    """The nine entries of ``M = Rx(phi) Ry(theta) Rz(psi)`` (row-major).

    Parameters
    ----------
    sf, cf, st, ct, ss, cs : float or ndarray
        Sines and cosines of the attitude angles phi, theta and psi (rad).

    Returns
    -------
    tuple of 9
        ``M[0, 0], M[0, 1], ..., M[2, 2]``; ``C_pn = P_NUE^T M`` (p to ENU: its rows E, N, U are M's rows 2, 0, 1).
    """
    return (ct * cs, -ct * ss, st,
            cf * ss + sf * st * cs, cf * cs - sf * st * ss, -sf * ct,
            sf * ss - cf * st * cs, sf * cs + cf * st * ss, cf * ct)


def rate_terms(st, ct, ss, cs, w0, w1, w2):
    """Rates of the attitude angles for a relative angular rate (the Euler-angle rate relation).

    Parameters
    ----------
    st, ct, ss, cs : float or ndarray
        Sines and cosines of theta and psi (rad; ``|theta|`` < 90 deg).
    w0, w1, w2 : float or ndarray
        ``w_np^p``: angular rate of p relative to n, resolved in p, rad/s.

    Returns
    -------
    tuple of 3
        ``(phi', theta', psi')``, rad/s.
    """
    dphi = (cs * w0 - ss * w1) / ct
    return dphi, ss * w0 + cs * w1, w2 - st * dphi


def drift_terms(c, f0, f1, f2):
    """Gyro drifts from the g-sensitive error model (no noise).

    Parameters
    ----------
    c : indexable of 42 (float or ndarray each)
        Coefficients, SI; ``c[i]`` may be a float (compiled loop) or an array (NumPy, leading axes).
    f0, f1, f2 : float or ndarray
        Specific force in p, m/s^2.

    Returns
    -------
    tuple of 3
        ``(eps_X, eps_Y, eps_Z)``: drift of each gyro about its input axis, rad/s.
    """
    # X gyro (I, O, S) = (x, y, z); Y gyro = (y, z, x); Z gyro = (z, x, y)
    ex = c[0] + c[3] * f0 + c[4] * f1 + c[5] * f2 + c[12] * f0 * f1 + c[13] * f0 * f2 + c[14] * f1 * f2
    ey = c[1] + c[6] * f1 + c[7] * f2 + c[8] * f0 + c[15] * f1 * f2 + c[16] * f1 * f0 + c[17] * f2 * f0
    ez = c[2] + c[9] * f2 + c[10] * f0 + c[11] * f1 + c[18] * f2 * f0 + c[19] * f2 * f1 + c[20] * f0 * f1
    return ex, ey, ez


def accel_terms(c, f0, f1, f2):
    """Accelerometer outputs (no noise): ``y_j = K0_j + (1 + K1_j) a_j + K2_j a_j^2`` with ``a = A f^p``.

    Parameters
    ----------
    c : indexable of 42 (float or ndarray each)
        Coefficients, SI.
    f0, f1, f2 : float or ndarray
        Specific force in p, m/s^2.

    Returns
    -------
    tuple of 3
        ``(y_X, y_Y, y_Z)``, m/s^2.
    """
    a0 = f0
    a1 = c[36] * f0 + f1
    a2 = c[37] * f0 + c[38] * f1 + f2
    y0 = c[27] + (1.0 + c[30]) * a0 + c[33] * a0 * a0
    y1 = c[28] + (1.0 + c[31]) * a1 + c[34] * a1 * a1
    y2 = c[29] + (1.0 + c[32]) * a2 + c[35] * a2 * a2
    return y0, y1, y2
