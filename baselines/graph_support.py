"""Support for the factor-graph aligner (:mod:`baselines.factor_graph`): IMU increments for gtsam,
keyframe bookkeeping, attitude propagation between keyframes (the rows and their tile factors are
:mod:`baselines.graph_rows`), the posterior covariance from a QR-eliminated Bayes net
(``gtsam.Marginals`` factors by Cholesky, which fails on these nearly singular graphs), and the
residual statistics of variance-component estimation.

Frames: navigation ENU, body RFU; angles rad, rates rad/s, velocities m/s.
"""

from __future__ import annotations

import numpy as np

import gtsam
from gtsam.symbol_shorthand import B, X

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


_DIMS = {"x": 6, "v": 3, "b": 6}
_KEY_DIMS = {}


def _dim(key):
    """Tangent dimension of a key (Pose3 6, velocity 3, bias 6)."""
    d = _KEY_DIMS.get(key)
    if d is None:
        d = _KEY_DIMS[key] = _DIMS[chr(gtsam.Symbol(key).chr())]
    return d


def _offsets(keys):
    """Start of each key's block in a stacked tangent vector, and the total size, as ints."""
    off = [0]
    for k in keys:
        off.append(off[-1] + _dim(k))
    return off


class Posterior:
    """The Gaussian posterior of a keyframe graph linearised at its solution.

    The graph is eliminated by QR in gtsam's COLAMD order: a Bayes net ``prod p(x_f | parents)`` of
    unit-noise conditionals ``R x_f + S x_P = d + e``. Backwards, each parent set is a clique whose covariances are
    already known, and ``Sigma_fP = -A Sigma_PP``, ``Sigma_ff = R^-1 R^-T + A Sigma_PP A^T`` (``A = R^-1 S``). With
    the biases known the same recursion runs on the graph with a constrained prior on every bias key (zero
    covariance there). Linear in K; ``gtsam.Marginals`` factors by Cholesky, which fails on these nearly singular
    graphs. Covariances are in gtsam's tangent spaces (Pose3: rotation then translation, body frame,
    ``R = R_hat Exp(delta)``). The elimination order changes the cost only (docs/methods/gtsam.md, "Marginals").

    Parameters
    ----------
    graph : gtsam.NonlinearFactorGraph
    values : gtsam.Values
    K : int
        Number of keyframes (keys ``X(k)``, ``V(k)``); not needed by the COLAMD elimination, kept in the signature for
        its callers.
    bias_keys : sequence of int
        The bias keys (held known for the covariances with the biases known).

    Raises
    ------
    RuntimeError
        When gtsam cannot eliminate the graph.
    """

    def __init__(self, graph, values, K, bias_keys):
        self.lin = graph.linearize(values)
        self.bias_keys = list(bias_keys)
        self._cov = self._covariances(self.lin)
        self._cov_known = None  # with the biases known: computed when asked

    @classmethod
    def _covariances(cls, lin):
        """The covariances of every conditional's clique of the linear graph ``lin``: ``{(a, b): block}``."""
        net = lin.eliminateSequential(gtsam.Ordering.ColamdGaussianFactorGraph(lin), gtsam.EliminateQR)
        conds = [net.at(i) for i in range(net.size())]
        # R is upper triangular, 3x3 or 6x6: inverted in one call per size (numpy's inverse costs more in its
        # wrapper than in LAPACK; scipy's solve_triangular costs milliseconds a call when its threaded BLAS
        # competes for the cores)
        Rs = [c.R() for c in conds]
        R_inv = [None] * len(Rs)
        for d in {R.shape[0] for R in Rs}:
            idx = [i for i, R in enumerate(Rs) if R.shape[0] == d]
            for i, inv in zip(idx, np.linalg.inv(np.stack([Rs[i] for i in idx]))):
                R_inv[i] = inv
        cov = {}
        for i in range(len(conds) - 1, -1, -1):
            c = conds[i]
            keys = list(c.keys())
            f, parents = keys[0], keys[1:]
            model = c.get_model()
            # the noise of R x_f + S x_P = d: unit, or the sigmas of a diagonal model left on it (by a
            # constrained factor); then cov(x_f | x_P) = R^-1 diag(sigma^2) R^-T
            Ri = R_inv[i] if model is None else R_inv[i] * model.sigmas()[None, :]
            if parents:
                cls._condition(cov, f, parents, R_inv[i] @ c.S(), Ri)
            else:
                cov[f, f] = Ri @ Ri.T
        return cov

    def _known(self):
        """The covariances with every bias known (a constrained zero-mean prior on each bias key)."""
        if self._cov_known is None:
            lin = self.lin.clone()
            for b in self.bias_keys:
                lin.add(gtsam.JacobianFactor(b, np.eye(6), np.zeros(6), gtsam.noiseModel.Constrained.All(6)))
            self._cov_known = self._covariances(lin)
        return self._cov_known

    @classmethod
    def _condition(cls, cov, f, parents, A, Ri):
        """The covariances of a frontal key ``f`` given its ``parents`` (whose joint covariance ``cov`` holds):
        ``Sigma_ff = Ri Ri^T + A Sigma_PP A^T`` and ``Sigma_fp = -A Sigma_Pp``."""
        off = _offsets(parents)
        cross = -A @ cls._assemble(cov, parents, off)
        cov[f, f] = Ri @ Ri.T - cross @ A.T
        for j, p in enumerate(parents):
            cov[f, p] = cross[:, off[j]:off[j + 1]]

    @staticmethod
    def _assemble(cov, keys, off=None):
        """The joint covariance of ``keys`` from the blocks ``cov`` holds (``off``: :func:`_offsets` of ``keys``).
        Each pair is held once, as ``(a, b)`` or ``(b, a)`` (a frontal key with a parent), the other its transpose."""
        off = _offsets(keys) if off is None else off
        P = np.zeros((off[-1], off[-1]))
        for a, ka in enumerate(keys):
            P[off[a]:off[a + 1], off[a]:off[a + 1]] = cov[ka, ka]
            for b in range(a + 1, len(keys)):
                kb = keys[b]
                blk = cov.get((ka, kb))
                if blk is None:
                    blk = cov.get((kb, ka))
                    if blk is None:  # keys never in one clique
                        continue
                    blk = blk.T
                P[off[a]:off[a + 1], off[b]:off[b + 1]] = blk
                P[off[b]:off[b + 1], off[a]:off[a + 1]] = blk.T
        return P

    def cov(self, keys, bias=True):
        """Joint covariance of ``keys`` (which must lie in one clique: a factor's keys do), with the
        bias priors (``bias=True``) or with the biases known."""
        return self._assemble(self._cov if bias else self._known(), keys)

    def attitude_sigmas(self, C_kf):
        """Marginal misalignment sigmas, rad, ENU, each (K, 3): with the bias priors, and with the biases
        known. The misalignment is ``phi = -C_bn delta`` (delta the rotation part of the Pose3
        tangent), so its covariance is ``C_bn S C_bn^T``."""
        K = C_kf.shape[0]
        full, noise = np.empty((K, 3)), np.empty((K, 3))
        known = self._known()
        for k in range(K):
            C = C_kf[k]
            full[k] = np.sqrt(np.clip(np.diag(C @ self._cov[X(k), X(k)][:3, :3] @ C.T), 0.0, None))
            noise[k] = np.sqrt(np.clip(np.diag(C @ known[X(k), X(k)][:3, :3] @ C.T), 0.0, None))
        return full, noise


