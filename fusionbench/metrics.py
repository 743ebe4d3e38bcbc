"""Alignment errors against truth, theoretical limits, settling time and statistics.

Errors are misalignment angles phi = [phiE, phiN, phiU] (rad, ENU) with
``C_bn_est = (I - [phi x]) C_bn_true`` (see :mod:`fusionbench.attitude`).

Theoretical limits of stationary alignment (any unbiased method, biases unobservable):
with the accelerometer bias ``nabla^n = C_bn nabla^b`` and gyro bias ``eps^n = C_bn eps^b``
resolved in ENU, g the local gravity and Omega the earth rate::

    phiE = -nabla_N / g
    phiN =  nabla_E / g
    phiU = -eps_E / (Omega cos L) + tan(L) nabla_E / g
"""

from __future__ import annotations

import numpy as np

from . import attitude, earth


def misalignment_history(C_bn_est, C_bn_true):
    """phi (rad, ENU), shape (R, M, 3), of estimates (R, M, 3, 3) against truth (M, 3, 3)."""
    return attitude.misalignment(C_bn_est, np.asarray(C_bn_true)[None])


def theoretical_limits(gyro_bias_b, accel_bias_b, C_bn, lat, h=0.0):
    """Limit misalignment (rad, ENU) of stationary alignment, shape (..., 3).

    Parameters
    ----------
    gyro_bias_b : array_like, shape (..., 3)
        Gyro bias, body frame, rad/s.
    accel_bias_b : array_like, shape (..., 3)
        Accelerometer bias, body frame, m/s^2.
    C_bn : array_like, shape (..., 3, 3)
        True attitude.
    lat : float
        Latitude, rad.
    h : float
        Height, m.
    """
    C = np.asarray(C_bn, dtype=float)
    eps = np.einsum("...ij,...j->...i", C, np.asarray(gyro_bias_b, dtype=float))
    nab = np.einsum("...ij,...j->...i", C, np.asarray(accel_bias_b, dtype=float))
    g = earth.gravity(lat, h)
    wn = earth.OMEGA_IE * np.cos(lat)
    return np.stack(
        [-nab[..., 1] / g, nab[..., 0] / g, -eps[..., 0] / wn + np.tan(lat) * nab[..., 0] / g], axis=-1
    )


def settling_time(t, x, band, target=0.0):
    """First time after which ``|x - target|`` stays inside ``band`` until the end.

    Settling is measured against the truth: ``x`` is an error history (estimate minus truth, e.g. phiU
    in arcmin) and ``target`` the error a method should settle on, the theoretical limit (constant, or
    a history like ``x`` when the limit moves with the attitude). A method that settles on a wrong
    value does not settle.

    Parameters
    ----------
    t : array_like, shape (M,)
        Times, s.
    x : array_like, shape (..., M)
        Error histories, e.g. phiU in arcmin.
    band : float
        Half-width of the band, same units as ``x``.
    target : float or array_like broadcastable to ``x``
        Where the error should settle (the limit), same units as ``x``.

    Returns
    -------
    ndarray, shape (...)
        Settling time, s: ``t[0]`` if always inside; ``t[-1]`` for a history that ends outside the band
        (not settled: :func:`settled` tells these apart).
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    outside = np.abs(x - target) > band
    any_out = outside.any(axis=-1)
    last_out = x.shape[-1] - 1 - np.argmax(outside[..., ::-1], axis=-1)
    idx = np.where(any_out, np.minimum(last_out + 1, x.shape[-1] - 1), 0)
    return t[idx]


def settled(x, band, target=0.0):
    """Whether each history ``x`` (..., M) ends inside ``band`` around ``target`` (bool, shape (...))."""
    x = np.asarray(x, dtype=float)
    target = np.broadcast_to(np.asarray(target, dtype=float), x.shape)
    return np.abs(x[..., -1] - target[..., -1]) <= band


def stats(x):
    """``{"mean", "std", "rms", "max_abs"}`` of the values in ``x`` (floats, same units as x)."""
    x = np.asarray(x, dtype=float).ravel()
    return {
        "mean": float(np.mean(x)),
        "std": float(np.std(x)),
        "rms": float(np.sqrt(np.mean(x**2))),
        "max_abs": float(np.max(np.abs(x))),
    }


def rmse_window(t, x, t_from, t_to=None):
    """RMS of ``x`` (..., M) over times ``t_from <= t <= t_to`` (s), along the last axis."""
    t = np.asarray(t, dtype=float)
    t_to = t[-1] if t_to is None else t_to
    sel = (t >= t_from) & (t <= t_to)
    if not np.any(sel):
        raise ValueError(f"window: no sample between {t_from} s and {t_to} s")
    return np.sqrt(np.mean(np.asarray(x)[..., sel] ** 2, axis=-1))
