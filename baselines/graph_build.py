"""The factor graph of one recording (:mod:`baselines.factor_graph`): gtsam's preintegration of each keyframe
interval, the bias segments and their walk, and the graph itself (ImuFactors, the tile factors of the aiding rows with
the IMU's own share of their noise, the priors), with the robust variant's Huber weights.

Frames: navigation ENU, body RFU (a pose's rotation is ``C_bn``); units SI. The design and what decided it:
``docs/methods/gtsam.md``.
"""

from __future__ import annotations

import numpy as np

import gtsam
from gtsam.symbol_shorthand import B, V, X

from .graph_aiding import keyframe_states
from .graph_model import STILL_WALK, UNFIXED_SIGMA, UNMEASURED_VELOCITY_SIGMA
from .graph_rows import Intervals, tile_error, tile_factors, tile_imu_variance
from .graph_support import _interval_rotations, tangent_rates


class GraphBuilder:
    """Builds the graph of one recording for :class:`baselines.factor_graph.FactorGraphAligner`, from the aligner's
    figures (``gyro_noise``, ``accel_noise``, ``integration_sigma``, bias priors and walk, ``bias_interval_s``,
    ``vref_sigma``, ``aiding_position_sigma``, ``position_sigma``, ``init_sigma``, ``robust``, ``huber_k``)."""

    def _tile_variance(self, g, data, pims, R, imu_scale=None):
        """Variance (K, 3) (m/s)^2 or m^2, ENU, of the tile factors of group ``g`` ("v" velocity, "p" position)
        before any Huber weight: the rows' own (their unit sigma squared times ``data[g]["var"]``) and, for the
        velocity tiles, what the IMU's own noise leaves in the prediction (:func:`baselines.graph_rows.tile_imu_variance`
        at the keyframe attitudes ``R``), at least the nominal share: the ImuFactors' residuals, which the tiles share, put
        the adaptive IMU factor ``imu_scale`` below 1 with an exact reference, and a share scaled down with it left
        gtsam-adaptive 1.59 bounds off at 60 N (tactical IMU; 0.90 with this floor)."""
        unit = self.vref_sigma if g == "v" else self.aiding_position_sigma
        var = unit**2 * data[g]["var"]
        if g == "v":
            scale = None if imu_scale is None else np.maximum(imu_scale, 1.0)
            var = var + tile_imu_variance(pims, R, scale)
        return var

    def _huber_weights(self, problem, data, states, pims, imu_scale=None):
        """Huber weights of the tile factors at the keyframe ``states`` (:func:`baselines.graph_aiding.keyframe_states`
        of a solution), ``{"v": (K,), "p": (K,)}`` (robust variant; all 1
        otherwise): 1 within ``huber_k`` sigmas of the whitened error's norm, ``huber_k / |e|`` beyond (gtsam's
        Huber on a block). The error is whitened by the factor's whole variance (:meth:`_tile_variance`), the IMU's
        share included, so that a tile the factor itself expects to be off is not down-weighted for it."""
        K = problem["counts"].size
        out = {g: np.ones(K) for g in ("v", "p")}
        if not self.robust:
            return out
        R, t, v, b = states
        for g in ("v", "p"):
            if data[g] is not None:
                e = tile_error(data[g], R, t, v, b) / np.sqrt(self._tile_variance(g, data, pims, R, imu_scale))
                r = np.linalg.norm(np.where(np.isfinite(data[g]["var"]), e, 0.0), axis=1)
                out[g] = np.where(r <= self.huber_k, 1.0, self.huber_k / np.maximum(r, 1e-300))
        return out

    def _params(self, g, omega):
        """PreintegrationParams: z-up (ENU) gravity g (m/s^2), Coriolis rate omega (ENU, rad/s), noise densities."""
        p = gtsam.PreintegrationParams.MakeSharedU(float(g))
        p.setOmegaCoriolis(np.asarray(omega, dtype=float))
        p.setGyroscopeCovariance(np.diag(np.broadcast_to(self.gyro_noise, (3,)) ** 2))
        p.setAccelerometerCovariance(np.diag(np.broadcast_to(self.accel_noise, (3,)) ** 2))
        p.setIntegrationCovariance(self.integration_sigma**2 * np.eye(3))
        return p

    def _bias_segments(self, t_kf):
        """Bias key of each keyframe interval (K-1,) ints and the bias-walk sigmas (6,) over one segment
        (gtsam order: accelerometer, gyro); one constant bias when the model's bias does not walk."""
        walk = np.r_[np.broadcast_to(self.accel_bias_walk, (3,)), np.broadcast_to(self.gyro_bias_walk, (3,))]
        K = t_kf.size
        if not np.any(walk > 0):
            return np.zeros(K - 1, int), walk
        # an axis whose bias does not walk beside one that does (an identified spec: the accelerometers' rate
        # random walk found, the gyros' not) walks by 1e-3 of its prior over an hour: as constant as the record can
        # tell, where a zero sigma made the between factor's weight infinite and LM stop at its start
        prior = np.r_[np.broadcast_to(self.accel_bias_sigma, (3,)), np.broadcast_to(self.gyro_bias_sigma, (3,))]
        walk = np.where(walk > 0, walk, STILL_WALK * prior)
        n = max(1, int(round((t_kf[-1] - t_kf[0]) / self.bias_interval_s)))
        seg = np.minimum(((t_kf[:-1] - t_kf[0]) / self.bias_interval_s).astype(int), n - 1)
        return seg, walk * np.sqrt(self.bias_interval_s)

    def _preintegrate(self, problem, C_kf):
        """Preintegrated IMU measurements of the K-1 keyframe intervals; the transport-rate correction
        uses attitude ``C_kf`` (K, 3, 3). The gyro rates (:func:`baselines.graph_support.tangent_rates`), which do not
        depend on the attitude, are computed once and kept in ``problem["gyr"]``."""
        phi, dv, dt, counts = problem["phi"], problem["dv"], problem["dt"], problem["counts"]
        w_in, c_n, g = problem["w_in"], problem["c_n"], problem["g"]
        K = counts.size
        acc = dv / dt
        if np.any(c_n):
            c_b, _ = _interval_rotations(phi, counts, np.einsum("kji,kj->ki", C_kf[:-1], c_n))
            acc = acc + c_b
        gyr = problem.get("gyr")
        if gyr is None:
            gyr = problem["gyr"] = tangent_rates(phi, counts, dt)
        zero = gtsam.imuBias.ConstantBias()
        same = np.all(w_in == w_in[0]) and np.all(g == g[0])
        params = self._params(g[0], w_in[0]) if same else None
        pims = Intervals()
        for k in range(1, K):
            pim = gtsam.PreintegratedImuMeasurements(params if same else self._params(g[k - 1], w_in[k - 1]), zero)
            for i in range(counts[k - 1], counts[k]):
                pim.integrateMeasurement(acc[i], gyr[i], dt)
            pims.append(pim)
        return pims

    def _graph(self, pims, data, refs, seg, walk, at, imu_scale=None, huber=None, states=None):
        """The factor graph of one recording from its preintegrated intervals ``pims`` and its tile factors'
        ``data`` (:func:`baselines.graph_aiding.tile_data`), linearised at the values ``at`` (``states``: their
        keyframe states, :func:`baselines.graph_aiding.keyframe_states`, when the caller has them).

        ``imu_scale`` (K-1,) multiplies the preintegrated covariance of each interval, ``huber`` (``{"v": (K,), "p":
        (K,)}``) the tile factors' information (default 1). Returns the graph and the indices of its ImuFactors
        (K-1,), velocity and position factors (K,; -1 where a keyframe has none).
        """
        K = len(pims) + 1
        graph = gtsam.NonlinearFactorGraph()
        zero = gtsam.imuBias.ConstantBias()
        imu_idx, idx = np.empty(K - 1, int), {"v": np.full(K, -1), "p": np.full(K, -1)}
        for k in range(1, K):
            pim = pims[k - 1]
            f = gtsam.ImuFactor(X(k - 1), V(k - 1), X(k), V(k), B(seg[k - 1]), pim)
            if imu_scale is not None and imu_scale[k - 1] != 1.0:
                cov = imu_scale[k - 1] * pim.preintMeasCov()
                f = f.cloneWithNewNoiseModel(gtsam.noiseModel.Gaussian.Covariance(cov))
            imu_idx[k - 1] = graph.size()
            graph.add(f)
        keys = [(X(k), V(k), B(seg[min(k, K - 2)])) for k in range(K)]
        if states is None and (data["v"] is not None or data["p"] is not None):
            states = keyframe_states(at, K, seg)
        for g in ("v", "p"):
            if data[g] is None:
                continue
            w = 1.0 if huber is None else huber[g][:, None]
            var = self._tile_variance(g, data, pims, states[0], imu_scale) / w
            for k, f in tile_factors(data[g], np.sqrt(var), keys, states, at):
                idx[g][k] = graph.size()
                graph.add(f)
        free = np.ones(3, bool) if refs["pos"] is None else ~np.any(refs["pos"]["W"] > 0, axis=0)
        if free.any():  # a loose prior on the position's axes that no row fixes (velocities leave it free)
            sig = np.where(free, self.position_sigma, UNFIXED_SIGMA)
            graph.add(gtsam.GPSFactor(X(0), refs["p_kf"][0], gtsam.noiseModel.Diagonal.Sigmas(sig)))
        free &= True if refs["vel"] is None else ~np.any(refs["vel"]["W"] > 0, axis=0)
        if free.any():  # nor the velocity's (a vertical that no row measures)
            sig = np.where(free, UNMEASURED_VELOCITY_SIGMA, UNFIXED_SIGMA)
            graph.add(gtsam.PriorFactorVector(V(0), refs["v_kf"][0], gtsam.noiseModel.Diagonal.Sigmas(sig)))
        if refs.get("C0") is not None:
            # phi = -C_bn delta (delta: Pose3 rotation tangent, body frame): cov(delta) = C^T diag(sigma^2) C
            C0 = refs["C0"]
            cov = np.zeros((6, 6))
            cov[:3, :3] = C0.T @ np.diag(self.init_sigma**2) @ C0
            cov[3:, 3:] = np.eye(3) * 1e6
            graph.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(gtsam.Rot3(C0), refs["p_kf"][0]),
                                             gtsam.noiseModel.Gaussian.Covariance(cov)))
        b_sigmas = np.r_[np.broadcast_to(self.accel_bias_sigma, (3,)), np.broadcast_to(self.gyro_bias_sigma, (3,))]
        # smart=False: gtsam makes a model with a sigma below 1e-9 a Constrained one (a navigation-grade
        # gyro's walk over 30 s is 1.3e-9 rad/s)
        graph.add(gtsam.PriorFactorConstantBias(B(0), zero, gtsam.noiseModel.Diagonal.Sigmas(b_sigmas, False)))
        walk_noise = gtsam.noiseModel.Diagonal.Sigmas(walk, False) if seg.max() > 0 else None
        for j in range(1, int(seg.max()) + 1):
            graph.add(gtsam.BetweenFactorConstantBias(B(j - 1), B(j), zero, walk_noise))
        return graph, imu_idx, idx
