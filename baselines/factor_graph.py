"""Factor-graph fine alignment on gtsam: the aligners ``gtsam`` (:class:`FactorGraphAligner`) and ``gtsam-robust``
(:class:`RobustFactorGraphAligner`); ``gtsam-adaptive`` is in :mod:`baselines.graph_adaptive`.

One graph per recording: keyframes every ``step_s`` with a pose (attitude ``C_bn``, ENU position) and an ENU velocity,
gtsam ImuFactors between them with the earth rate as Coriolis, a tile factor of the aiding rows nearest each keyframe
(each row at its time of validity, with the lever arm), bias priors and walk from the IMU model, solved by
Levenberg-Marquardt: a smoother, every keyframe's estimate from the whole record. Frames: navigation ENU, body RFU.

Built from :mod:`baselines.graph_model` (the figures), :mod:`baselines.graph_build` (the graph),
:mod:`baselines.graph_solve` (its solve), :mod:`baselines.graph_rows` and :mod:`baselines.graph_aiding` (the rows),
:mod:`baselines.graph_support` (increments), :mod:`baselines.graph_posterior` (marginals). The design, its conventions and what was measured to decide it:
``docs/methods/gtsam.md``.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np

from gtsam.symbol_shorthand import B

from fusionbench.methods.aligner import AlignmentResult, Site
from fusionbench.methods.aligner_base import AlignerBase
from fusionbench.methods.claims import Supports
from fusionbench.simulation.attitude import orthonormalize
from fusionbench.simulation.imu import load_spec
from fusionbench.simulation.imudata import IMUData

from fusionbench.methods.coarse import InertialCoarseAligner
from .graph_aiding import POSITION_SIGMA, build_problem, keyframe_states, motion_from_solution, recording_rows
from .graph_model import VREF_SIGMA_FLOOR, _scalar_or_axes, noise_model
from .graph_solve import GraphSolver
from .graph_posterior import marginal_sigmas
from .graph_support import _interval_rotations, _propagate, keyframe_counts

__all__ = ["FactorGraphAligner", "RobustFactorGraphAligner", "noise_model"]


def _check_turn_per_interval(name, dth, counts, t_kf):
    """Refuse, in one line, a record whose gyros turn by pi rad or more within one keyframe interval: the interval's
    rotation vector, which the tangent preintegration accumulates, would wrap. ``dth`` (R, M, 3) rad, the sample
    rotation vectors; ``counts`` (K,) the keyframe sample counts; ``t_kf`` (K,) their times, s. The sum of the samples'
    angles bounds the interval's rotation from above, so a record this accepts never wraps."""
    angles = np.sqrt(np.einsum("rmi,rmi->rm", dth, dth))  # (R, M) rad, without an (R, M, 3) temporary
    turned = np.add.reduceat(angles, counts[:-1], axis=1)  # (R, K - 1) rad
    r, k = np.unravel_index(np.argmax(turned), turned.shape)
    if turned[r, k] >= np.pi:
        raise ValueError(f"{name}: the gyros turn by {np.degrees(turned[r, k]):.0f} deg within the keyframe interval "
                         f"from t = {t_kf[k]:.2f} s to {t_kf[k + 1]:.2f} s (run {r}): expected less than 180 deg, "
                         f"where the interval's rotation vector wraps; give a shorter keyframe interval (step_s)")


