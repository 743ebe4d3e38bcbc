"""Support for the factor-graph aligner (:mod:`baselines.factor_graph`): IMU increments for gtsam,
keyframe bookkeeping and attitude propagation between keyframes (the rows and their tile factors are
:mod:`baselines.graph_rows`, the posterior :mod:`baselines.graph_posterior`).

Frames: navigation ENU, body RFU; angles rad, rates rad/s, velocities m/s.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation.attitude import orthonormalize, rotvec_to_dcm
from fusionbench.simulation.strapdown import coning_sculling

from .graph_compiled import interval_products, interval_rates, interval_starts


def compensated_increments(dtheta, dvel):
    """Coning- and sculling-compensated increments of one recording
    (:func:`fusionbench.simulation.strapdown.coning_sculling` from rest: no sample before the first).

    Parameters
    ----------
    dtheta, dvel : ndarray, shape (M, 3)
        Angle (rad) and velocity (m/s) increments of one recording, body frame.

    Returns
    -------
    phi : ndarray, shape (M, 3)
        Rotation vector of each sample interval, rad, body frame.
    dv : ndarray, shape (M, 3)
        Velocity increment resolved in the body frame at the start of the interval, m/s.
    """
    zero = np.zeros((1, 3))
    phi, dv = coning_sculling(np.asarray(dtheta)[None], np.asarray(dvel)[None], zero, zero)
    return phi[0], dv[0]


def keyframe_counts(samples, per_keyframe):
    """Sample counts at the keyframes: 0, n, 2n, ..., ending at ``samples``.

    The last interval is between 0.5 and 1.5 keyframe intervals long (a shorter remainder is merged
    into the interval before it).

    Parameters
    ----------
    samples : int
        Number of increments M.
    per_keyframe : int
        Increments per keyframe interval.

    Returns
    -------
    ndarray of int, shape (K,)
    """
    c = list(range(0, samples, per_keyframe)) + [samples]
    if len(c) > 2 and c[-1] - c[-2] < per_keyframe / 2:
        del c[-2]
    return np.asarray(c, dtype=int)


def _interval_rotations(phi, counts, u_kf):
    """Body rotations over the keyframe intervals, and vectors carried into each sample's body frame.

    Parameters
    ----------
    phi : ndarray, shape (M, 3)
        Rotation vectors of the samples, rad.
    counts : ndarray of int, shape (K,)
        Keyframe sample counts.
    u_kf : ndarray, shape (K - 1, 3) or None
        A navigation-frame vector held over each interval, resolved in the body frame at the
        interval's start.

    Returns
    -------
    u_b : ndarray, shape (M, 3) or None
        ``u_kf`` resolved in the body frame at the start of each sample (the turn of the
        navigation frame over one interval neglected); None if ``u_kf`` is None.
    dR : ndarray, shape (K - 1, 3, 3)
        Body rotation over each interval (zero bias), C_b(end)^b(start).
    """
    after = interval_products(phi, counts)
    dR = after[counts[1:] - 1]
    if u_kf is None:
        return None, dR
    u_b = np.empty_like(phi)
    interval = np.repeat(np.arange(counts.size - 1), np.diff(counts))
    start = interval_starts(after, counts)[counts[0]:counts[-1]]
    u_b[counts[0]:counts[-1]] = np.einsum("kji,kj->ki", start, u_kf[interval])
    return u_b, dR


def tangent_rates(phi, counts, dt):
    """Gyro rates (M, 3), rad/s, that make gtsam's tangent-space preintegration turn exactly as the samples do.

    gtsam (built with tangent preintegration) advances the rotation of an interval as ``theta <- theta + J_r(theta)^-1
    w dt``, first order in ``w dt``: under a sway its rotation over an interval drifts from the product of the
    samples' rotations (2e-5 rad over 2 s of seed 000's (Zhou 2011, ADRC gyrocompass) Table-1 sway), the same way on
    every interval, and that left the graph's azimuth -4.2 arcmin off at 1-s keyframes and 3.3 deg at 2-s ones on a
    perfect IMU. Each returned rate is ``J_r(theta) (Log(Exp(theta) Exp(phi_i)) - theta) / dt``, with ``theta`` the
    exact rotation vector of the interval so far, so that gtsam's ``theta`` is the exact one after every sample (and its
    velocity and position steps, which use ``Exp(theta)`` at the sample's start, exact too).

    Parameters
    ----------
    phi : ndarray, shape (M, 3)
        Rotation vectors of the samples (body frame RFU), rad.
    counts : ndarray of int, shape (K,)
        Keyframe sample counts (:func:`keyframe_counts`).
    dt : float
        Sample interval, s.
    """
    return interval_rates(phi, counts, dt)


def _propagate(C_known, dR, w_n, T, forward):
    """Keyframe attitudes (K, 3, 3) from the first (``forward``) or the last one, ``C_known``.

    ``C_k = exp(-[w_k x] T_k) C_{k-1} dR_k`` with ``dR`` (K-1, 3, 3) the body rotations, ``w_n``
    (K-1, 3) the turn rate of the navigation frame (rad/s) and ``T`` (K-1,) the lengths (s) of the
    intervals.
    """
    K = dR.shape[0] + 1
    out = np.empty((K, 3, 3))
    E = rotvec_to_dcm(-w_n * T[:, None])
    if forward:
        out[0] = C_known
        for k in range(1, K):
            out[k] = E[k - 1] @ out[k - 1] @ dR[k - 1]
    else:
        out[-1] = C_known
        for k in range(K - 1, 0, -1):
            out[k - 1] = E[k - 1].T @ out[k] @ dR[k - 1].T
    return orthonormalize(out)
