"""Alignment errors against truth, theoretical limits, settling time and statistics.

Errors are misalignment angles phi = [phiE, phiN, phiU] (rad, ENU) with
``C_bn_est = (I - [phi x]) C_bn_true`` (see :mod:`fusionbench.simulation.attitude`).

Theoretical limits of stationary alignment (any unbiased method, biases unobservable):
with the accelerometer bias ``nabla^n = C_bn nabla^b`` and gyro bias ``eps^n = C_bn eps^b``
resolved in ENU, g the local gravity and Omega the earth rate::

    phiE = -nabla_N / g
    phiN =  nabla_E / g
    phiU = -eps_E / (Omega cos L) + tan(L) nabla_E / g

:func:`attainable_bound` gives the rest: the standard deviation about that limit which an optimal
estimator reaches with the sensors' noise (white noise, random and drifting bias parts) and the
velocity reference's or a receiver's noise, on a static, swaying or moving base; :func:`bias_limit` the
limit's generalisation to a moving base. Both live in :mod:`fusionbench.scoring.bound` and are re-exported here.
"""

from __future__ import annotations

import numpy as np

from fusionbench.scoring.bound import VREF_FLOOR, attainable_bound, bias_limit  # their home is bound
from fusionbench.simulation import attitude, earth

__all__ = ["misalignment_history", "theoretical_limits", "settling_time", "settled", "stats", "attainable_bound",
           "bias_limit", "VREF_FLOOR"]


def misalignment_history(C_bn_est, C_bn_true):
    """phi (rad, ENU), shape (R, M, 3), of estimates (R, M, 3, 3) against truth (M, 3, 3).

    Run by run, so that the temporaries of the rotation-vector conversion are one run's (a 20-hour history at 1 s
    holds 72 000 attitudes a run; all runs at once cost about 22 MB a run over the result)."""
    C_est = np.asarray(C_bn_est, dtype=float)
    C_true = np.asarray(C_bn_true, dtype=float)
    out = np.empty(C_est.shape[:-1])
    for r in range(C_est.shape[0]):
        out[r] = attitude.misalignment(C_est[r], C_true)
    return out


def theoretical_limits(gyro_bias_b, accel_bias_b, C_bn, lat, h=0.0, f_n=None, w_in=None):
    """Limit misalignment (rad, ENU) of alignment with unknown constant biases, shape (..., 3).

    The steady state of the error model in which the level velocity errors stop changing and the east tilt
    stops drifting (the gyrocompass condition)::

        dvE' =  fN phiU - fU phiN + nabE = 0
        dvN' = -fE phiU + fU phiE + nabN = 0
        phiE' = wU phiN - wN phiU - epsE = 0

    with ``f^n = [fE, fN, fU]`` the base's specific force and ``w_in = [wE, wN, wU]`` the navigation
    frame's rate (the term wE is dropped with the level rows it multiplies). On a stationary or swaying
    base (``f_n = [0, 0, g]``, ``w_in`` the earth rate: the defaults) it is the classical limit of the
    module docstring; on a base accelerating steadily the specific force leans and the azimuth limit
    couples into the level by fN / g and fE / g (a gyro bias's azimuth limit of 5 deg comes with a
    level limit of 30 arcmin at 0.1 g).

    Parameters
    ----------
    gyro_bias_b : array_like, shape (..., 3)
        Gyro bias, body frame, rad/s.
    accel_bias_b : array_like, shape (..., 3)
        Accelerometer bias, body frame, m/s^2.
    C_bn : array_like, shape (..., 3, 3)
        True attitude.
    lat : float or array_like
        Latitude, rad.
    h : float or array_like
        Height, m.
    f_n : array_like, shape (..., 3), optional
        Mean specific force of the base, ENU, m/s^2 (default ``[0, 0, g]``: not accelerating).
    w_in : array_like, shape (..., 3), optional
        Rate of the navigation frame, ENU, rad/s (default the earth rate at ``lat``; add the transport
        rate on a moving base).
    """
    C = np.asarray(C_bn, dtype=float)
    eps = np.einsum("...ij,...j->...i", C, np.asarray(gyro_bias_b, dtype=float))
    nab = np.einsum("...ij,...j->...i", C, np.asarray(accel_bias_b, dtype=float))
    g = earth.gravity(lat, h)
    if f_n is None and w_in is None:  # the closed form
        wn = earth.OMEGA_IE * np.cos(lat)
        return np.stack(
            [-nab[..., 1] / g, nab[..., 0] / g, -eps[..., 0] / wn + np.tan(lat) * nab[..., 0] / g], axis=-1
        )
    f = np.broadcast_to(np.stack([np.zeros_like(g), np.zeros_like(g), g], -1) if f_n is None
                        else np.asarray(f_n, dtype=float), eps.shape)
    w = np.broadcast_to(earth.earth_rate_n(lat) if w_in is None else np.asarray(w_in, dtype=float), eps.shape)
    A = np.zeros(eps.shape + (3,))
    A[..., 0, 1], A[..., 0, 2] = -f[..., 2], f[..., 1]       # dvE' row
    A[..., 1, 0], A[..., 1, 2] = f[..., 2], -f[..., 0]       # dvN' row
    A[..., 2, 1], A[..., 2, 2] = w[..., 2], -w[..., 1]       # phiE' row
    b = -np.stack([nab[..., 0], nab[..., 1], -eps[..., 0]], axis=-1)
    return np.linalg.solve(A, b[..., None])[..., 0]