class FactorGraphAligner(GraphSolver, AlignerBase):
    """Factor-graph fine alignment (method ``gtsam``): gtsam ImuFactors with earth-rate Coriolis,
    velocity factors from every reference sample and a bias with zero-mean priors, solved by
    Levenberg-Marquardt (docs/methods/gtsam.md). A smoother: each keyframe's estimate uses the
    whole record (the result's ``causal`` is False).

    Parameters
    ----------
    step_s : float
        The graph's step: the keyframe interval, s (default 1 s), rounded to a whole number of IMU samples.
    imu : str, path, IMUSpec or None
        The sensor model (a preset name, an IMU spec TOML file or an IMUSpec,
        :func:`fusionbench.simulation.imu.load_spec`; default the ``navigation`` preset) from which the white-noise
        densities, the bias priors and the bias random walk come (:func:`noise_model`); its noise schedules are not
        used (a change of noise level is what :class:`AdaptiveFactorGraphAligner` estimates). An IMU whose gyro bias
        hides the earth rate is refused (:func:`fusionbench.methods.claims.check_azimuth_observable`). None:
        seed000's white noise, bias priors 0.1 deg/h and 100 ug, a constant bias. Its name is
        reported as the result's ``imu_model``.
    gyro_noise : float or (3,) float, optional
        Gyro white-noise density (angle random walk), rad/sqrt(s); overrides the model's.
    accel_noise : float or (3,) float, optional
        Accelerometer white-noise density (velocity random walk), m/s/sqrt(s); overrides the model's.
    gyro_bias_sigma : float or (3,) float, optional
        Sigma of the zero-mean gyro-bias prior, rad/s, body axes; overrides the model's. Not smaller
        than the sensor's bias (docs/methods/gtsam.md, "The IMU model").
    accel_bias_sigma : float or (3,) float, optional
        Sigma of the zero-mean accelerometer-bias prior, m/s^2; overrides the model's.
    vref_sigma : float
        Noise of one velocity row without its own sigma (``Aiding.sigma_v``), m/s, each ENU axis, independent
        between rows (or of the zero velocity at each increment end without aiding); floored at 1 mm/s (an exact
        reference), like the rows' own. A scenario gives the graph its reference's noise. A keyframe's velocity
        factor holds the n rows of its tile: ``vref_sigma / sqrt(n)`` (docs/methods/gtsam.md).
    position_sigma : float
        Sigma of the loose position prior on the first keyframe, m, without position rows (it only fixes the
        otherwise free position).
    aiding_position_sigma : float
        Noise of one position row without its own sigma (``Aiding.sigma_p``), m, each ENU axis (default 1 m:
        :data:`baselines.graph_aiding.POSITION_SIGMA`, a single-frequency GNSS fix with SBAS).
    integration_sigma : float
        gtsam's integration noise density (position), m/sqrt(s); small.
    bias_interval_s : float, optional
        When the model's bias walks (``random_walk`` or ``instability``), the bias is piecewise
        constant over intervals of this length, s, tied by random-walk factors (default 30 s);
        otherwise one constant bias.
    max_iterations : int
        Levenberg-Marquardt iteration limit. When it is reached from a given ``init``, the
        recording is solved again from the coarse alignment and the solution of lower cost kept.
    recompensate_rad : float
        Retake the rows' lever-arm terms and the turn of ENU, and on a moving base recompensate the transport rate
        (the preintegration is redone only where the compensation matters: angle moved times compensation above
        1e-9 m/s^2), when the optimised attitude moved by more than this (rad) since they were taken; the default
        of ``relinearize_rad``.
    relinearize_rad : float, optional
        Rebuild the graph, its row factors linearised at the solution, until the attitude moves by less than this
        (rad) between builds; default ``recompensate_rad``. Where the heading is barely observable (a tactical
        gyro at high latitude) the answer depends on where the last linearisation was, by arcminutes; 3e-6 (0.01
        arcmin) with ``max_passes=30`` lands on the minimum of the rows' own nonlinear factors, whatever the start
        (docs/methods/gtsam.md, "Passes").
    max_passes : int
        At most this many graph builds per recording (the robust variant: at least 10, for its
        reweighting).
    marginals : bool
        Compute ``sigma_phi`` and ``extra["sigma_phi_noise"]``.
    huber_k : float
        Huber threshold, in sigmas, of the robust variant.
    coarse : object, optional
        Aligner used when ``init`` is None (default :class:`fusionbench.methods.coarse.InertialCoarseAligner`,
        which works on a swaying base).
    init_sigma_deg : float or (3,) float, optional
        Sigma of a prior on the attitude of ``init`` at the first keyframe, misalignment E, N, U, deg
        (what a Kalman filter's initial covariance says: ``(1, 1, 5)`` is the Kalman aligner's
        default). None (default): no prior, ``init`` is only where the solve starts (it may be 180 deg
        off). Where the east gyro bias's limit is large (tactical grade), the prior decides how the
        inseparable heading and bias share it.
    """

    positive_options = ("step_s", "position_sigma", "aiding_position_sigma", "integration_sigma", "max_iterations",
                        "max_passes", "huber_k")

    name = "gtsam"
    uses_aiding = True
    description = ("factor-graph fine alignment (gtsam ImuFactors, earth-rate Coriolis, every aiding row against the "
                   "IMU's velocity or position at its time, bias priors from the IMU model)")
    robust = False
    # sway (conformance, 20 runs; gtsam-robust and gtsam-adaptive alike): seed 000's (Zhou 2011, ADRC gyrocompass) case
    # 1.21, the mild sway 0.81-1.13, the Table-1 sway at 60, 75, 80 N 1.07, 0.77, 1.05 (1.60 at 60 N before
    # tangent_rates); tactical gyros (up to
    # 0.149 of the horizontal earth rate in the matrix) on a fixed base: static 0.88-0.93 (4.88 at 60 N before the
    # tiles held the IMU's own noise), swaying 0.80-1.44 with the levels on the bias limit (the sway separates the
    # accelerometer biases); not on a moving base (the tactical drive's levels at 0.95-1.0 of their tolerance;
    # docs/open-claims.md)
    # aiding: a car's 300-s drive with turns at 34 N and 60 N, navigation grade at 50 Hz, 6 runs each, rows of
    # 0.05 m/s or 0.5 m: velocity at 1, 0.5, 0.2, 0.1 Hz, azimuth rms 2.1, 2.6, 6.3, 10.2 arcmin (marginal sigma 2.6,
    # 3.5, 5.6, 8.0; 0.05 Hz 5.9 against 12); position only at 1, 0.2, 0.1 Hz 2.1, 2.9, 3.3 (2.5, 4.4, 5.9); outages
    # of 60, 100, 140 s from 150 s in 10-Hz velocities 0.9, 0.8, 0.8 (1.0, 1.1, 1.2), in 1-Hz positions 1.8, 1.9,
    # 1.8 (2.7, 3.0, 3.4); every axis within its sigma (rms of error over sigma 0.5 to 1.5)
    supports = Supports(bases=("static", "sway", "moving"), max_abs_lat_deg=80.0, max_bias_ratio=0.15,
                        max_bias_ratio_moving=0.05, aiding=("velocity", "position"), min_aiding_hz=0.1,
                        max_outage_s=140.0)
    #: Highest abs(latitude) accepted, deg: the horizontal earth rate W cos(L) that sets the heading vanishes at the
    #: poles.
    max_latitude_deg = 89.0
    #: Keys of the per-recording extras that are the same for every recording (kept once).
    _shared_extra = ("adapt_window_t",)

    def __init__(self, step_s=1.0, imu="navigation", gyro_noise=None, accel_noise=None, gyro_bias_sigma=None,
                 accel_bias_sigma=None, vref_sigma=0.01, position_sigma=1.0, integration_sigma=1e-6,
                 bias_interval_s=None, max_iterations=100, recompensate_rad=1e-3, max_passes=3, marginals=True,
                 huber_k=1.345, coarse=None, init_sigma_deg=None, aiding_position_sigma=POSITION_SIGMA,
                 relinearize_rad=None):
        if not (isinstance(vref_sigma, (int, float)) and np.isfinite(vref_sigma) and vref_sigma >= 0):
            raise ValueError(f"vref_sigma: expected a non-negative standard deviation in m/s, found {vref_sigma!r}")
        vref_sigma = max(float(vref_sigma), VREF_SIGMA_FLOOR)  # an exact reference: a well-conditioned factor
        positive = dict(step_s=step_s, vref_sigma=vref_sigma, position_sigma=position_sigma,
                        aiding_position_sigma=aiding_position_sigma,
                        integration_sigma=integration_sigma, recompensate_rad=recompensate_rad,
                        relinearize_rad=recompensate_rad if relinearize_rad is None else relinearize_rad,
                        huber_k=huber_k,
                        bias_interval_s=30.0 if bias_interval_s is None else bias_interval_s)
        for key, val in positive.items():
            setattr(self, key, self._positive(key, val))
        self.spec = None if imu is None else load_spec(imu)
        model = noise_model(self.spec)
        self.imu = self.spec
        self.imu_model = model.pop("name")
        given = dict(gyro_noise=gyro_noise, accel_noise=accel_noise, gyro_bias_sigma=gyro_bias_sigma,
                     accel_bias_sigma=accel_bias_sigma)
        for key, val in given.items():
            if val is not None:
                val = np.broadcast_to(self._positive(key, val), (3,))
            setattr(self, key, _scalar_or_axes(model[key] if val is None else val))
        self.gyro_bias_walk, self.accel_bias_walk = model["gyro_bias_walk"], model["accel_bias_walk"]
        for key, val in (("max_iterations", max_iterations), ("max_passes", max_passes)):
            if int(val) != val or val < 1:
                raise ValueError(f"{key}: expected a positive integer, found {val}")
        self.max_iterations, self.max_passes = int(max_iterations), int(max_passes)
        self.marginals = bool(marginals)
        self.init_sigma = None if init_sigma_deg is None else np.radians(np.broadcast_to(
            self._positive("init_sigma_deg", init_sigma_deg), (3,)))
        self.coarse = InertialCoarseAligner() if coarse is None else coarse
        #: Shortest record, s: three keyframe intervals, and what the coarse initialisation needs.
        self.min_duration_s = max(3.0 * self.step_s, float(getattr(self.coarse, "min_duration_s", 0.0)))

    @staticmethod
    def _positive(key, val):
        try:
            arr = np.asarray(val, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{key}: expected a positive number, found {val!r}") from None
        if arr.ndim > 1 or arr.size not in (1, 3) or not (np.all(np.isfinite(arr)) and np.all(arr > 0)):
            raise ValueError(f"{key}: expected a positive number, found {val!r}")
        return float(arr) if arr.ndim == 0 else arr

    def estimate_only(self):
        """This aligner without the marginal covariances (``marginals=False``): the same attitudes, a third
        cheaper, for the runner's settling of a smoother (:func:`fusionbench.bench.runner._prefix_settling`), which
        reads only the final attitude of each prefix."""
        lean = copy.copy(self)
        lean.marginals = False
        return lean

    # ------------------------------------------------------------------------------------- align
    def _align(self, imu: IMUData, site: Site, aiding, init) -> AlignmentResult:
        """Align every recording of ``imu`` by factor-graph smoothing, from any heading.

        Parameters
        ----------
        imu : IMUData
            R recordings, body frame RFU (increments or rates).
        site : Site
            Latitude (|lat| <= 89 deg), longitude, height.
        aiding : fusionbench.simulation.aiding.Aiding, optional
            Velocity and/or position rows for the R recordings, each used at its time of validity with the lever
            arm (docs/methods/gtsam.md); a row without its own sigma has ``vref_sigma`` (velocity) or
            ``aiding_position_sigma`` (position). None: a fixed base (zero velocity at every increment end).
        init : ndarray, shape (R, 3, 3) or (3, 3), optional
            Initial guess of ``C_bn`` at the first keyframe (the initial state, ``imu.t0``), carried
            to the other keyframes with the gyros; any heading (from 180 deg off, LM needs about 70
            iterations instead of 5). None: the coarse stage (``self.coarse``) gives the attitude at
            the last sample, carried back to the start with the gyros.

        Returns
        -------
        AlignmentResult
            ``t`` (K,) keyframe times, s (the last one the last sample); ``C_bn`` (R, K, 3, 3) the
            optimised attitude at the keyframes, each from the whole record (``causal`` False);
            ``sigma_phi`` (with ``marginals``) and ``extra["sigma_phi_noise"]`` (R, K, 3) marginal misalignment
            sigmas, rad, ENU (with the bias priors; with the biases known); ``extra``: ``gyro_bias`` (R, 3) rad/s
            and ``accel_bias`` (R, 3) m/s^2, the estimated biases at the last keyframe, body frame; ``iterations``,
            ``passes`` (R,) ints (LM iterations, graph builds); ``restarted`` (R,) bool (solved again from the
            coarse alignment); ``graph_error`` (R,), the final cost; ``step_s``; ``imu_model``
            the IMU model's name (``"default"`` without one).

        Raises
        ------
        ValueError
            Naming the field: beside the input policy of :class:`fusionbench.methods.aligner_base.AlignerBase` (latitude
            beyond 89 deg, a record shorter than ``min_duration_s``, aiding outside the record, a bad ``init``,
            non-finite samples), a keyframe interval shorter than the sample interval, a record that turns by half a
            turn or more within one keyframe interval (the interval's rotation vector would wrap: give a shorter
            ``step_s``).
        """
        if self.step_s < imu.dt:
            raise ValueError(f"{self.name}: step_s: expected a keyframe interval of at least the sample interval "
                             f"{imu.dt:g} s, found {self.step_s:g} s")
        init = None if init is None else orthonormalize(init)
        t_end, dth, dvel = imu.increments()
        M, dt, R = t_end.size, imu.dt, imu.runs
        counts = keyframe_counts(M, max(1, int(round(self.step_s / dt))))
        K = counts.size
        t_kf = np.concatenate([[imu.t0], t_end[counts[1:] - 1]])
        _check_turn_per_interval(self.name, dth, counts, t_kf)
        T = np.diff(counts) * dt
        seg, walk = self._bias_segments(t_kf)
        warm = self._warm_runs(imu)  # a prefix of the record a prefix aligner solved: start from its solution
        coarse_final = None if (init is not None or warm) else self.coarse.align(imu, site, aiding=aiding).C_bn_final

        C_out = np.empty((R, K, 3, 3))
        sig, sig_noise = np.full((R, K, 3), np.nan), np.full((R, K, 3), np.nan)
        bg, ba = np.empty((R, 3)), np.empty((R, 3))
        iters, passes, cost = np.zeros(R, int), np.zeros(R, int), np.empty(R)
        restarted = np.zeros(R, bool)
        per_run, kept = [], []
        differenced = None
        if aiding is not None and aiding.has_position:  # heights not measured: no vertical velocity (a level drive)
            differenced = replace(aiding, position=np.where(np.isnan(aiding.position) & (np.arange(3) == 2), site.h,
                                                            aiding.position)).velocities_from_positions()
        for r in range(R):
            rows = recording_rows(aiding, r, t_end, site, self.vref_sigma, self.aiding_position_sigma)
            diff = None if differenced is None else {"t": differenced.t_valid, "W": np.isfinite(
                differenced.velocity[r]).astype(float), "z": np.nan_to_num(differenced.velocity[r])}
            problem = build_problem(rows, site, t_end, t_kf, counts, dt, dth[r], dvel[r],
                                    None if (init is None or self.init_sigma is None) else init[r], diff)
            problem.update(seg=seg, walk=walk)
            if warm:
                C_start, values, pims = self._warm_start(warm[r], counts, seg)
                if pims is not None:  # the record's intervals: its gyro rates too (each interval's its own)
                    problem["gyr"] = warm[r][3][:counts[-1]]
                sol = self._solve(problem, C_start, values=values, pims=pims)
            else:
                _, dR = _interval_rotations(problem["phi"], counts, None)
                start = init[r] if init is not None else orthonormalize(coarse_final[r])
                sol = self._solve(problem, _propagate(start, dR, problem["w_in"], T, forward=init is not None))
                if init is not None and not sol[5]:
                    # LM stopped at its iteration limit from the given guess: start again from the coarse
                    # alignment and keep the better solution
                    if coarse_final is None:
                        coarse_final = self.coarse.align(imu, site, aiding=aiding).C_bn_final
                    other = self._solve(problem, _propagate(orthonormalize(coarse_final[r]), dR, problem["w_in"], T,
                                                            forward=False))
                    restarted[r] = True
                    spent = sol[3] + other[3]
                    if other[0].error(other[1]) < sol[0].error(sol[1]):
                        sol = other
                    sol = sol[:3] + (spent,) + sol[4:]
            if problem["refine_motion"]:  # rows not at every sample: the compensation from the solution's motion
                C, t, v, b = keyframe_states(sol[1], K, seg)
                problem = motion_from_solution(problem, site, C, v, t, b)
                again = self._solve(problem, sol[2], values=sol[1], imu_scale=None)
                sol = again[:3] + (sol[3] + again[3], sol[4] + again[4]) + again[5:]
            sol, more = self._refine(problem, sol)
            per_run.append(more)
            if r < self._keeps:
                kept.append((counts, sol[1], sol[8], problem["gyr"]))
            graph, values, C_kf, iters[r], passes[r] = sol[:5]
            cost[r] = graph.error(values)
            C_out[r] = C_kf
            bias = values.atConstantBias(B(int(seg.max())))
            bg[r], ba[r] = bias.gyroscope(), bias.accelerometer()
            if self.marginals:
                sig[r], sig_noise[r] = marginal_sigmas(graph, values, C_kf, [B(j) for j in range(int(seg.max()) + 1)])
        extra = {"sigma_phi_noise": sig_noise, "gyro_bias": bg, "accel_bias": ba,
                 "iterations": iters, "passes": passes, "restarted": restarted, "graph_error": cost,
                 "step_s": self.step_s}
        if self._keeps:  # prefixes of this record are to be aligned: keep its solution to start them from
            self._solved = (imu, kept)
        for key in (per_run[0] if per_run else {}):
            stacked = np.stack([m[key] for m in per_run])
            extra[key] = stacked[0] if key in self._shared_extra else stacked
        return AlignmentResult(self.name, t_kf, C_out, extra, sigma_phi=sig if self.marginals else None,
                               imu_model=self.imu_model, causal=False)


class RobustFactorGraphAligner(FactorGraphAligner):
    """Factor-graph fine alignment with Huber-robust velocity factors (method ``gtsam-robust``).

    The graph of :class:`FactorGraphAligner`, but each keyframe's velocity factor is weighted by
    Huber's M-estimator on the norm of its whitened error (iteratively reweighted, at most 10 graph
    builds): reference-velocity outliers (noise bursts, base motion the reference does not see)
    weigh linearly rather than quadratically beyond ``huber_k`` sigmas (default 1.345, 95 %
    efficiency on Gaussian noise). Parameters as for :class:`FactorGraphAligner`. On data whose
    velocity errors stay inside the threshold it gives the same result. It keeps its use for
    outliers: 1 % of the samples of paper001-moving-base 3 m/s off leave it at 1.1 arcmin of
    azimuth where gtsam has 2.0 and gtsam-adaptive 1.7 (8 runs). A change of noise level (all
    samples noisier, none an outlier) is :class:`AdaptiveFactorGraphAligner`'s, although a x100
    variance jump puts a keyframe's errors so many sigmas out that the Huber weight helps there too.
    """

    name = "gtsam-robust"
    description = "factor-graph fine alignment with Huber-robust velocity factors (gtsam)"
    robust = True


def __getattr__(name):
    """``baselines.factor_graph.AdaptiveFactorGraphAligner``, its home until the graph family was split: still
    importable from here, with a DeprecationWarning."""
    if name == "AdaptiveFactorGraphAligner":
        import importlib
        import warnings

        warnings.warn("baselines.factor_graph.AdaptiveFactorGraphAligner moved to baselines.graph_adaptive",
                      DeprecationWarning, stacklevel=2)
        # looked up when the old name is used, not imported with this module: graph_adaptive builds on this one
        return importlib.import_module("baselines.graph_adaptive").AdaptiveFactorGraphAligner
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