def marginal_sigmas(graph, values, C_kf, bias_keys=None):
    """Marginal misalignment sigmas, rad, ENU, each (K, 3): with the bias priors, and with the biases
    known (NaN when the graph cannot be eliminated). ``bias_keys`` default: ``[B(0)]``, one constant
    bias. See :class:`Posterior`."""
    K = C_kf.shape[0]
    bias_keys = [B(0)] if bias_keys is None else bias_keys
    try:
        return Posterior(graph, values, K, bias_keys).attitude_sigmas(C_kf)
    except (RuntimeError, KeyError, ValueError):
        return np.full((K, 3), np.nan), np.full((K, 3), np.nan)


def residual_statistics(post, factor_keys, factor_index):
    """Whitened squared residuals and redundancy numbers of factors, for variance-component estimation.

    For a factor with whitened Jacobian ``A`` and whitened residual ``b`` at the solution (``m`` rows)
    and the posterior covariance ``Sigma`` of its keys, ``E[b^T b] = m - tr(A Sigma A^T)`` when the
    factor's covariance is right: the redundancy number, the share of the factor's rows that the rest
    of the graph checks. A group of factors whose covariance is ``lambda`` times the assumed one has
    ``E[sum b^T b] = lambda sum r``, which is what the adaptive graph solves for.

    Parameters
    ----------
    post : Posterior
        The linearised, eliminated graph (its ``lin`` keeps the factor order of the graph).
    factor_keys : sequence of sequences of int
        The keys of each factor, in the factor's own key order.
    factor_index : sequence of int
        The factors' indices in the graph (negative: skipped, zeros returned).

    Returns
    -------
    e2, red : ndarray, each (len(factor_index),)
        ``b^T b`` and ``m - tr(A Sigma A^T)``.
    """
    n = len(factor_index)
    e2, red = np.zeros(n), np.zeros(n)
    for i, (keys, idx) in enumerate(zip(factor_keys, factor_index)):
        if idx < 0:
            continue
        lf = post.lin.at(int(idx))
        A, b = lf.jacobian()
        lin_keys = list(lf.keys())
        if lin_keys != list(keys):
            raise RuntimeError("factor keys out of order")
        S = post.cov(lin_keys)
        e2[i] = float(b @ b)
        red[i] = A.shape[0] - float(np.einsum("ij,jk,ik->", A, S, A))
    return e2, red
