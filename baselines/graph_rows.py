"""Measurement rows on the factor graph's keyframes (:mod:`baselines.factor_graph`): the record split into tiles (the
samples nearest each keyframe), what the IMU predicts at a row's time from its keyframe (velocity, and position
integrated, a row between two samples reading the partial sample interpolated), the weighted means of a tile's rows
per axis, their scatter, and the tile factor that compares the means with the prediction.

A row valid at ``tau`` lies in sample ``j`` (``(t_end[j-1], t_end[j]]``,
:func:`fusionbench.simulation.aiding_geometry.bracket`) at the fraction ``w`` of it, and belongs to the tile of that
sample. A quantity known at the sample ends as a sum ``S`` (:func:`tile_sums`) of per-sample increments ``x`` from the
keyframe is ``S[j] - (1 - w) x[j]`` at the row (:func:`at_rows`; linear within the sample), and its integral from the
keyframe to the row follows from the same straight lines (:func:`integral_at_rows`).

The tile factor of keyframe ``k`` holds, per ENU axis ``a``, the weighted mean of its rows' equations
``c_t t + c_v,a v + (R (U_a - Mb_a b_a))_a = z_a`` on the pose (attitude ``R = C_bn``, translation ``t``), velocity
``v`` and accelerometer bias ``b_a`` of the keyframe: a velocity row (``c_t = 0``, ``c_v = 1``; ``U`` the velocity
increments since the keyframe in its body frame) or a position row (``c_t = 1``, ``c_v = tau - t_k``; ``U`` their
integral). Each axis has its own weights (a row that does not measure an axis weighs nothing on it); with the same
weights on every axis all three read the same means. The mean keeps the information of the rows about the keyframe's
state and drops their scatter about it (:func:`tile_scatter` measures it for the adaptive graph).

Frames: navigation ENU, body RFU; velocities m/s, positions m, times s.
"""

from __future__ import annotations

import numpy as np

import gtsam

from fusionbench.simulation.strapdown import rodrigues

from .graph_compiled import interval_products, interval_starts


def tiles(t, t_kf):
    """The keyframe nearest to each time (its *tile*): the record split at the midpoints between keyframes.

    Parameters
    ----------
    t : ndarray, shape (M,)
        Times, s.
    t_kf : ndarray, shape (K,)
        Keyframe times, s, increasing.

    Returns
    -------
    ndarray of int, shape (M,)
    """
    return np.searchsorted(0.5 * (t_kf[1:] + t_kf[:-1]), t, side="left")


def tile_increments(phi, dv, counts, tile):
    """Each sample's velocity increment resolved in the body frame of its tile's keyframe.

    Parameters
    ----------
    phi, dv : ndarray, shape (M, 3)
        Rotation vectors (rad) and velocity increments (m/s, body frame at the start of each sample) of the samples
        (:func:`baselines.graph_support.compensated_increments`).
    counts : ndarray of int, shape (K,)
        Keyframe sample counts (:func:`baselines.graph_support.keyframe_counts`).
    tile : ndarray of int, shape (M,)
        The keyframe of each sample (:func:`tiles` of the increment ends).

    Returns
    -------
    u : ndarray, shape (M, 3)
        ``C_{b_k}^{b_i} dv_i``, m/s, with the gyros' rotation from keyframe k to the start of sample i.
    R : ndarray, shape (M, 3, 3)
        ``C_{b_k}^{b_i}``.
    """
    M = phi.shape[0]
    after = interval_products(phi, counts)
    R_start = interval_starts(after, counts)
    interval = np.searchsorted(counts, np.arange(M), side="right") - 1  # sample i in [counts[j], counts[j+1])
    later = tile == interval + 1  # belongs to the keyframe at the end of its interval
    R_start[later] = np.swapaxes(after[counts[1:] - 1][interval[later]], -1, -2) @ R_start[later]
    return np.einsum("mij,mj->mi", R_start, dv), R_start


def tile_sums(x, tile, counts):
    """``x`` summed from each sample's keyframe to the sample: over the samples after the keyframe up to and
    including sample i, or minus those after sample i up to the keyframe's own sample.

    Parameters
    ----------
    x : ndarray, shape (M, ...)
        Per-sample increments (each tile's in its own frame: only a tile's own samples are summed).
    tile : ndarray of int, shape (M,)
    counts : ndarray of int, shape (K,)
        Keyframe sample counts: keyframe k is at the end of sample ``counts[k] - 1`` (k >= 1), keyframe 0 at the
        start of sample 0.

    Returns
    -------
    ndarray, shape (M, ...)
        The value at each sample's end; zero at a keyframe's own sample.
    """
    S = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])  # S[i + 1]: through sample i
    return S[1:] - S[counts][tile]


