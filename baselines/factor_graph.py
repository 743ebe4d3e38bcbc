"""Factor-graph fine alignment on gtsam (methods ``gtsam`` and ``gtsam-robust``).

Frames and conventions
----------------------
The navigation frame n is East-North-Up (ENU), the body frame b Right-Front-Up (x right, y
forward, z up). gtsam's ``PreintegrationParams.MakeSharedU(g)`` uses a z-up navigation frame with
gravity ``[0, 0, -g]``, which is ENU here, and its body frame is RFU, so a pose's rotation is the
attitude ``C_bn`` (body to ENU) and its translation the position in ENU metres from the start.
Misalignment ``phi = [phiE, phiN, phiU]`` (rad) is defined by ``C_bn_est = (I - [phi x]) C_bn_true``.

The graph (one per recording)
-----------------------------
Keyframes ``k = 0 .. K-1`` lie every ``keyframe_s`` seconds from the initial state ``imu.t0``;
the last keyframe is the last sample (the final interval is between 0.5 and 1.5 keyframe
intervals long). Each keyframe has a pose ``X(k)`` (``C_bn``, position) and a velocity ``V(k)``
(ENU, m/s); one bias key ``B(0)`` (accelerometer m/s^2, gyro rad/s, body frame) is shared by the
whole record (constant bias). Factors:

* ``ImuFactor(X(k-1), V(k-1), X(k), V(k), B(0))`` from ``PreintegratedImuMeasurements`` between
  consecutive keyframes, built on ``MakeSharedU(g)`` with ``setOmegaCoriolis(omega_ie^n)``, the
  earth rate in ENU (plus the transport rate on a moving base, below). The navigation frame turns with the earth: without the Coriolis term gtsam
  would read the earth rate as a gyro bias and the heading (gyrocompassing, the whole point)
  would never move. The gyro and accelerometer white-noise densities set the preintegration
  covariance; the integration covariance is small.
* a velocity prior on every ``V(k)``: the reference velocity (``vref``, averaged over a window
  centred on the keyframe), or zero on a stationary base (``vref=None``), sigma
  ``velocity_sigma``; in ``gtsam-robust`` it carries a Huber M-estimator.
* a loose position prior (``GPSFactor``) on every ``X(k)`` at the integral of the reference
  velocity (zero on a stationary base); it fixes the otherwise free position.
* a zero-mean prior on ``B(0)``. On a stationary base the horizontal accelerometer biases are
  collinear with the level angles and the east gyro bias is nearly collinear with the heading
  (over minutes): the data cannot tell them apart, the zero-mean prior keeps these bias
  components at zero and the attitude lands on the theoretical limits
  (:func:`fusionbench.metrics.theoretical_limits`). The north gyro bias, however, is observable
  as a drift of the level angles: a tight prior holds it at zero and its drift leaks into the
  level angles. With seed000's 0.01 deg/h on every axis, a prior of
  0.01 deg/h leaves the north level angle up to 5 % off its limit after 120 to 300 s, 0.1 deg/h
  within 1 %. Hence the default gyro-bias sigma of 0.1 deg/h, ten times the seed000 bias (set it
  to at least the sensor's bias). The accelerometer prior (100 ug) matters for the vertical bias,
  which is observable and also carries the vertical scale-factor error (seed000: 30 ug plus
  70 ppm of g, about 100 ug, estimated as such), and for the reported level sigmas. The up gyro
  bias turns the heading by ``eps_U t``, which minutes of data cannot see (it is not estimated),
  so the final heading carries about ``eps_U T / 2`` beyond the limit: 0.04 arcmin for
  0.015 deg/h over 300 s, 1.7 % of a 2.5-arcmin limit.

There is no attitude prior: the attitude comes from gravity and the earth rate alone. The graph is
solved by Levenberg-Marquardt with a multifrontal QR factorisation and tolerances of 1e-10: the
whitened Jacobian has a condition number near 1e7 (from a metre-level position prior to a
gyro bias of 1e-8 rad/s), so Cholesky on the information matrix (condition 1e14) fails.

Moving base and accuracy details
--------------------------------
* The IMU increments get the coning and sculling compensation of the strapdown
  (:mod:`fusionbench.strapdown`) before they are fed, as rates over the sample interval, to gtsam,
  whose per-sample integration rotates each velocity increment with the attitude at the start of
  the sample.
* gtsam 4.3 integrates the kinematics of a frame turning at the Coriolis rate ``omega`` exactly,
  about an axis through the origin of the positions: ``dv/dt = f + g - 2 omega x v -
  omega x (omega x p)`` (checked: a perfect stationary IMU is predicted to 1e-11 m/s over 10 s,
  although the frozen-frame velocity increment carries ``g W cos(L) T^2 / 2``, and the
  prediction changes by ``-omega x (omega x p) T`` with the position p).
* On a moving base (``vref``) the ENU frame also turns with the transport rate
  ``omega_en^n``. Each interval then gets its own parameters: gravity at its latitude and height
  and ``setOmegaCoriolis(omega_ie^n + omega_en^n)`` at the mean reference velocity over the
  interval (latitude and height from the integrated reference). Where gtsam's model and the ENU
  velocity equation ``dv/dt = f + g - (2 omega_ie + omega_en) x v`` differ, the specific force of
  every sample gets ``C_nb (omega_en x v + omega x (omega x p))`` (the centrifugal term is
  already in normal gravity, and p, from the integrated reference, reaches tens of km), with the
  current attitude estimate; the graph is rebuilt when the optimised attitude moved by more than
  ``recompensate_rad``. A perfect IMU accelerating at 0.1 g to 245 m/s is then aligned to
  0.0003 arcmin (0.007 arcmin with the 1 s averaging of ``vref`` across the onset of the
  acceleration), against 5 to 19 arcmin with the earth rate alone. Position is a local ENU
  offset from the start.
* With ``init=None`` the coarse stage (inertial-frame coarse alignment) assumes a stationary or
  swaying base; on an accelerating base give ``init``.

Keyframe interval
-----------------
1 s by default: the highest rate of velocity information in the 1 to 10 s range (on a stationary
base the zero velocity is exact, so more of it helps), and the smallest errors from what is held
constant over an interval (transport rate, compensation) or averaged (``vref`` over a
keyframe-wide window). Measured with a perfect IMU on the 0.1 g accelerating base above, the
largest final error grows from 0.0003 arcmin (1 s) to 0.002 arcmin (10 s) with ``vref`` taken at
the keyframes, and from 0.007 to 0.12 arcmin with the default window; under degree-level sway it
stays below 0.012 arcmin. A 10-minute record at 100 Hz is 600 poses and takes about 0.7 s per
recording with the marginals (0.25 s of it the coarse stage when ``init`` is None).

Marginals
---------
``gtsam.Marginals`` (Cholesky on the information matrix) fails on this graph with an
IndeterminantLinearSystem error, so ``sigma_phi`` comes from a QR-eliminated Bayes net of the
graph linearised at the solution (a backward covariance recursion, linear in K). It includes the
bias prior: the azimuth sigma is at least ``gyro_bias_sigma / (W cos L)`` and the level sigmas at
least ``accel_bias_sigma / g``, the unobservable parts. ``sigma_phi_noise`` is the same marginal
with the bias known (conditional on ``B(0)``): the spread around the limits that the sensor noise
alone causes.

The result's history is the optimised attitude at each keyframe (``t`` the keyframe times, the last
one the last sample).
"""

