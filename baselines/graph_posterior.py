"""The posterior of a factor graph linearised at its solution (:mod:`baselines.factor_graph`): covariances from a
QR-eliminated Bayes net (``gtsam.Marginals`` factors by Cholesky, which fails on these nearly singular graphs), the
marginal attitude sigmas, and the residual statistics of variance-component estimation (:mod:`baselines.graph_adaptive`).

Covariances are in gtsam's tangent spaces (Pose3: rotation then translation, body frame, ``R = R_hat Exp(delta)``);
sigmas are rad, ENU.
"""

from __future__ import annotations

import numpy as np

import gtsam
from gtsam.symbol_shorthand import B, X

from .posterior_compiled import covariances, joint_covariance, quad_traces, structure


class _Covariances:
    """The covariances of every clique of a Bayes net: the net's structure, the positions of its keys and the flat
    blocks of :func:`baselines.posterior_compiled.covariances`."""

    def __init__(self, lin):
        net = lin.eliminateSequential(gtsam.Ordering.ColamdGaussianFactorGraph(lin), gtsam.EliminateQR)
        conds = [net.at(i) for i in range(net.size())]
        keys = [list(c.keys()) for c in conds]
        self.pos = {k[0]: i for i, k in enumerate(keys)}
        Rs = [c.R() for c in conds]
        # R is upper triangular, 3x3 or 6x6: inverted in one call per size (numpy's inverse costs more in its
        # wrapper than in LAPACK; scipy's solve_triangular costs milliseconds a call when its threaded BLAS
        # competes for the cores)
        R_inv = [None] * len(Rs)
        for d in {R.shape[0] for R in Rs}:
            idx = [i for i, R in enumerate(Rs) if R.shape[0] == d]
            for i, inv in zip(idx, np.linalg.inv(np.stack([Rs[i] for i in idx]))):
                R_inv[i] = inv
        # the noise of R x_f + S x_P = d: unit, or the sigmas of a diagonal model left on it (by a constrained factor)
        models = [c.get_model() for c in conds]
        sigmas = np.concatenate([np.ones(R.shape[0]) if m is None else m.sigmas() for R, m in zip(Rs, models)])
        self.net = structure([R.shape[0] for R in Rs], [[self.pos[p] for p in k[1:]] for k in keys])
        self.cov = covariances(self.net, np.concatenate([R.ravel() for R in R_inv]), sigmas,
                               np.concatenate([c.S().ravel() for c in conds]))

    def joint(self, keys):
        """The joint covariance of ``keys`` (which share a clique)."""
        return joint_covariance(self.net, self.cov, [self.pos[k] for k in keys])

    def marginals(self, keys):
        """The marginal covariance of each key, all of one dimension ``d``: (len(keys), d, d)."""
        pos = np.array([self.pos[k] for k in keys], dtype=np.int64)
        d = int(self.net[0][pos[0]])
        if np.any(self.net[0][pos] != d):
            raise ValueError("marginals: keys of different dimensions")
        start = self.net[5][pos]
        return self.cov[0][start[:, None] + np.arange(d * d)].reshape(-1, d, d)


class Posterior:
    """The Gaussian posterior of a keyframe graph linearised at its solution.

    The graph is eliminated by QR in gtsam's COLAMD order: a Bayes net ``prod p(x_f | parents)`` of
    unit-noise conditionals ``R x_f + S x_P = d + e``. Backwards, each parent set is a clique whose covariances are
    already known, and ``Sigma_fP = -A Sigma_PP``, ``Sigma_ff = R^-1 R^-T + A Sigma_PP A^T`` (``A = R^-1 S``;
    compiled, :mod:`baselines.posterior_compiled`). With the biases known the same recursion runs on the graph with a
    constrained prior on every bias key (zero covariance there). Linear in K; ``gtsam.Marginals`` factors by
    Cholesky, which fails on these nearly singular graphs. Covariances are in gtsam's tangent spaces (Pose3: rotation
    then translation, body frame, ``R = R_hat Exp(delta)``). The elimination order changes the cost only
    (docs/methods/gtsam.md, "Marginals").

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
        self._cov = _Covariances(self.lin)
        self._cov_known = None  # with the biases known: computed when asked

    def _known(self):
        """The covariances with every bias known (a constrained zero-mean prior on each bias key)."""
        if self._cov_known is None:
            lin = self.lin.clone()
            for b in self.bias_keys:
                lin.add(gtsam.JacobianFactor(b, np.eye(6), np.zeros(6), gtsam.noiseModel.Constrained.All(6)))
            self._cov_known = _Covariances(lin)
        return self._cov_known

    def cov(self, keys, bias=True):
        """Joint covariance of ``keys`` (which must lie in one clique: a factor's keys do), with the
        bias priors (``bias=True``) or with the biases known."""
        return (self._cov if bias else self._known()).joint(keys)

    def attitude_sigmas(self, C_kf):
        """Marginal misalignment sigmas, rad, ENU, each (K, 3): with the bias priors, and with the biases
        known. The misalignment is ``phi = -C_bn delta`` (delta the rotation part of the Pose3
        tangent), so its covariance is ``C_bn S C_bn^T``."""
        keys = [X(k) for k in range(C_kf.shape[0])]

        def sigmas(cov):
            S = cov.marginals(keys)[:, :3, :3]
            return np.sqrt(np.clip(np.einsum("kij,kjl,kil->ki", C_kf, S, C_kf), 0.0, None))

        return sigmas(self._cov), sigmas(self._known())

    def traces(self, jacobians, keys):
        """``tr(A Sigma A^T)`` of factors with whitened Jacobians ``A`` (each rows x the dimensions of its keys) on the
        ``keys`` (one sequence per factor, in its columns' order) and the joint covariance ``Sigma`` of those keys
        (with the bias priors)."""
        pos = self._cov.pos
        fac_ptr = np.r_[0, np.cumsum([len(k) for k in keys])]
        J_off = np.r_[0, np.cumsum([A.size for A in jacobians])]
        return quad_traces(self._cov.net, self._cov.cov, fac_ptr, [pos[k] for ks in keys for k in ks],
                           np.concatenate([A.ravel() for A in jacobians]) if jacobians else np.zeros(0), J_off[:-1],
                           [A.shape[0] for A in jacobians])


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
    sel = [i for i, idx in enumerate(factor_index) if idx >= 0]
    jacobians, keys = [], []
    for i in sel:
        lf = post.lin.at(int(factor_index[i]))
        A, b = lf.jacobian()
        keys.append(list(lf.keys()))
        if keys[-1] != list(factor_keys[i]):
            raise RuntimeError("factor keys out of order")
        jacobians.append(A)
        e2[i] = float(b @ b)
    red[sel] = np.array([A.shape[0] for A in jacobians], dtype=float) - post.traces(jacobians, keys)
    return e2, red