def _expand(w, ndim):
    return w.reshape(w.shape + (1,) * (ndim - 1))


def at_rows(S, x, j, w):
    """The value at rows' times of ``S`` (M, ...), the :func:`tile_sums` of per-sample increments ``x`` (M, ...):
    ``S[j] - (1 - w) x[j]`` for rows in samples ``j`` (n,) at fractions ``w`` (n,) of them."""
    return S[j] - (1.0 - _expand(w, x.ndim)) * x[j]


def integral_at_rows(S, x, j, w, dt, tile, counts):
    """The integral over time, from each row's keyframe to the row, of what :func:`at_rows` reads (straight
    lines between the sample ends), (n, ...), unit of ``S`` times s; arguments as :func:`at_rows` and
    :func:`tile_sums`, ``dt`` the sample interval, s."""
    q = dt * (S - 0.5 * x)  # the integral over each sample
    Q = tile_sums(q, tile, counts)
    wb = _expand(w, x.ndim)
    return Q[j] - q[j] + dt * (wb * S[j] - (wb - 0.5 * wb**2) * x[j])


def mean_at_rows(x, j, w):
    """Per-sample means ``x`` (M, ...) (a gyro's mean rate over each sample) at rows in samples ``j`` (n,) at
    fractions ``w`` (n,): interpolated linearly between the samples' middles (second order for smooth motion;
    half-way at a sample's end), held beyond the first and last."""
    f = w - 0.5
    lo = np.where(f >= 0, j, j - 1)
    frac = np.where(f >= 0, f, f + 1.0)
    lo_c, hi_c = np.clip(lo, 0, x.shape[0] - 1), np.clip(lo + 1, 0, x.shape[0] - 1)
    frac = _expand(frac, x.ndim)
    return (1.0 - frac) * x[lo_c] + frac * x[hi_c]


def row_rotations(R_start, phi, j, w):
    """``C_{b_k}^{b(tau)}`` (n, 3, 3): the body frame at each row's time in its keyframe's, from the rotation at the
    start of its sample ``R_start`` (M, 3, 3) (:func:`tile_increments`) and the fraction ``w`` of the sample's
    rotation vector ``phi`` (M, 3), rad."""
    return R_start[j] @ rodrigues(w[:, None] * phi[j])


def axis_means(tile, K, W, per_axis=(), shared=()):
    """Weighted means over each tile, one per ENU axis, and their variance per unit row variance.

    Parameters
    ----------
    tile : ndarray of int, shape (n,)
    K : int
        Number of tiles.
    W : ndarray, shape (n, 3)
        Each row's weight on each axis (its inverse variance relative to a unit; 0 where it does not measure the
        axis).
    per_axis : sequence of ndarray, each (n, 3)
        Arrays whose component a is read on axis a (the measurement): mean (K, 3).
    shared : sequence of ndarray, each (n, ...)
        Arrays read whole on every axis (the model's vectors): mean (K, 3, ...) with axis a weighted by ``W[:, a]``.

    Returns
    -------
    var : ndarray, shape (K, 3)
        ``1 / sum W`` per tile and axis (inf where no row weighs).
    means : list of ndarray
        The means of ``per_axis``, then of ``shared`` (zero where no row weighs).
    """
    W = np.asarray(W, dtype=float)
    same = bool(np.all(W == W[:, :1]))  # every axis weighted alike: one mean for all
    cols = [W[:, 0]] if same else [W[:, a] for a in range(3)]
    s0 = np.stack([np.bincount(tile, w, minlength=K) for w in cols], axis=1)
    some = s0 > 0
    var = np.broadcast_to(np.where(some, 1.0 / np.where(some, s0, 1.0), np.inf), (K, 3)).copy()

    def mean(x, i):
        out = np.zeros(K)
        out[some[:, i]] = np.bincount(tile, cols[i] * x, minlength=K)[some[:, i]] / s0[some[:, i], i]
        return out

    means = [np.stack([mean(x[:, a], 0 if same else a) for a in range(3)], axis=1) for x in per_axis]
    for x in shared:
        flat = x.reshape(x.shape[0], -1)
        m = np.stack([np.stack([mean(flat[:, c], i) for c in range(flat.shape[1])], axis=1)
                      for i in range(len(cols))], axis=1)
        means.append(np.broadcast_to(m, (K, 3, flat.shape[1])).reshape((K, 3) + x.shape[1:]).copy())
    return var, means