from __future__ import annotations

import numpy as np

import gtsam
from gtsam.symbol_shorthand import B, V, X

from fusionbench import earth, units
from fusionbench.aligner import AlignmentResult, Site, initial_attitude
from fusionbench.attitude import dcm_to_rotvec, orthonormalize
from fusionbench.imudata import IMUData

from .coarse import InertialCoarseAligner
from .graph_support import (_interval_rotations, _propagate, _window_means, compensated_increments,  # noqa: F401
                            keyframe_counts, marginal_sigmas)

__all__ = ["FactorGraphAligner", "RobustFactorGraphAligner", "keyframe_counts", "compensated_increments",
           "MAX_LATITUDE_DEG"]

#: Highest |latitude| accepted, deg: the horizontal earth rate W cos(L) that sets the heading vanishes at the poles.
MAX_LATITUDE_DEG = 89.0

#: Defaults: white noise of the seed000 preset ("Zhou 2011"), bias-prior sigmas (see the module docstring).
GYRO_NOISE = 0.005 * units.DEG_PER_SQRT_H       # rad/sqrt(s)
ACCEL_NOISE = 6.0 * units.UG_PER_SQRT_HZ        # m/s/sqrt(s)
GYRO_BIAS_SIGMA = 0.1 * units.DEG_PER_H         # rad/s, 10 x seed000's 0.01 deg/h
ACCEL_BIAS_SIGMA = 100.0 * units.UG             # m/s^2, above seed000's 30 ug


