"""The factor graph's per-sample rotation loops, compiled (:mod:`baselines.factor_graph`).

Two numba calls over a record: :func:`interval_products`, the body rotation accumulated from the start of each
keyframe interval to the end of each sample (from which :mod:`baselines.graph_support` and :mod:`baselines.graph_rows`
read the interval rotations and the tiles' increments with whole-array NumPy), and :func:`interval_rates`, the gyro
rates given to gtsam's preintegration. Their NumPy oracle, the loops they replaced: ``tests/oracles/graph_rotations.py``.

Frames: body RFU; a rotation ``C_{b(t)}^{b(t0)}`` carries a vector from the body frame at t into the body frame at
the interval's start ``t0``.
"""

from __future__ import annotations

import numba
import numpy as np

from fusionbench.simulation.strapdown_compiled import _rodrigues3


@numba.njit(cache=True)
def _products(phi, counts, out):
    E = np.empty((3, 3))
    C = np.empty((3, 3))
    for j in range(counts.shape[0] - 1):
        C[:] = 0.0
        C[0, 0] = C[1, 1] = C[2, 2] = 1.0
        for k in range(counts[j], counts[j + 1]):
            _rodrigues3(phi[k, 0], phi[k, 1], phi[k, 2], E)
            for i in range(3):
                for m in range(3):
                    out[k, i, m] = C[i, 0] * E[0, m] + C[i, 1] * E[1, m] + C[i, 2] * E[2, m]
            C[:] = out[k]


@numba.njit(cache=True)
def _log(C, out):
    """The rotation vector of the rotation matrix ``C``, rad, into ``out`` (3,): through the unit quaternion,
    taken from the largest of its four squares (Shepperd), then ``2 atan2(|q_v|, q_w) q_v / |q_v|``."""
    tr = C[0, 0] + C[1, 1] + C[2, 2]
    if tr >= C[0, 0] and tr >= C[1, 1] and tr >= C[2, 2]:
        w = 0.5 * np.sqrt(1.0 + tr)
        x, y, z = (C[2, 1] - C[1, 2]) / (4 * w), (C[0, 2] - C[2, 0]) / (4 * w), (C[1, 0] - C[0, 1]) / (4 * w)
    elif C[0, 0] >= C[1, 1] and C[0, 0] >= C[2, 2]:
        x = 0.5 * np.sqrt(1.0 + 2 * C[0, 0] - tr)
        w, y, z = (C[2, 1] - C[1, 2]) / (4 * x), (C[1, 0] + C[0, 1]) / (4 * x), (C[0, 2] + C[2, 0]) / (4 * x)
    elif C[1, 1] >= C[2, 2]:
        y = 0.5 * np.sqrt(1.0 + 2 * C[1, 1] - tr)
        w, x, z = (C[0, 2] - C[2, 0]) / (4 * y), (C[1, 0] + C[0, 1]) / (4 * y), (C[2, 1] + C[1, 2]) / (4 * y)
    else:
        z = 0.5 * np.sqrt(1.0 + 2 * C[2, 2] - tr)
        w, x, y = (C[1, 0] - C[0, 1]) / (4 * z), (C[0, 2] + C[2, 0]) / (4 * z), (C[2, 1] + C[1, 2]) / (4 * z)
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = np.sqrt(x * x + y * y + z * z)
    if s < 1e-12:  # 2 atan2(s, w) / s to second order in s
        f = 2.0 / w * (1.0 - s * s / (3.0 * w * w))
    else:
        f = 2.0 * np.arctan2(s, w) / s
    out[0], out[1], out[2] = f * x, f * y, f * z