def tile_scatter(r, tile, t, t_kf, weight=None):
    """Weighted residual sum of squares of ``r`` (n, 3) about a straight line in time over each tile, summed over
    the axes, and its degrees of freedom (``n_a - 2`` per axis with at least three weighing rows): the rows' own
    scatter about what the solution predicts, a slow drift of the prediction (an attitude error) not counted.

    ``tile`` (n,) the rows' tiles, ``t`` (n,) their times, s, ``t_kf`` (K,) the keyframe times; ``weight`` (n,) or
    (n, 3), default 1. Returns ``rss`` and ``dof``, each (K,).
    """
    K = t_kf.size
    W = np.ones((t.size, 3)) if weight is None else np.broadcast_to(
        np.asarray(weight, dtype=float).reshape(t.size, -1), (t.size, 3))
    tau = t - t_kf[tile]
    rss, dof = np.zeros(K), np.zeros(K)
    for a in range(3):
        w = W[:, a]
        n = np.bincount(tile, w > 0, minlength=K)
        s0, s1, s2 = (np.bincount(tile, w * tau**p, minlength=K) for p in range(3))
        y0, y1 = np.bincount(tile, w * r[:, a], minlength=K), np.bincount(tile, w * tau * r[:, a], minlength=K)
        det = s0 * s2 - s1**2
        line = (n >= 3) & (det > 1e-12 * np.maximum(s0 * s2, 1e-300))
        c0, c1 = np.zeros(K), np.zeros(K)
        c0[line] = (s2[line] * y0[line] - s1[line] * y1[line]) / det[line]
        c1[line] = (s0[line] * y1[line] - s1[line] * y0[line]) / det[line]
        res = r[:, a] - c0[tile] - c1[tile] * tau
        rss += np.where(line, np.bincount(tile, w * res**2, minlength=K), 0.0)
        dof += np.where(line, n - 2, 0)
    return rss, dof


def tile_error(d, R, t, v, b_acc):
    """The tile factors' errors (K, 3) ``c_t t + c_v v + (R (U_a - Mb_a b_a))_a - z_a`` (ENU, m/s or m).

    ``d`` the factors' data (``z`` (K, 3), ``U`` (K, 3, 3), ``Mb`` (K, 3, 3, 3) s or s^2, ``c_v`` (K, 3) 1 or s,
    ``position`` bool: ``c_t`` 1 or 0); ``R`` (K, 3, 3) the attitudes ``C_bn``, ``t`` (K, 3) m and ``v`` (K, 3) m/s
    the keyframes' positions and velocities, ``b_acc`` (K, 3) m/s^2 their accelerometer biases."""
    Ub = d["U"] - np.einsum("kaij,kj->kai", d["Mb"], b_acc)
    e = d["c_v"] * v + np.einsum("kaj,kaj->ka", R, Ub) - d["z"]
    return e + t if d["position"] else e