class FactorGraphAligner:
    """Factor-graph fine alignment (method ``gtsam``): gtsam ImuFactors with earth-rate Coriolis,
    velocity priors and one constant bias, solved by Levenberg-Marquardt (see the module docstring).

    Parameters
    ----------
    keyframe_s : float
        Keyframe interval, s (default 1 s).
    gyro_noise : float
        Gyro white-noise density (angle random walk), rad/sqrt(s); default seed000's
        0.005 deg/sqrt(h).
    accel_noise : float
        Accelerometer white-noise density (velocity random walk), m/s/sqrt(s); default seed000's
        6 ug/sqrt(Hz).
    gyro_bias_sigma : float
        Sigma of the zero-mean gyro-bias prior, rad/s; default 0.1 deg/h. Not smaller than the
        sensor's bias.
    accel_bias_sigma : float
        Sigma of the zero-mean accelerometer-bias prior, m/s^2; default 100 ug.
    velocity_sigma : float
        Sigma of the velocity priors (zero velocity or ``vref``), m/s.
    position_sigma : float
        Sigma of the loose position priors, m.
    integration_sigma : float
        gtsam's integration noise density (position), m/sqrt(s); small.
    vref_window_s : float, optional
        Full width of the window over which ``vref`` is averaged around each keyframe, s
        (default one keyframe interval; shrunk symmetrically at the ends of the record).
    max_iterations : int
        Levenberg-Marquardt iteration limit. When it is reached from a given ``init``, the
        recording is solved again from the coarse alignment and the solution of lower cost kept.
    recompensate_rad : float
        On a moving base, rebuild the graph when the optimised attitude moved by more than this from
        the attitude used for the transport-rate compensation (rad), unless the compensation is too
        small for it to matter (angle moved times compensation below 1e-9 m/s^2).
    max_passes : int
        At most this many graph builds per recording.
    marginals : bool
        Compute ``extra["sigma_phi"]`` and ``extra["sigma_phi_noise"]``.
    huber_k : float
        Huber threshold, in sigmas, of the robust variant.
    coarse : object, optional
        Aligner used when ``init`` is None (default :class:`baselines.coarse.InertialCoarseAligner`,
        which works on a swaying base).
    """

    name = "gtsam"
    description = "factor-graph fine alignment (gtsam ImuFactors, earth-rate Coriolis, velocity priors, one constant bias)"
    robust = False

    def __init__(self, keyframe_s=1.0, gyro_noise=GYRO_NOISE, accel_noise=ACCEL_NOISE, gyro_bias_sigma=GYRO_BIAS_SIGMA,
                 accel_bias_sigma=ACCEL_BIAS_SIGMA, velocity_sigma=0.01, position_sigma=1.0, integration_sigma=1e-6,
                 vref_window_s=None, max_iterations=100, recompensate_rad=1e-3, max_passes=3, marginals=True,
                 huber_k=1.345, coarse=None):
        positive = dict(keyframe_s=keyframe_s, gyro_noise=gyro_noise, accel_noise=accel_noise,
                        gyro_bias_sigma=gyro_bias_sigma, accel_bias_sigma=accel_bias_sigma,
                        velocity_sigma=velocity_sigma, position_sigma=position_sigma,
                        integration_sigma=integration_sigma, recompensate_rad=recompensate_rad, huber_k=huber_k)
        for key, val in positive.items():
            try:
                val = float(val)
            except (TypeError, ValueError):
                raise ValueError(f"{key}: expected a positive number, found {val!r}") from None
            if not (np.isfinite(val) and val > 0):
                raise ValueError(f"{key}: expected a positive number, found {val}")
            setattr(self, key, val)
        if vref_window_s is not None and not (np.isfinite(vref_window_s) and vref_window_s >= 0):
            raise ValueError(f"vref_window_s: expected a non-negative number of seconds, found {vref_window_s}")
        self.vref_window_s = self.keyframe_s if vref_window_s is None else float(vref_window_s)
        for key, val in (("max_iterations", max_iterations), ("max_passes", max_passes)):
            if int(val) != val or val < 1:
                raise ValueError(f"{key}: expected a positive integer, found {val}")
        self.max_iterations, self.max_passes = int(max_iterations), int(max_passes)
        self.marginals = bool(marginals)
        self.coarse = InertialCoarseAligner() if coarse is None else coarse
        #: Shortest record, s: three keyframe intervals, and what the coarse initialisation needs.
        self.min_duration_s = max(3.0 * self.keyframe_s, float(getattr(self.coarse, "min_duration_s", 0.0)))

    # ------------------------------------------------------------------------------------ checks
    def _check(self, imu, site, vref, init):
        if not isinstance(imu, IMUData):
            raise ValueError(f"imu: expected an IMUData, found {type(imu).__name__}")
        if not np.isfinite(site.lat) or abs(site.lat) > np.radians(MAX_LATITUDE_DEG):
            raise ValueError(f"site latitude: {self.name} needs |latitude| <= {MAX_LATITUDE_DEG:g} deg "
                             f"(the heading comes from the horizontal earth rate), found {np.degrees(site.lat):g} deg")
        if imu.duration < self.min_duration_s:
            raise ValueError(f"duration: {self.name} needs at least {self.min_duration_s:g} s "
                             f"(keyframes every {self.keyframe_s:g} s), found {imu.duration:g} s")
        if self.keyframe_s < imu.dt:
            raise ValueError(f"keyframe_s: expected at least the sample interval {imu.dt:g} s, "
                             f"found {self.keyframe_s:g} s")
        for nm, a in (("gyro", imu.gyro), ("accel", imu.accel)):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"imu {nm}: expected finite samples, found NaN or inf")
        M = imu.increments()[0].size
        if vref is not None:
            vref = np.asarray(vref, dtype=float)
            if vref.ndim == 2:
                vref = vref[None]
            if vref.ndim != 3 or vref.shape[1:] != (M, 3) or vref.shape[0] not in (1, imu.runs):
                raise ValueError(f"vref: expected shape ({imu.runs}, {M}, 3) (ENU m/s at the increment ends), "
                                 f"found {vref.shape}")
            if not np.all(np.isfinite(vref)):
                raise ValueError("vref: expected finite velocities, found NaN or inf")
            vref = np.broadcast_to(vref, (imu.runs, M, 3))
        if init is not None:
            try:
                init = initial_attitude(init, imu.runs)
            except ValueError:
                raise ValueError(f"init: expected shape ({imu.runs}, 3, 3) or (3, 3), found {np.shape(init)}") from None
            if not np.all(np.isfinite(init)) or np.any(np.linalg.det(init) < 0.5):
                raise ValueError("init: expected finite rotation matrices (C_bn, body RFU to ENU)")
            init = orthonormalize(init)
        return vref, init

    # --------------------------------------------------------------------------------- the model
    def _velocity_noise(self):
        base = gtsam.noiseModel.Isotropic.Sigma(3, self.velocity_sigma)
        if not self.robust:
            return base
        return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(self.huber_k), base)

    def _params(self, g, omega):
        """PreintegrationParams: z-up (ENU) gravity g (m/s^2), Coriolis rate omega (ENU, rad/s), noise densities."""
        p = gtsam.PreintegrationParams.MakeSharedU(float(g))
        p.setOmegaCoriolis(np.asarray(omega, dtype=float))
        p.setGyroscopeCovariance(self.gyro_noise**2 * np.eye(3))
        p.setAccelerometerCovariance(self.accel_noise**2 * np.eye(3))
        p.setIntegrationCovariance(self.integration_sigma**2 * np.eye(3))
        return p

    @staticmethod
    def _references(site, vref_r, counts, dt, half):
        """Keyframe velocities and positions, and per-interval rates and gravity, for one recording.

        Returns ``v_kf`` (K, 3) m/s and ``p_kf`` (K, 3) m (ENU), ``w_in`` (K-1, 3) rad/s the turn
        rate of ENU over each interval (earth plus transport rate), ``c_n`` (K-1, 3) m/s^2 the
        specific-force correction ``omega_en x v + omega_in x (omega_in x p)`` and ``g`` (K-1,) m/s^2.
        """
        K = counts.size
        if vref_r is None:
            w = earth.earth_rate_n(site.lat)
            return (np.zeros((K, 3)), np.zeros((K, 3)), np.broadcast_to(w, (K - 1, 3)), np.zeros((K - 1, 3)),
                    np.full(K - 1, site.g))
        v_kf = _window_means(vref_r, np.maximum(counts - 1, 0), half)
        v_prev = np.vstack([vref_r[:1], vref_r[:-1]])
        p = np.vstack([np.zeros((1, 3)), np.cumsum(0.5 * (vref_r + v_prev) * dt, axis=0)])
        p_kf = p[counts]
        v_bar = np.diff(p_kf, axis=0) / (np.diff(counts) * dt)[:, None]
        p_mid = 0.5 * (p_kf[1:] + p_kf[:-1])
        rm, _ = earth.radii(site.lat)
        lat = site.lat + p_mid[:, 1] / (rm + site.h)
        h = site.h + p_mid[:, 2]
        w_en = earth.transport_rate_n(v_bar, lat, h)
        w_in = earth.earth_rate_n(lat) + w_en
        # gtsam applies 2 w_in x v (ENU needs (2 w_ie + w_en) x v) and the centrifugal term of a frame
        # turning about an axis through the origin, w_in x (w_in x p) (in normal gravity already)
        c_n = np.cross(w_en, v_bar) + np.cross(w_in, np.cross(w_in, p_mid))
        return v_kf, p_kf, w_in, c_n, earth.gravity(lat, h)

    def _graph(self, phi, dv, dt, counts, C_kf, refs):
        """The factor graph of one recording; the transport-rate correction uses attitude ``C_kf`` (K, 3, 3)."""
        v_kf, p_kf, w_in, c_n, g = refs
        K = counts.size
        acc = dv / dt
        if np.any(c_n):
            c_b, _ = _interval_rotations(phi, counts, np.einsum("kji,kj->ki", C_kf[:-1], c_n))
            acc = acc + c_b
        gyr = phi / dt
        graph = gtsam.NonlinearFactorGraph()
        zero = gtsam.imuBias.ConstantBias()
        same = np.all(w_in == w_in[0]) and np.all(g == g[0])
        params = self._params(g[0], w_in[0]) if same else None
        for k in range(1, K):
            pim = gtsam.PreintegratedImuMeasurements(params if same else self._params(g[k - 1], w_in[k - 1]), zero)
            for i in range(counts[k - 1], counts[k]):
                pim.integrateMeasurement(acc[i], gyr[i], dt)
            graph.add(gtsam.ImuFactor(X(k - 1), V(k - 1), X(k), V(k), B(0), pim))
        v_noise = self._velocity_noise()
        p_noise = gtsam.noiseModel.Isotropic.Sigma(3, self.position_sigma)
        for k in range(K):
            graph.add(gtsam.PriorFactorVector(V(k), v_kf[k], v_noise))
            graph.add(gtsam.GPSFactor(X(k), p_kf[k], p_noise))
        b_sigmas = np.r_[np.full(3, self.accel_bias_sigma), np.full(3, self.gyro_bias_sigma)]  # gtsam order: acc, gyro
        graph.add(gtsam.PriorFactorConstantBias(B(0), zero, gtsam.noiseModel.Diagonal.Sigmas(b_sigmas)))
        return graph

    def _optimize(self, graph, values):
        lm = gtsam.LevenbergMarquardtParams()
        lm.setLinearSolverType("MULTIFRONTAL_QR")
        lm.setRelativeErrorTol(1e-10)
        lm.setAbsoluteErrorTol(1e-10)
        lm.setMaxIterations(self.max_iterations)
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, lm)
        return opt.optimize(), opt.iterations()

    def _solve(self, phi, dv, dt, counts, C_kf, refs):
        """Optimise one recording from keyframe attitudes ``C_kf`` (K, 3, 3).

        Returns ``(graph, values, C_kf, iterations, passes, converged)``; the graph is rebuilt with
        the optimised attitude (moving base only) until it moves by less than ``recompensate_rad``.
        """
        K = counts.size
        values = gtsam.Values()
        for k in range(K):
            values.insert(X(k), gtsam.Pose3(gtsam.Rot3(C_kf[k]), refs[1][k]))
            values.insert(V(k), refs[0][k])
        values.insert(B(0), gtsam.imuBias.ConstantBias())
        iterations, converged = 0, True
        for n_pass in range(1, self.max_passes + 1):
            graph = self._graph(phi, dv, dt, counts, C_kf, refs)
            values, n_it = self._optimize(graph, values)
            iterations += n_it
            converged = n_it < self.max_iterations
            C_new = np.stack([values.atPose3(X(k)).rotation().matrix() for k in range(K)])
            moved = np.abs(dcm_to_rotvec(C_new @ np.swapaxes(C_kf, -1, -2))).max()
            C_kf = C_new
            if moved <= self.recompensate_rad or moved * np.abs(refs[3]).max() <= 1e-9:
                break
        return graph, values, C_kf, iterations, n_pass, converged

    # ------------------------------------------------------------------------------------- align
    def align(self, imu: IMUData, site: Site, vref=None, init=None) -> AlignmentResult:
        """Align every recording of ``imu`` by factor-graph smoothing, from any heading.

        Parameters
        ----------
        imu : IMUData
            R recordings, body frame RFU (increments or rates).
        site : Site
            Latitude (|lat| <= 89 deg), longitude, height.
        vref : ndarray, shape (R, M, 3) or (M, 3), optional
            Reference velocity, ENU, m/s, at the ends of the increment intervals
            (``imu.increments()[0]``); None for a stationary base (zero velocity).
        init : ndarray, shape (R, 3, 3) or (3, 3), optional
            Initial guess of ``C_bn`` at the first keyframe (the initial state, ``imu.t0``), carried
            to the other keyframes with the gyros; any heading (from 180 deg off, LM needs about 70
            iterations instead of 5). None: the coarse stage (``self.coarse``) gives the attitude at
            the last sample, carried back to the start with the gyros.

        Returns
        -------
        AlignmentResult
            ``t`` (K,) keyframe times, s (the last one the last sample); ``C_bn`` (R, K, 3, 3) the
            optimised attitude at the keyframes. ``extra``: ``sigma_phi`` and ``sigma_phi_noise``
            (R, K, 3) marginal misalignment sigmas, rad, ENU (with the bias prior; with the bias
            known); ``gyro_bias`` (R, 3) rad/s and ``accel_bias`` (R, 3) m/s^2, the estimated
            biases, body frame; ``iterations``, ``passes`` (R,) ints (LM iterations, graph builds);
            ``restarted`` (R,) bool (solved again from the coarse alignment); ``graph_error`` (R,),
            the final cost; ``keyframe_s``.

        Raises
        ------
        ValueError
            Naming the field: latitude beyond 89 deg, a record shorter than ``min_duration_s``,
            badly shaped ``vref`` or ``init``, non-finite samples.
        """
        vref, init = self._check(imu, site, vref, init)
        t_end, dth, dvel = imu.increments()
        M, dt, R = t_end.size, imu.dt, imu.runs
        counts = keyframe_counts(M, max(1, int(round(self.keyframe_s / dt))))
        K = counts.size
        t_kf = np.concatenate([[imu.t0], t_end[counts[1:] - 1]])
        T = np.diff(counts) * dt
        half = int(round(0.5 * self.vref_window_s / dt))
        coarse_final = None if init is not None else self.coarse.align(imu, site, vref=vref).C_bn_final

        C_out = np.empty((R, K, 3, 3))
        sig, sig_noise = np.full((R, K, 3), np.nan), np.full((R, K, 3), np.nan)
        bg, ba = np.empty((R, 3)), np.empty((R, 3))
        iters, passes, cost = np.zeros(R, int), np.zeros(R, int), np.empty(R)
        restarted = np.zeros(R, bool)
        for r in range(R):
            refs = self._references(site, None if vref is None else vref[r], counts, dt, half)
            phi, dv = compensated_increments(dth[r], dvel[r])
            _, dR = _interval_rotations(phi, counts, None)
            if init is not None:
                start = _propagate(init[r], dR, refs[2], T, forward=True)
            else:
                start = _propagate(orthonormalize(coarse_final[r]), dR, refs[2], T, forward=False)
            sol = self._solve(phi, dv, dt, counts, start, refs)
            if init is not None and not sol[-1]:
                # LM stopped at its iteration limit from the given guess: start again from the coarse
                # alignment and keep the better solution
                if coarse_final is None:
                    coarse_final = self.coarse.align(imu, site, vref=vref).C_bn_final
                other = self._solve(phi, dv, dt, counts, _propagate(orthonormalize(coarse_final[r]), dR, refs[2], T,
                                                                    forward=False), refs)
                restarted[r] = True
                spent = sol[3] + other[3]
                if other[0].error(other[1]) < sol[0].error(sol[1]):
                    sol = other
                sol = sol[:3] + (spent,) + sol[4:]
            graph, values, C_kf, iters[r], passes[r], _ = sol
            cost[r] = graph.error(values)
            C_out[r] = C_kf
            bias = values.atConstantBias(B(0))
            bg[r], ba[r] = bias.gyroscope(), bias.accelerometer()
            if self.marginals:
                sig[r], sig_noise[r] = marginal_sigmas(graph, values, C_kf)
        extra = {"sigma_phi": sig, "sigma_phi_noise": sig_noise, "gyro_bias": bg, "accel_bias": ba,
                 "iterations": iters, "passes": passes, "restarted": restarted, "graph_error": cost,
                 "keyframe_s": self.keyframe_s}
        return AlignmentResult(self.name, t_kf, C_out, extra)


class RobustFactorGraphAligner(FactorGraphAligner):
    """Factor-graph fine alignment with Huber-robust velocity priors (method ``gtsam-robust``).

    The graph of :class:`FactorGraphAligner`, but the velocity priors use
    ``Robust(Huber(huber_k), Isotropic(velocity_sigma))``: reference-velocity outliers (noise
    bursts, base motion the reference does not see) weigh linearly rather than quadratically beyond
    ``huber_k`` sigmas (default 1.345, 95 % efficiency on Gaussian noise). Parameters as for
    :class:`FactorGraphAligner`. On data whose velocity residuals stay inside the threshold it
    gives the same result.
    """

    name = "gtsam-robust"
    description = "factor-graph fine alignment with Huber-robust velocity priors (gtsam)"
    robust = True
