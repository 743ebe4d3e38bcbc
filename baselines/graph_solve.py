"""Levenberg-Marquardt on the factor graph of one recording (:mod:`baselines.factor_graph`): the start values, the
passes that relinearise the tile factors and recompensate the preintegration where the attitude moved, and the
robust variant's reweighting.

The solver's tolerances and why QR: ``docs/methods/gtsam.md``.
"""

from __future__ import annotations

import copy

import numpy as np

import gtsam
from gtsam.symbol_shorthand import B, V, X

from fusionbench.simulation.attitude import dcm_to_rotvec

from .graph_aiding import keyframe_states, tile_data
from .graph_build import GraphBuilder
from .graph_rows import Intervals


def _moved(C, C_ref):
    """The largest rotation, rad, between the keyframe attitudes ``C`` and ``C_ref`` (K, 3, 3)."""
    return np.abs(dcm_to_rotvec(C @ np.swapaxes(C_ref, -1, -2))).max()


def _prefix_runs(solved, imu):
    """The solutions of ``solved = (record, runs)`` when ``imu`` is a prefix of that record (its first samples of
    its first runs); else None."""
    if solved is None:
        return None
    whole, runs = solved
    n = imu.t.size
    if (imu.kind != whole.kind or imu.runs > len(runs) or n > whole.t.size
            or not np.array_equal(imu.t, whole.t[:n]) or not np.array_equal(imu.gyro, whole.gyro[:imu.runs, :n])
            or not np.array_equal(imu.accel, whole.accel[:imu.runs, :n])):
        return None
    return runs


#: Levenberg-Marquardt's tolerance on the decrease of the cost (relative and absolute) for the solution a recording
#: ends with, and for a pass whose graph is rebuilt at its solution unless it hardly moved (docs/methods/gtsam.md,
#: "Passes").
FINAL_TOL, PASS_TOL = 1e-10, 1e-6