def tile_factors(d, sigma, keys, states, values):
    """The tile factors of the keyframes, each linearised at its keyframe's current values (a
    ``gtsam.LinearContainerFactor``: in C++; the caller relinearises when the attitude moved).

    The Jacobians, in gtsam's tangents (Pose3: rotation then translation in the body frame, ``R = R_hat Exp(delta)``,
    ``t = t_hat + R delta_t``; bias: accelerometer then gyro), are per axis a: ``(U_a - Mb_a b_a) x r_a`` on the
    rotation (``r_a`` row a of R), ``c_t r_a`` on the translation, ``c_v,a`` on ``v_a`` and ``-r_a Mb_a`` on the
    accelerometer bias. The error is quadratic in the attitude's move from there (``|U| delta^2 / 2``).

    Parameters
    ----------
    d : dict
        The factors' data (:func:`tile_error`).
    sigma : ndarray, shape (K, 3)
        Standard deviation of each mean, m/s or m; inf: no factor row on that axis (no factor without any).
    keys : sequence of (int, int, int)
        ``X(k)``, ``V(k)``, ``B(j)`` of each keyframe.
    states : (ndarray, ndarray, ndarray, ndarray)
        Linearisation point: the keyframes' attitudes ``C_bn`` (K, 3, 3), positions (K, 3) m, velocities (K, 3) m/s
        and accelerometer biases (K, 3) m/s^2 (:func:`baselines.graph_aiding.keyframe_states` of ``values``).
    values : gtsam.Values
        The same point, every key in one container (the solver's values): each factor copies its own keys from it.

    Returns
    -------
    list of (int, gtsam.LinearContainerFactor)
        The keyframe index and its factor, for the keyframes with one.
    """
    R, t, v, b_acc = states
    K = R.shape[0]
    Ub = d["U"] - np.einsum("kaij,kj->kai", d["Mb"], b_acc)
    e0 = tile_error(d, R, t, v, b_acc)
    H_x = np.zeros((K, 3, 6))
    H_x[..., :3] = np.cross(Ub, R)
    if d["position"]:
        H_x[..., 3:] = R
    H_v = np.zeros((K, 3, 3))
    H_v[:, np.arange(3), np.arange(3)] = d["c_v"]
    H_b = np.zeros((K, 3, 6))
    H_b[..., :3] = -np.einsum("kaj,kajl->kal", R, d["Mb"])
    rows = np.isfinite(sigma)
    out = []
    for k in np.flatnonzero(rows.any(axis=1)):
        a = rows[k]
        key_x, key_v, key_b = keys[k]
        noise = gtsam.noiseModel.Diagonal.Sigmas(sigma[k, a])
        jf = gtsam.JacobianFactor(key_x, H_x[k, a], key_v, H_v[k, a], key_b, H_b[k, a], -e0[k, a], noise)
        out.append((k, gtsam.LinearContainerFactor(jf, values)))
    return out


def interval_velocity_cov(pims):
    """The velocity block (K - 1, 3, 3) (m/s)^2 of each interval's preintegrated covariance, in the body frame of the
    interval's start; read once from a :class:`Intervals` and kept on it (the graph and the Huber weights read it
    at every pass)."""
    cov = getattr(pims, "velocity_cov", None)
    if cov is None:
        cov = np.stack([p.preintMeasCov()[6:9, 6:9] for p in pims])
        if isinstance(pims, Intervals):
            pims.velocity_cov = cov
    return cov


class Intervals(list):
    """The preintegrated intervals of a recording (``gtsam.PreintegratedImuMeasurements``, a list) with what is
    read from them kept beside (:func:`interval_velocity_cov`)."""

    velocity_cov = None


def tile_imu_variance(pims, R, scale=None):
    """Variance (K, 3) (m/s)^2, ENU, that the IMU's own noise leaves in a tile's velocity prediction: the velocity
    block of the preintegrated covariance of the intervals on either side of keyframe k (their mean; one at the ends),
    turned into ENU with the keyframe's attitude.

    A tile's rows are compared with ``V(k) + R(k) U`` (:func:`tile_error`), and ``U`` carries the accelerometers'
    white noise and the gyros' (through the attitude within the tile) that the ImuFactors of the same samples hold
    too. An interval's variance bounds the part inside a tile (half an interval on each side) and covers its
    correlation with the ImuFactor, which two factors modelled as independent do not. Without it an exact reference
    (rows at 1 mm/s, 50 to a tile) made each tile 3 to 4 times more certain than the IMU allows, and with a tactical
    IMU (50 ug/sqrt(Hz)) the graph drifted 10 to 34 deg along the heading it cannot see (docs/open-claims.md).

    Parameters
    ----------
    pims : sequence of gtsam.PreintegratedImuMeasurements
        The K - 1 intervals.
    R : ndarray, shape (K, 3, 3)
        The K keyframes' attitudes ``C_bn``.
    scale : ndarray, shape (K - 1,), optional
        A factor on each interval's covariance (the adaptive graph's).
    """
    K = R.shape[0]
    cov = interval_velocity_cov(pims)  # (K-1, 3, 3): body frame of the interval's start
    if scale is not None:
        cov = cov * np.asarray(scale, dtype=float)[:, None, None]
    enu = R[:-1] @ cov @ np.swapaxes(R[:-1], -1, -2)
    d = np.diagonal(enu, axis1=1, axis2=2)
    out = np.empty((K, 3))
    out[0], out[-1] = d[0], d[-1]
    out[1:-1] = 0.5 * (d[:-1] + d[1:])
    return out
