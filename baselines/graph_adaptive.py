"""Noise-adaptive factor-graph fine alignment (method ``gtsam-adaptive``): the graph of
:class:`baselines.factor_graph.FactorGraphAligner`, with the reference's and the IMU's noise levels estimated per
window by variance-component estimation and the graph solved again with them. Frames and units as there; the design
and what was measured: ``docs/methods/gtsam.md`` ("gtsam-adaptive").
"""

from __future__ import annotations

import numpy as np

from gtsam.symbol_shorthand import B, V, X

from .factor_graph import FactorGraphAligner
from .graph_aiding import keyframe_states, row_scatter
from .graph_posterior import Posterior, residual_statistics

__all__ = ["AdaptiveFactorGraphAligner"]


class AdaptiveFactorGraphAligner(FactorGraphAligner):
    """Noise-adaptive factor-graph fine alignment (method ``gtsam-adaptive``).

    The graph of :class:`FactorGraphAligner`, whose reference-noise variance and IMU noise level are
    estimated per time window from the residuals of the solution, and the graph solved again with
    them (iterated variance-component estimation, docs/methods/gtsam.md). The record is cut into windows
    of ``adapt_window_s``; in each, variance factors (covariance multipliers): ``lambda_v`` of
    the velocity rows, ``lambda_p`` of the position rows and ``lambda_i`` of the preintegrated IMU noise
    (gyro and accelerometer together). From a solution, for each group, ``lambda = (nu + sum(lambda_old b^T b)) / (nu +
    sum(r))`` over the window, with the whitened residuals ``b`` and redundancy numbers ``r`` of
    its factors (:func:`baselines.graph_posterior.residual_statistics`) and, for the rows, their
    scatter about the velocity or position predicted at their times (``n - 2`` degrees of freedom per
    tile and axis). A window with less than ``adapt_min_dof`` of redundancy pools its
    neighbours, up to ``adapt_smooth`` either side; ``nu = adapt_prior_dof`` pseudo-degrees of
    freedom at the nominal model (``lambda = 1``) keep a window that sees little near it. The
    rows are then weighted ``1 / lambda_v`` or ``1 / lambda_p`` in their tile means, each ImuFactor's
    covariance is multiplied by ``lambda_i``, and the graph is solved again from the previous
    solution, until no factor changes by more than ``adapt_tol`` (relative) or after
    ``adapt_iterations`` rounds.

    Parameters
    ----------
    adapt_window_s : float
        Window length, s (default 10 s).
    adapt_iterations : int
        At most this many re-solutions (default 6).
    adapt_tol : float
        Stop when every factor changed by less than this, relative (default 0.05).
    adapt_smooth : int
        At most this many neighbouring windows pooled on each side (default 5).
    adapt_min_dof : float
        Redundancy a window's estimate gathers before it stops pooling neighbours (default 10).
    adapt_prior_dof : float
        Pseudo-degrees of freedom of the nominal model in each estimate (default 10: on a stationary
        base, 2 left the heading 10 % worse than the fixed graph's in nominal windows, static-r-jump,
        while a x100 IMU jump still gets a factor of 25 to 100, within 5 % of the best weighting).
    adapt_bounds : (float, float)
        Bounds of the variance factors (default 0.01 and 1e4).
    **kw
        As for :class:`FactorGraphAligner`.

    ``extra`` adds ``reference_variance_scale``, ``position_variance_scale`` and ``imu_variance_scale`` (R,
    W), the final variance factors of the W windows (square roots: the noise sigma relative to the rows' (or
    ``vref_sigma``, ``aiding_position_sigma``) and to the IMU model; 1 without such rows), ``adapt_window_t``
    (W,) the windows' centres, s, and ``adapt_rounds`` (R,).
    """

    name = "gtsam-adaptive"
    description = ("noise-adaptive factor-graph fine alignment (gtsam; reference and IMU noise levels per window by "
                   "variance-component estimation)")
    # claims as gtsam; with a tactical IMU on a fixed base 0.80-1.42 (1.59 at 60 N, static, while the tiles' share of
    # the IMU noise shrank with the IMU's variance factor: graph_build keeps it at the nominal one at least)

    def __init__(self, adapt_window_s=10.0, adapt_iterations=6, adapt_tol=0.05, adapt_smooth=5, adapt_min_dof=10.0,
                 adapt_prior_dof=10.0, adapt_bounds=(1e-2, 1e4), imu="navigation", vref_sigma=0.01, **kw):
        super().__init__(imu=imu, vref_sigma=vref_sigma, **kw)
        self.adapt_min_dof = float(adapt_min_dof)
        self.adapt_window_s = self._positive("adapt_window_s", adapt_window_s)
        self.adapt_tol = self._positive("adapt_tol", adapt_tol)
        for key, val in (("adapt_iterations", adapt_iterations), ("adapt_smooth", adapt_smooth + 1)):
            if int(val) != val or val < 1:
                raise ValueError(f"{key}: expected a {'non-negative' if key == 'adapt_smooth' else 'positive'} "
                                 f"integer, found {val}")
        self.adapt_iterations, self.adapt_smooth = int(adapt_iterations), int(adapt_smooth)
        if not (np.isfinite(adapt_prior_dof) and adapt_prior_dof >= 0):
            raise ValueError(f"adapt_prior_dof: expected a non-negative number, found {adapt_prior_dof}")
        self.adapt_prior_dof = float(adapt_prior_dof)
        lo, hi = (float(x) for x in adapt_bounds)
        if not 0 < lo <= 1 <= hi < np.inf:
            raise ValueError(f"adapt_bounds: expected 0 < low <= 1 <= high, found {adapt_bounds}")
        self.adapt_bounds = (lo, hi)

    def _update(self, lam, e2, red, window, W):
        """New variance factors (W,) from a group's whitened squares and redundancies per factor.

        Each window pools its neighbours, out to ``adapt_smooth`` windows either side, only as far as
        needed to gather ``adapt_min_dof`` degrees of freedom (redundancy): a window rich in redundancy
        keeps a sharp estimate (a noise jump keeps its edges), a poor one borrows from its neighbours.
        """
        E = np.bincount(window, e2, W) * lam
        Rn = np.bincount(window, red, W)
        cE, cR = np.r_[0.0, np.cumsum(E)], np.r_[0.0, np.cumsum(Rn)]
        idx = np.arange(W)
        Es, Rs = E.copy(), Rn.copy()
        for rho in range(1, self.adapt_smooth + 1):
            short = Rs < self.adapt_min_dof
            if not short.any():
                break
            lo, hi = np.maximum(idx - rho, 0), np.minimum(idx + rho + 1, W)
            Es[short], Rs[short] = (cE[hi] - cE[lo])[short], (cR[hi] - cR[lo])[short]
        nu = self.adapt_prior_dof
        return np.clip((nu + Es) / np.maximum(nu + Rs, 1e-12), *self.adapt_bounds)

    def _refine(self, problem, sol):
        t_kf, counts, seg = problem["t_kf"], problem["counts"], problem["seg"]
        K = counts.size
        W = max(1, int(round((t_kf[-1] - t_kf[0]) / self.adapt_window_s)))

        def window(t):
            return np.minimum(((t - t_kf[0]) / self.adapt_window_s).astype(int), W - 1)

        w_kf, w_int = window(t_kf), window(0.5 * (t_kf[1:] + t_kf[:-1]))
        bias_keys = [B(j) for j in range(int(seg.max()) + 1)]
        imu_keys = [[X(k - 1), V(k - 1), X(k), V(k), B(seg[k - 1])] for k in range(1, K)]
        row_keys = [[X(k), V(k), B(seg[min(k, K - 2)])] for k in range(K)]
        # the groups of rows: their factors' indices in a solution, their unit sigma and their rows
        groups = {g: spec for g, spec in (("v", (7, self.vref_sigma, "vel")), ("p", (10, self.aiding_position_sigma,
                                                                                      "pos"))) if problem[spec[2]]}
        lam = {g: np.ones(W) for g in ("i", "v", "p")}
        rounds = 0
        for rounds in range(1, self.adapt_iterations + 1):
            graph, values, C_kf = sol[:3]
            try:
                post = Posterior(graph, values, K, bias_keys)
            except (RuntimeError, KeyError, ValueError):
                break
            e_i, r_i = residual_statistics(post, imu_keys, sol[6])
            new = {"i": self._update(lam["i"], e_i, r_i, w_int, W)}
            b_acc = keyframe_states(values, K, seg)[3]
            for g, (at, unit, _) in groups.items():
                e, red = residual_statistics(post, row_keys, sol[at])
                rss, dof = row_scatter(problem, sol[9], g, C_kf, b_acc)
                new[g] = self._update(lam[g], e + rss / unit**2, red + dof, w_kf, W)
            change = max(np.abs(np.log(new[g] / lam[g])).max() for g in new)
            lam.update(new)
            problem = {**problem, **{rows: {**problem[rows], "scale": 1.0 / lam[g][window(problem[rows]["t"])]}
                                     for g, (_, _, rows) in groups.items()}}
            spent = sol[3]
            sol = self._solve(problem, C_kf, values=values, imu_scale=lam["i"][w_int], pims=sol[8])
            sol = sol[:3] + (spent + sol[3],) + sol[4:]
            if change < np.log1p(self.adapt_tol):
                break
        centres = t_kf[0] + (np.arange(W) + 0.5) * self.adapt_window_s
        centres[-1] = 0.5 * (t_kf[0] + (W - 1) * self.adapt_window_s + t_kf[-1])
        return sol, {"reference_variance_scale": lam["v"], "position_variance_scale": lam["p"],
                     "imu_variance_scale": lam["i"], "adapt_window_t": centres, "adapt_rounds": rounds}