class GraphSolver(GraphBuilder):
    """Solves the graph of one recording (:class:`GraphBuilder`) for
    :class:`baselines.factor_graph.FactorGraphAligner` (``max_iterations``, ``max_passes``, ``recompensate_rad``,
    ``relinearize_rad``),
    and its record's prefixes from the whole record's solution (:meth:`prefix_aligner`)."""

    #: The record a prefix aligner solved and each run's ``(counts, values, pims, gyro rates)`` (:meth:`prefix_aligner`).
    _warm = None
    #: How many runs' solutions (the first ones) ``_align`` keeps in ``_solved`` with the record
    #: (:meth:`keeping_solutions`; 0: none, inf: every run).
    _keeps = 0
    #: A keeper's last record and its runs' solutions, as ``_warm``.
    _solved = None

    def keeping_solutions(self, runs=None):
        """A copy that keeps each run's solution of the record it last aligned, so that :meth:`prefix_aligner` on
        that record (or on its first runs) starts from it instead of solving the record again. What the runner
        aligns a smoother's whole record with before it reads the settling off the prefixes
        (:func:`fusionbench.bench.runner._align_batch`); it holds the record and each kept run's keyframe values,
        preintegrated intervals and gyro rates (about 5 MB a run of 600 s at 100 Hz) until it is dropped.

        Parameters
        ----------
        runs : int or None
            Keep the solutions of the first ``runs`` recordings only (the prefixes of the others are solved from
            the start); None: of every recording.

        Returns
        -------
        FactorGraphAligner
        """
        if runs is not None and not runs >= 0:
            raise ValueError(f"keeping_solutions: runs: expected a number of runs >= 0 or None, found {runs}")
        keeper = copy.copy(self)
        keeper._keeps, keeper._solved = (np.inf if runs is None else runs), None
        return keeper

    def prefix_aligner(self, imu, site, aiding=None, init=None):
        """A copy, without the marginal covariances, that aligns prefixes of the record ``imu`` from its solution.

        The copy starts from the solution of the whole record (``imu``, ``site``, ``aiding`` and ``init`` as for
        ``align``): the one this aligner kept when it is a keeper (:meth:`keeping_solutions`) that last aligned
        this record or one whose first runs it is, else one solved here. Aligning a prefix of that record (the same
        first samples of the same runs, the same aiding up to the prefix's end) then starts Levenberg-Marquardt from
        those values and reuses the intervals the prefix shares, in place of the coarse stage (or ``init``) and a
        new preintegration. The prefix's graph is the same as a cold start's; only the start differs, so the
        solution is the same to the solver's tolerance (tested). Any other record is aligned as by ``align``. What
        the runner's settling of a smoother uses (:func:`fusionbench.bench.runner._prefix_settling`).

        Returns
        -------
        FactorGraphAligner
        """
        lean = self.estimate_only()
        lean._keeps, lean._solved = 0, None
        runs = _prefix_runs(self._solved, imu)
        if runs is None:  # not the record this aligner last solved: solve it
            solver = lean.keeping_solutions()
            solver.align(imu, site, init=init, aiding=aiding)
            runs = solver._solved[1]
        lean._warm = (imu, runs[:imu.runs])
        return lean

    def _warm_runs(self, imu):
        """The kept solutions, one per run, when ``imu`` is a prefix of the record they solved; else None."""
        return _prefix_runs(self._warm, imu)

    @staticmethod
    def _warm_start(kept, counts, seg):
        """``(C_kf, values, pims)`` for :meth:`_solve` on a prefix with keyframe ``counts`` (K,) and bias segments
        ``seg``: the kept solution's first K keyframes and bias keys, and its intervals when the prefix's are the
        same ones (else None: preintegrated again)."""
        counts_all, values_all, pims_all = kept[:3]
        K = counts.size
        values = gtsam.Values()
        for k in range(K):
            values.insert(X(k), values_all.atPose3(X(k)))
            values.insert(V(k), values_all.atVector(V(k)))
        for j in range(int(seg.max()) + 1):
            values.insert(B(j), values_all.atConstantBias(B(j)))
        C_kf = np.stack([values.atPose3(X(k)).rotation().matrix() for k in range(K)])
        same = K <= counts_all.size and np.array_equal(counts, counts_all[:K])
        return C_kf, values, (Intervals(pims_all[:K - 1]) if same else None)

    def _optimize(self, graph, values, tol=FINAL_TOL):
        """Levenberg-Marquardt from ``values`` until the cost decreases by less than ``tol``, relative or absolute;
        the solution and the iterations."""
        lm = gtsam.LevenbergMarquardtParams()
        lm.setLinearSolverType("MULTIFRONTAL_QR")
        lm.setRelativeErrorTol(tol)
        lm.setAbsoluteErrorTol(tol)
        lm.setMaxIterations(self.max_iterations)
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, lm)
        return opt.optimize(), opt.iterations()

    def _solve(self, problem, C_kf, values=None, imu_scale=None, pims=None):
        """Optimise one recording from keyframe attitudes ``C_kf`` (K, 3, 3) (or from ``values``).

        Returns ``(graph, values, C_kf, iterations, passes, converged, imu_idx, vel_idx, pims, data, pos_idx)``.
        The tile factors are linearised at the current solution and the graph rebuilt there until a pass moves
        the attitude by less than ``relinearize_rad`` (and, in the robust variant, the Huber weights settle); their
        lever-arm terms and the turn of ENU, and on a moving base the preintegration's compensation for the
        transport rate, are retaken when the attitude moved by more than ``recompensate_rad`` since they were
        taken. ``pims``: intervals already preintegrated with an attitude within ``recompensate_rad`` of ``C_kf``.
        """
        counts, seg, walk = problem["counts"], problem["seg"], problem["walk"]
        K = counts.size
        data = tile_data(problem, C_kf)
        if values is None:
            values = gtsam.Values()
            v0 = problem["v_kf"].copy()
            if data["v"] is not None:  # the keyframes with rows: the velocity their rows and the IMU say
                d = data["v"]
                v_rows = d["z"] - np.einsum("kaj,kaj->ka", C_kf, d["U"])
                v0 = np.where(np.isfinite(d["var"]), v_rows, v0)
            for k in range(K):
                values.insert(X(k), gtsam.Pose3(gtsam.Rot3(C_kf[k]), problem["p_kf"][k]))
                values.insert(V(k), v0[k])
            for j in range(int(seg.max()) + 1):
                values.insert(B(j), gtsam.imuBias.ConstantBias())
        states = keyframe_states(values, K, seg)  # of the current values: the graph's linearisation point
        iterations, converged = 0, True
        huber = None  # the Huber weights need the intervals' covariance (the tiles' IMU share): first pass below
        c_max = np.abs(problem["c_n"]).max()
        C_data = C_pims = C_kf  # the attitudes the rows' terms and the compensation were taken with
        passes = max(self.max_passes, 10) if self.robust else self.max_passes
        for n_pass in range(1, passes + 1):
            if pims is not None and c_max > 0:
                turned = _moved(C_kf, C_pims)
                if turned > self.recompensate_rad and turned * c_max > 1e-9:  # the compensation matters
                    pims = None
            if pims is None:
                pims, C_pims = self._preintegrate(problem, C_kf), C_kf
            if _moved(C_kf, C_data) > self.recompensate_rad:  # the lever arm and the turn of ENU at the new attitude
                data, C_data = tile_data(problem, C_kf), C_kf
            if huber is None:
                huber = self._huber_weights(problem, data, states, pims, imu_scale)
            graph, imu_idx, idx = self._graph(pims, data, problem, seg, walk, values, imu_scale, huber, states)
            # a pass whose graph may be rebuilt at its solution stops at PASS_TOL; once its linearisation holds
            # there (and the Huber weights settled), the same graph goes on to the solver's tolerance
            tol = FINAL_TOL if n_pass == passes else PASS_TOL
            while True:
                values, n_it = self._optimize(graph, values, tol)
                iterations += n_it
                converged = converged and n_it < self.max_iterations  # a pass stopped at the limit may have stalled
                states = keyframe_states(values, K, seg)
                moved = _moved(states[0], C_kf)
                new_huber = self._huber_weights(problem, data, states, pims, imu_scale)
                settled = max(np.abs(new_huber[g] - huber[g]).max() for g in huber) <= 1e-3
                if tol == FINAL_TOL or moved > self.relinearize_rad or not settled:
                    break
                tol = FINAL_TOL
            C_kf = states[0]
            huber = new_huber
            if moved <= self.relinearize_rad and settled:
                break
        return graph, values, C_kf, iterations, n_pass, converged, imu_idx, idx["v"], pims, data, idx["p"]

    def _refine(self, problem, sol):
        """Hook for the adaptive variant: the final solution and a dict of per-recording extras."""
        return sol, {}