@numba.njit(cache=True)
def _rates(phi, counts, dt, rates):
    E = np.empty((3, 3))
    C = np.empty((3, 3))
    T = np.empty((3, 3))
    new = np.empty(3)
    th = np.empty(3)
    for j in range(counts.shape[0] - 1):
        C[:] = 0.0
        C[0, 0] = C[1, 1] = C[2, 2] = 1.0
        th[:] = 0.0
        for k in range(counts[j], counts[j + 1]):
            _rodrigues3(phi[k, 0], phi[k, 1], phi[k, 2], E)
            for i in range(3):
                for m in range(3):
                    T[i, m] = C[i, 0] * E[0, m] + C[i, 1] * E[1, m] + C[i, 2] * E[2, m]
            C[:] = T
            _log(C, new)
            d0, d1, d2 = new[0] - th[0], new[1] - th[1], new[2] - th[2]
            a2 = th[0] * th[0] + th[1] * th[1] + th[2] * th[2]
            a = np.sqrt(a2)
            if a < 1e-8:  # J_r(theta) = I
                rates[k, 0], rates[k, 1], rates[k, 2] = d0 / dt, d1 / dt, d2 / dt
            else:  # J_r(theta) d = d - (1 - cos a) / a^2 theta x d + (a - sin a) / a^3 theta x (theta x d)
                b, c = (1.0 - np.cos(a)) / a2, (a - np.sin(a)) / (a2 * a)
                x0, x1, x2 = th[1] * d2 - th[2] * d1, th[2] * d0 - th[0] * d2, th[0] * d1 - th[1] * d0
                y0, y1, y2 = th[1] * x2 - th[2] * x1, th[2] * x0 - th[0] * x2, th[0] * x1 - th[1] * x0
                rates[k, 0] = (d0 - b * x0 + c * y0) / dt
                rates[k, 1] = (d1 - b * x1 + c * y1) / dt
                rates[k, 2] = (d2 - b * x2 + c * y2) / dt
            th[:] = new


def interval_rates(phi, counts, dt):
    """The gyro rates, rad/s (M, 3), whose first-order tangent-space integration (gtsam's preintegration:
    ``theta <- theta + J_r(theta)^-1 w dt`` from ``theta = 0`` at each interval's start) turns exactly as the samples
    do: ``J_r(theta) (Log(Exp(theta) Exp(phi_i)) - theta) / dt`` with ``theta`` the rotation vector of the
    interval's product up to sample i (:func:`baselines.graph_support.tangent_rates`, which documents why).

    Parameters
    ----------
    phi : ndarray, shape (M, 3)
        Rotation vectors of the samples (body frame RFU), rad.
    counts : ndarray of int, shape (K,)
        Keyframe sample counts, increasing.
    dt : float
        Sample interval, s.

    Returns
    -------
    ndarray, shape (M, 3)
        ``phi / dt`` for samples outside ``[counts[0], counts[-1])``. An interval that turns by more than pi
        wraps the logarithm, as the NumPy loops did (a keyframe interval of 1 s would have to turn at 180 deg/s);
        the aligner refuses such a record before it gets here.
    """
    phi = np.ascontiguousarray(phi, dtype=float)
    rates = phi / dt
    if counts.size > 1:
        _rates(phi, np.ascontiguousarray(counts, dtype=np.int64), float(dt), rates)
    return rates


def interval_products(phi, counts):
    """The body rotation from the start of each sample's keyframe interval to the end of the sample.

    Parameters
    ----------
    phi : ndarray, shape (M, 3)
        Rotation vectors of the samples (body frame RFU), rad.
    counts : ndarray of int, shape (K,)
        Keyframe sample counts, increasing (:func:`baselines.graph_support.keyframe_counts`; a prefix's may end
        before M).

    Returns
    -------
    ndarray, shape (M, 3, 3)
        ``C_{b(end of sample i)}^{b(start of its interval)}``: the product of the rotations ``Exp(phi)`` of the
        interval's samples up to and including i; the identity for samples outside ``[counts[0], counts[-1])``.
    """
    phi = np.ascontiguousarray(phi, dtype=float)
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    out = np.empty((phi.shape[0], 3, 3))
    out[:] = np.eye(3)
    if counts.size > 1:
        _products(phi, counts, out)
    return out


def interval_starts(after, counts):
    """The rotation from each sample's interval start to the start of the sample, ``(M, 3, 3)``: the
    :func:`interval_products` ``after`` of the sample before, the identity at an interval's first sample."""
    start = np.empty_like(after)
    start[0] = np.eye(3)
    start[1:] = after[:-1]
    start[counts[:-1]] = np.eye(3)
    return start
