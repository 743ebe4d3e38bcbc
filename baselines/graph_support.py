"""Support for the factor-graph aligner (:mod:`baselines.factor_graph`): IMU increments for gtsam,
keyframe bookkeeping, attitude propagation between keyframes, and the marginal covariance of the
misalignment from a QR-eliminated Bayes net (``gtsam.Marginals`` factors by Cholesky, which fails on
these nearly singular graphs).

Frames: navigation ENU, body RFU; angles rad, rates rad/s, velocities m/s.
"""

from __future__ import annotations

import numpy as np

import gtsam
from gtsam.symbol_shorthand import B, V, X

from fusionbench.attitude import orthonormalize, rotvec_to_dcm
from fusionbench.strapdown import rodrigues


def compensated_increments(dtheta, dvel):
    """Coning- and sculling-compensated increments (the two-sample form of :mod:`fusionbench.strapdown`).

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
    th_prev = np.vstack([np.zeros((1, 3)), dtheta[:-1]])
    dv_prev = np.vstack([np.zeros((1, 3)), dvel[:-1]])
    phi = dtheta + np.cross(th_prev, dtheta) / 12.0
    dv = dvel + 0.5 * np.cross(dtheta, dvel) + (np.cross(th_prev, dvel) + np.cross(dv_prev, dtheta)) / 12.0
    return phi, dv


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
    starts, lengths = counts[:-1], np.diff(counts)
    Rcur = np.broadcast_to(np.eye(3), (starts.size, 3, 3)).copy()
    u_b = None if u_kf is None else np.empty_like(phi)
    for s in range(int(lengths.max())):
        sel = lengths > s
        idx = starts[sel] + s
        if u_b is not None:
            u_b[idx] = np.einsum("kji,kj->ki", Rcur[sel], u_kf[sel])
        Rcur[sel] = Rcur[sel] @ rodrigues(phi[idx])
    return u_b, Rcur


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


def _window_means(x, centres, half):
    """Mean of ``x`` (M, 3) over windows ``centres +- half`` samples, shrunk symmetrically at the ends."""
    M = x.shape[0]
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    h = np.minimum(half, np.minimum(centres, M - 1 - centres))
    return (cs[centres + h + 1] - cs[centres - h]) / (2 * h + 1)[:, None]


def marginal_sigmas(graph, values, C_kf):
    """Marginal misalignment sigmas, rad, ENU, each (K, 3): with the bias prior, and with the bias known.

    The graph is linearised at the solution and eliminated by QR in the order
    ``X(0), V(0), X(1), ..., V(K-1), B(0)``: a Bayes net ``p(B) prod p(x_f | parents)`` of
    unit-noise conditionals ``R x_f + S x_P = d + e``. Backwards from ``B(0)``, with the bias
    known, ``Sigma_fP = -A Sigma_PP`` and ``Sigma_ff = R^-1 R^-T + A Sigma_PP A^T``
    (``A = R^-1 S``; each parent set is a clique whose covariances are already known), and the
    sensitivity to the bias is ``M_f = -A M_P``; with the bias prior,
    ``Sigma_ff + M_f Sigma_BB M_f^T``. gtsam's Pose3 tangent is [rotation, translation] in the
    body frame with ``R = R_hat Exp(delta)``; the misalignment is ``phi = -C_bn delta``, so its
    covariance is ``C_bn S C_bn^T`` with S the rotation block.
    """
    K = C_kf.shape[0]
    full, noise = np.full((K, 3), np.nan), np.full((K, 3), np.nan)
    dims = {"x": 6, "v": 3, "b": 6}
    try:
        lin = graph.linearize(values)
        order = gtsam.Ordering()
        for k in range(K):
            order.push_back(X(k))
            order.push_back(V(k))
        order.push_back(B(0))
        net = lin.eliminateSequential(order, gtsam.EliminateQR)
        cov, sens = {}, {}
        for i in range(net.size() - 1, -1, -1):
            c = net.at(i)
            model = c.get_model()
            if model is not None and not np.allclose(model.sigmas(), 1.0):
                raise RuntimeError("non-unit conditional")
            keys = list(c.keys())
            f, parents = keys[0], keys[1:]
            # upper triangular, 3x3 or 6x6: scipy's solve_triangular costs milliseconds per call when its
            # threaded BLAS competes for the cores (19 s per recording measured), numpy's inverse 0.03 ms
            Ri = np.linalg.inv(c.R())
            if not parents:  # the bias
                cov[f, f], sens[f], S_bb = np.zeros((6, 6)), np.eye(6), Ri @ Ri.T
                continue
            sizes = [dims[chr(gtsam.Symbol(p).chr())] for p in parents]
            off = np.cumsum([0] + sizes)
            P = np.empty((off[-1], off[-1]))
            for a, pa in enumerate(parents):
                for b, pb in enumerate(parents):
                    P[off[a]:off[a + 1], off[b]:off[b + 1]] = cov[pa, pb] if (pa, pb) in cov else cov[pb, pa].T
            A = Ri @ c.S()
            cross = -A @ P
            cov[f, f] = Ri @ Ri.T - cross @ A.T
            for j, p in enumerate(parents):
                cov[f, p] = cross[:, off[j]:off[j + 1]]
            sens[f] = -A @ np.vstack([sens[p] for p in parents])
        for k in range(K):
            C = C_kf[k]
            S_noise = cov[X(k), X(k)][:3, :3]
            M = sens[X(k)][:3]
            noise[k] = np.sqrt(np.clip(np.diag(C @ S_noise @ C.T), 0.0, None))
            full[k] = np.sqrt(np.clip(np.diag(C @ (S_noise + M @ S_bb @ M.T) @ C.T), 0.0, None))
    except (RuntimeError, KeyError, ValueError):
        pass
    return full, noise