def _check_histories(func, x, band, target, t=None):
    """``x`` (float, at least one sample on its last axis) checked against ``t``, ``band`` and ``target``: a
    ValueError of one line naming the argument, what was expected and what was found."""
    x = np.asarray(x, dtype=float)
    if t is not None and t.ndim != 1:
        raise ValueError(f"{func} t: expected a 1-D array of times, found shape {t.shape}")
    if x.ndim == 0 or x.shape[-1] == 0:
        raise ValueError(f"{func} x: expected error histories of shape (..., M), M >= 1 samples, found shape "
                         f"{x.shape}")
    if t is not None and x.shape[-1] != t.size:
        raise ValueError(f"{func} x: expected error histories of shape (..., {t.size}), one value per time in t, "
                         f"found shape {x.shape}")
    for name, value in (("band", band), ("target", target)):
        shape = np.shape(value)
        try:
            fits = np.broadcast_shapes(shape, x.shape) == x.shape
        except ValueError:
            fits = False
        if not fits:
            raise ValueError(f"{func} {name}: expected a value broadcastable to x's shape {x.shape}, found shape "
                             f"{shape}")
    return x


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
    band : float or array_like broadcastable to ``x``
        Half-width of the band, same units as ``x``.
    target : float or array_like broadcastable to ``x``
        Where the error should settle (the limit), same units as ``x``.

    Returns
    -------
    ndarray, shape (...)
        Settling time, s: ``t[0]`` if always inside; ``t[-1]`` for a history that ends outside the band
        (not settled: :func:`settled` tells these apart).

    Raises
    ------
    ValueError
        One line naming the argument: ``t`` not 1-D, ``x`` empty or not ending in ``t``'s length, ``band`` or
        ``target`` not broadcastable to ``x``.
    """
    t = np.asarray(t, dtype=float)
    x = _check_histories("settling_time", x, band, target, t)
    outside = np.abs(x - target) > band
    any_out = outside.any(axis=-1)
    last_out = x.shape[-1] - 1 - np.argmax(outside[..., ::-1], axis=-1)
    idx = np.where(any_out, np.minimum(last_out + 1, x.shape[-1] - 1), 0)
    return t[idx]


def settled(x, band, target=0.0):
    """Whether each history ``x`` (..., M) ends inside ``band`` around ``target`` (bool, shape (...)).

    ``band`` and ``target`` as in :func:`settling_time`, broadcastable to ``x``; otherwise, or for an empty
    ``x``, ValueError (one line naming the argument)."""
    x = _check_histories("settled", x, band, target)
    target = np.broadcast_to(np.asarray(target, dtype=float), x.shape)
    band = np.broadcast_to(np.asarray(band, dtype=float), x.shape)
    return np.abs(x[..., -1] - target[..., -1]) <= band[..., -1]


def stats(x):
    """``{"mean", "std", "rms", "max_abs"}`` of the values in ``x`` (floats, same units as x)."""
    x = np.asarray(x, dtype=float).ravel()
    return {
        "mean": float(np.mean(x)),
        "std": float(np.std(x)),
        "rms": float(np.sqrt(np.mean(x**2))),
        "max_abs": float(np.max(np.abs(x))),
    }
