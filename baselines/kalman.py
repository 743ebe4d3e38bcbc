"""Kalman fine alignment and its innovation-adaptive variant.

After a coarse alignment (or from the scenario's initial guess), the shared strapdown runs on the IMU increments and
an error-state filter per run (:mod:`baselines.kalman_filter`: the 11-state psi-angle model, 13 with the position
errors when the aiding measures positions) predicts every ``step_s`` and updates with the aiding rows valid in the
step, each at its own time of validity, with the lever arm in the measurement model (:mod:`baselines.kalman_aiding`);
between rows (outages, 1-Hz rows) it only predicts. Without aiding it measures the zero velocity of a fixed base at
every step. The filters of all runs step together in a :class:`baselines.filter_bank.FilterBank` (filterpy's
arithmetic on arrays over runs, or ``engine="filterpy"``, one :class:`filterpy.kalman.KalmanFilter` per run, the
reference).

Without an initial guess the fine stage starts at the record's start from the coarse attitude carried back there (on
a fixed base when that attitude is within the filter's linear range, else at the hand-over), with the velocity (and
position) the aiding gives at the start (:func:`baselines.kalman_aiding.initial_motion`: rows interpolated or
positions differenced, the lever arm's term removed), its initial covariance as good as that is, and reports from
the hand-over on.

Stationary-base limits: the filter cannot separate the horizontal accelerometer biases from tilt nor
the east gyro bias from azimuth, so it lands on :func:`fusionbench.scoring.metrics.theoretical_limits`.

:class:`AdaptiveKalmanAligner` (``akf``) adds innovation-based adaptation for noise that changes:
Sage-Husa estimation of R with a fading factor, and covariance matching of the innovations to inflate
the predicted covariance when they exceed what P and R explain (a stand-in for a Q that grew).
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.aligner import AlignmentResult, Site
from fusionbench.methods.aligner_base import AlignerBase, coarse_then_fine
from fusionbench.methods.claims import Supports, azimuth_bias_ratio
from fusionbench.methods.coarse import InertialCoarseAligner
from fusionbench.methods.init_check import COARSE_NOISE_DEG, coarse_error_deg
from fusionbench.simulation.imu import load_spec
from fusionbench.simulation.strapdown import NavState, Strapdown

from .filter_bank import ENGINES, FilterBank
from .kalman_aiding import CHANNELS, attitude_at_start, initial_motion, prepare_rows, zero_velocity_rows
from .kalman_filter import NX, FeedbackKalman

#: Floor of every measurement's standard deviation, m/s or m: an exact reference keeps the update well conditioned.
SIGMA_FLOOR = 1e-3
#: Largest coarse azimuth error (deg) the IMU model allows for which the fine stage on a fixed base re-runs the
#: record from its start (:meth:`KalmanAligner._align`), over the 60-s coarse stage: navigation grade 0.3-1.5 deg at
#: 0-80 deg of latitude, seed 000's (Zhou 2011, ADRC gyrocompass) IMU 0.6-1.3 up to 60 deg (2.4 at 75); tactical grade
#: 16-93, the README's bench FOG
#: 8.6.
RERUN_MAX_DEG = 2.0


class KalmanAligner(AlignerBase):
    """Kalman fine alignment (method ``kf``) on filterpy, feedback-corrected strapdown.

    Parameters
    ----------
    step_s : float
        Filter step, s (0.1: 10 Hz), rounded to a whole number of IMU samples: the interval of its predictions
        and updates.
    imu : str, path or IMUSpec
        Noise model of the filter (:func:`fusionbench.simulation.imu.load_spec`): a preset name, an IMU spec TOML
        file or an IMUSpec; default the ``navigation`` preset. Its white noises give Q; its bias sigmas
        (fixed part taken as a sigma too) the initial bias covariance, floored so that the prior is never
        tight (a tight gyro-bias prior biases the tilt). The result's ``imu_model`` names it.
    vref_sigma : float
        Standard deviation of each velocity row that has none of its own (east and north), m/s, and of the zero
        velocity of a fixed base without aiding (every sigma floored at 1 mm/s, so that an exact reference keeps
        the update well conditioned). A scenario gives a method with this option the noise of its reference
        (:func:`fusionbench.methods.aligner.load_method`); 0.05 m/s by default, the disturbance of a vehicle at rest.
    att_sigma_deg : (3,) float
        Initial misalignment standard deviations [E, N, U] after the initialisation, deg. ``None`` for U (the
        default): 5 deg, or three times the azimuth error the IMU model's gyro bias allows at the site
        (asin(bias / (earth rate cos L))) when that is larger: a prior tighter than the coarse start's real error
        makes the filter overconfident (a tactical gyro at 60 deg: 7.4 deg of limit alone).
    coarse_s : float
        Length of the inertial-frame coarse alignment when no initial guess is given, s.
    engine : {"numpy", "filterpy"}
        The filters of all runs on arrays (default), or one filterpy KalmanFilter per run (the reference:
        the same estimates to rounding, several times slower).
    aiding_position_sigma : float
        Standard deviation of each position row that has none of its own (east and north), m. 2 m by default: a
        single-frequency receiver's fix without corrections (1-3 m per horizontal axis), on the large side because
        its errors (ionosphere, multipath) stay correlated for minutes, which rows of white noise understate.
    """

    name = "kf"
    uses_aiding = True
    # moving (conformance matrix, 20 runs, seeds 0/1/2, efficiency about the optimal estimator's bias limit): the
    # 0.1 g base 0.66-1.37 (1.09-1.66 with one reference row in five and no mean offset either way); a car's drive
    # with turns 0.70-1.39 with velocity at 10 or 1 Hz, position only at 1 Hz, a 60-s outage, a 1.5-m lever arm,
    # 50 ms of latency; tactical gyros (1 deg/h, up to 0.149 of the horizontal earth rate in the matrix) on a fixed
    # base 0.68-1.01 since F is formed at gravity's reaction there (1.54-2.11 before), not on a moving one: on the
    # tactical drive its levels end at 0.94-0.99 of their tolerance (docs/open-claims.md)
    supports = Supports(bases=("static", "sway", "moving"), max_abs_lat_deg=89.0, max_bias_ratio=0.15,
                        max_bias_ratio_moving=0.05, aiding=("velocity", "position"), min_aiding_hz=1.0,
                        max_outage_s=60.0)
    max_latitude_deg = 89.0
    # a given init (yaw off; static, 34 N, navigation, 300 s): up to 45 deg recovered to the undisturbed 0.4-3.9
    # arcmin, 60 deg left 4-7, 90 deg 17-20, 180 deg 8-11 deg
    init_capture_deg = 30.0
    description = ("Kalman fine alignment (11-state psi-angle model, 13 with positions; aiding rows at their valid "
                   "times, lever arm; filterpy arithmetic batched over runs, feedback), coarse start")

    def __init__(self, step_s=0.1, imu="navigation", vref_sigma=0.05, att_sigma_deg=(1.0, 1.0, None), coarse_s=60.0,
                 engine="numpy", aiding_position_sigma=2.0):
        if engine not in ENGINES:
            raise ValueError(f"{self.name}: option engine: expected one of {ENGINES}, found {engine!r}")
        self.engine = engine
        self.step_s = float(step_s)
        if not (np.isfinite(self.step_s) and self.step_s > 0):
            raise ValueError(f"{self.name}: option step_s: expected a positive filter step in s, found {step_s!r}")
        self.spec = load_spec(imu)
        self.vref_sigma = float(vref_sigma)
        if not (np.isfinite(self.vref_sigma) and self.vref_sigma >= 0):
            raise ValueError(f"{self.name}: option vref_sigma: expected a non-negative standard deviation in m/s, "
                             f"found {vref_sigma!r}")
        self.aiding_position_sigma = float(aiding_position_sigma)
        att = list(np.broadcast_to(np.asarray(att_sigma_deg, dtype=object), (3,)))
        self._att_sigma_u = att[2]
        self.att_sigma = np.radians([float(att[0]), float(att[1]), 5.0 if att[2] is None else float(att[2])])
        self.coarse_s = float(coarse_s)
        self.min_duration_s = self.coarse_s + 10.0

    def events(self, init_given):
        """Stages for the figures (:mod:`fusionbench.reports.figures`): the hand-over from the own coarse alignment at
        ``coarse_s`` (s), when no initial attitude is given."""
        return [] if init_given else [(self.coarse_s, "coarse -> fine hand-over")]

    # ---------------------------------------------------------------- noise model
    def _qc(self):
        g, a = self.spec.gyro, self.spec.accel
        q = np.zeros(NX)
        q[0:3] = np.square(g.white)
        q[3:5] = np.square(a.white)[:2]
        q[5:8] = np.square(g.bias_walk())
        q[8:11] = np.square(a.bias_walk())
        return q

    def _p0(self, lat=None, sigma_v=(0.1, 0.1), sigma_p=None):
        """Initial covariance (11,) or (13,): attitude, velocity (``sigma_v`` (2,) m/s), body-frame biases, and the
        position (``sigma_p`` (2,) m) when given; ``lat`` (rad) sets the default azimuth prior from the gyro bias
        (``att_sigma_deg``)."""
        eps, nab = self.spec.bias_prior_sigma()
        att = self.att_sigma.copy()
        if self._att_sigma_u is None and lat is not None:
            ratio = min(1.0, azimuth_bias_ratio(self.spec, lat))
            att[2] = min(max(att[2], 3.0 * np.arcsin(ratio)), np.radians(60.0))
        return np.concatenate([att, np.broadcast_to(sigma_v, (2,)), eps, nab] +
                              ([] if sigma_p is None else [np.broadcast_to(sigma_p, (2,))])) ** 2

    def _new_bank(self, runs, P0):
        return FilterBank(runs, P0, engine=self.engine)

    def _q_scale(self, bank):
        """Factor (R,) on Q in the next prediction (1; the adaptive variant inflates it)."""
        return 1.0

    def _update(self, bank, z, H, r, chan, k):
        """Measurement update k with z (R, q), H (R, q, nx) and the channels' variances r (q,) (of
        :data:`baselines.kalman_aiding.CHANNELS` ``chan`` (q,)); the adaptive variant adapts R and Q first."""
        bank.update(z, H, np.diag(r))

    # ---------------------------------------------------------------- alignment
    def _align(self, imu, site: Site, aiding, init) -> AlignmentResult:
        """Align R recordings (body RFU increments, aiding rows or None): from ``init``, or after an inertial-frame
        coarse alignment over the first ``coarse_s`` seconds; the velocity (and position) at the fine stage's start
        from the aiding there (:func:`baselines.kalman_aiding.initial_motion`).

        The fine stage re-runs the coarse stage's span: it starts at the record's start from the coarse attitude
        carried back there (:func:`baselines.kalman_aiding.attitude_at_start`) and reports from the hand-over on, so
        that the filter has every row and sample from the start. On a car drive its sigma was 1.14 (10-Hz velocity)
        to 1.28 (1-Hz velocity) times the optimal estimator's when it started at the hand-over, 1.01-1.03 from the
        start; on a fixed base its first attitude carried the coarse stage's level (27 arcmin RMS, navigation grade,
        60 s) and a prior-sized sigma, and seed 000's case settled in 136 s (74 s from the start). On a fixed base it
        does so only when the coarse azimuth is within the filter's linear range: the error the IMU model allows the
        coarse stage (:func:`fusionbench.methods.init_check.coarse_error_deg` less its allowance for sway and rows)
        within :data:`RERUN_MAX_DEG`; beyond it the record's first minute, filtered from degrees off, cost more than
        it gave (a tactical IMU under seed 000's sway at the equator, 20 runs: 0.77 attainable bounds from the start,
        0.68 from the hand-over)."""
        t, dth, dv = imu.increments()

        def fine(rest, rows, C0, t_start, k, after=None):  # k: the increment at the start (its body rate)
            motion = initial_motion(aiding, t_start, C0, dth[:, k] / imu.dt, site.lat, imu.runs,
                                    max(self.vref_sigma, SIGMA_FLOOR), max(self.aiding_position_sigma, SIGMA_FLOOR),
                                    float(np.sqrt(np.max(self._p0(site.lat)[:3]))))
            return self._fine(rest, site, rows, C0, motion, imu.dt, aiding is None, after,
                              fixed_base=aiding is None or aiding.is_at_rest())

        if init is not None:
            return fine(imu, aiding, init, imu.t0, 0)
        coarse = InertialCoarseAligner(history_points=20, caller=self.name)
        k0 = int(round(self.coarse_s / imu.dt))
        if (aiding is None or aiding.is_at_rest()) and \
                coarse_error_deg(self.spec, site.lat, self.coarse_s) - COARSE_NOISE_DEG > RERUN_MAX_DEG:
            return coarse_then_fine(imu, site, aiding, coarse, self.coarse_s,
                                    lambda rest, aid, C0, t_hand: fine(rest, aid, C0, t_hand, k0 - 1))

        def rerun(rest, aid, C0, t_hand):
            C_start = attitude_at_start(C0, dth[:, :k0], dv[:, :k0], imu.dt, site, aiding, imu.t0, t_hand)
            return fine(imu, aiding, C_start, imu.t0, 0, after=t_hand)
        return coarse_then_fine(imu, site, aiding, coarse, self.coarse_s, rerun)

    def _fine(self, imu, site, aiding, C0, motion, dt, fixed, after=None, fixed_base=False) -> AlignmentResult:
        """The filter around the feedback-corrected strapdown from attitude ``C0`` (R, 3, 3) and ``motion`` (velocity,
        its sigma, position or None, its sigma: :func:`baselines.kalman_aiding.initial_motion`), on the rows of
        ``aiding`` (None: no row, prediction only), or the zero velocity of a fixed base when ``fixed`` (no aiding
        at all), with sample interval ``dt`` (s); the history after ``after`` (s) only, when given. On a
        ``fixed_base`` (no aiding, or rows at rest) the accelerometer bias states are navigation-frame ones
        (:mod:`baselines.kalman_filter`)."""
        t, dth, dv = imu.increments()
        R, N, _ = dth.shape
        v0, sigma_v0, p0, sigma_p0 = motion
        m = max(1, int(round(self.step_s / dt)))
        T = m * dt  # the filter's update interval: step_s in whole samples
        steps = N // m
        tail = N - steps * m  # samples after the last filter step, integrated at the end (time rule)
        sigma_v = max(self.vref_sigma, SIGMA_FLOOR)
        if fixed:
            rows = zero_velocity_rows(np.arange(1, steps + 1) * m - 1, R, sigma_v)
        else:
            rows = prepare_rows(aiding, t, imu.t0, R, sigma_v, self.aiding_position_sigma, SIGMA_FLOOR)
        rows.before_end(t, m)
        position = rows.has_position
        lat, lon, h = (site.lat, site.lon, site.h) if p0 is None else \
            (p0[:, 0], p0[:, 1], np.where(np.isfinite(p0[:, 2]), p0[:, 2], site.h))  # rows without a height: the site's
        sd = Strapdown(NavState.broadcast(R, C0, v0, lat, lon, h), dt, height_fixed=True)
        P0 = self._p0(site.lat, sigma_v0, sigma_p0 if position else None)
        kf = FeedbackKalman(sd, self._new_bank(R, P0), self._qc(), T, dt, self._q_scale, self._update,
                            fixed_base=fixed_base)
        out_t = np.empty(steps + (tail > 0))
        out_C = np.empty((R, steps + (tail > 0), 3, 3))
        out_s = np.empty((R, steps + (tail > 0), 3))
        for j in range(steps):
            a, b = j * m, (j + 1) * m
            out_s[:, j] = kf.step(dth[:, a:b], dv[:, a:b], rows, rows.span(a, b), a)
            out_t[j] = t[b - 1]
            out_C[:, j] = sd.state.C_bn
        if tail:  # the last samples, through the bias-compensated strapdown without an update
            kf.coast(dth[:, N - tail:], dv[:, N - tail:])
            out_t[-1], out_C[:, -1], out_s[:, -1] = t[-1], sd.state.C_bn, out_s[:, -2] if steps else np.nan
        keep = slice(None) if after is None else out_t > after
        return AlignmentResult(self.name, out_t[keep], out_C[:, keep],
                               {"gyro_bias": kf.eps_hat, "accel_bias": kf.nab_hat}, sigma_phi=out_s[:, keep],
                               imu_model=self.spec.name)


class AdaptiveKalmanAligner(KalmanAligner):
    """Innovation-adaptive Kalman alignment (method ``akf``).

    Each channel q of an update (the step's velocity east and north, position east and north: the means of its rows,
    :mod:`baselines.kalman_aiding`) has a nominal variance ``r_q``, a prior ``HPH_q = (H P^- H^T)_qq`` and an
    innovation ``nu_q``:

    * R by Sage-Husa with fading factor ``b``, a factor ``lambda_q`` on the nominal variance of each channel:
      ``lambda_q <- (1 - d_k) lambda_q + d_k (nu_q^2 - HPH_q) / r_q``, ``d_k = (1 - b) / (1 - b^(k+1))``, floored at
      ``r_floor``; R diagonal, ``lambda_q r_q`` (the channels' noises are independent; a full form can turn R
      indefinite once floored). With a constant nominal R this is the Sage-Husa estimate of R itself. A channel
      whose prior exceeds its nominal noise (``HPH_q > r_q``: the first updates, the first row after an outage or a
      second of 1-Hz rows) is not adapted: its innovation is mostly the state's error, and ``nu^2 - HPH`` there
      floored R at ``r_floor`` (on a drive with 1-Hz rows akf ended 2.6-3.2 bounds off, 0.8-1.2 with this).
    * Q by covariance matching: over the last ``window`` updates the mean of ``sum_q nu_q^2 / r_q`` is compared with
      the current ``sum_q (R_q + HPH_q) / r_q`` (per kind of measurement); the ratio ``(mean - sum_q R_q / r_q) /
      sum_q HPH_q / r_q`` (``tr(C - R) / tr(H P^- H^T)`` with a constant nominal R), bounded to [1,
      ``max_inflation``] and smoothed over the window, scales Q in the next predictions. (Scaling P^- itself runs
      away here: the unobservable azimuth and bias directions grow without bound.)
    """

    name = "akf"
    # as kf, and up to 80 deg: under seed 000's sway at 75 deg its adaptation left 1.95 bounds (kf 1.02) until the
    # scenario's reference noise reached it; since then 0.73-0.97 at 75 N, 1.27 at 80 N (0.82 on the mild sway at
    # 80 S; conformance, 20 runs); moving (20 runs, seeds 0/1/2): the 0.1 g base
    # 0.75-1.59 (1.59 on the 0.1-m/s reference at 45 S with seed 2, 1.09 and 1.16 with seeds 0 and 1), the drives
    # 0.76-1.39 (velocity at 10 or 1 Hz, position at 1 Hz, a 60-s outage, a lever arm, a latency); tactical gyros on
    # a fixed base as kf (0.68-1.01), not on a moving one (the tactical drive's levels 1.01 of their tolerance)
    supports = Supports(bases=("static", "sway", "moving"), max_abs_lat_deg=80.0, max_bias_ratio=0.15,
                        max_bias_ratio_moving=0.05, aiding=("velocity", "position"), min_aiding_hz=1.0,
                        max_outage_s=60.0)
    description = "innovation-adaptive Kalman alignment (Sage-Husa R, covariance-matched Q inflation)"
    # a given init (kf's conditions): 45 deg of yaw recovered to 1.1-1.9 arcmin but 0.6 of level (0.13 from the
    # truth), 90 deg to 3-6 arcmin, 180 deg left 178 deg
    init_capture_deg = 30.0

    def __init__(self, b=0.98, window=50, r_floor=0.1, max_inflation=100.0, imu="navigation", step_s=0.1,
                 vref_sigma=0.05, att_sigma_deg=(1.0, 1.0, None), coarse_s=60.0, engine="numpy",
                 aiding_position_sigma=2.0):
        # kf's options spelled out: a scenario gives its reference noise and IMU to the options it sees here
        # (fusionbench.methods.discovery.takes_option reads this signature; under **kw akf kept 0.05 m/s whatever the
        # noise)
        super().__init__(step_s=step_s, imu=imu, vref_sigma=vref_sigma, att_sigma_deg=att_sigma_deg, coarse_s=coarse_s,
                         engine=engine, aiding_position_sigma=aiding_position_sigma)
        self.b, self.window, self.r_floor = float(b), int(window), float(r_floor)
        self.max_inflation = float(max_inflation)

    def _new_bank(self, runs, P0):
        bank = super()._new_bank(runs, P0)
        bank.lam = np.ones((runs, len(CHANNELS)))  # factor on the nominal variance of each channel
        bank.innov = np.zeros((runs, self.window))  # the last `window` normalised innovation sums, a ring
        bank.count = 0
        bank.q_scale = np.ones(runs)
        return bank

    def _q_scale(self, bank):
        return bank.q_scale

    def _update(self, bank, z, H, r, chan, k):
        HPH = np.einsum("rqi,rij,rqj->rq", H, bank.P, H)  # (R, q): the diagonal of H P^- H^T
        nu = z - np.einsum("rqi,ri->rq", H, bank.x)
        kinds = chan.size / 2  # velocity, position: two channels each
        bank.innov[:, bank.count % self.window] = np.sum(nu**2 / r, axis=1) / kinds
        bank.count += 1
        # Sage-Husa R per channel, floored at a fraction of the nominal R
        d = (1 - self.b) / (1 - self.b ** (k + 1))
        d = np.where(HPH < r, d, 0.0)  # a channel whose prior exceeds its noise says little of R: not adapted
        bank.lam[:, chan] = np.maximum((1 - d) * bank.lam[:, chan] + d * (nu**2 - HPH) / r, self.r_floor)
        R_diag = bank.lam[:, chan] * r  # (R, q)
        # covariance matching: scale Q (for the next predictions) when the innovations exceed what
        # H P^- H^T + R explain; smoothed and bounded, so that P cannot run away
        if bank.count >= self.window:
            lam = np.clip((bank.innov.mean(axis=1) - np.sum(R_diag / r, axis=1) / kinds)
                          / (np.sum(HPH / r, axis=1) / kinds), 1.0, self.max_inflation)
            bank.q_scale = (1 - 1.0 / self.window) * bank.q_scale + lam / self.window
        bank.update(z, H, R_diag[:, :, None] * np.eye(chan.size))
