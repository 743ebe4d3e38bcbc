"""Factor-graph fine alignment on gtsam (methods ``gtsam``, ``gtsam-robust`` and ``gtsam-adaptive``).

Frames and conventions
----------------------
The navigation frame n is East-North-Up (ENU), the body frame b Right-Front-Up (x right, y
forward, z up). gtsam's ``PreintegrationParams.MakeSharedU(g)`` uses a z-up navigation frame with
gravity ``[0, 0, -g]``, which is ENU here, and its body frame is RFU, so a pose's rotation is the
attitude ``C_bn`` (body to ENU) and its translation the position in ENU metres from the start.
Misalignment ``phi = [phiE, phiN, phiU]`` (rad) is defined by ``C_bn_est = (I - [phi x]) C_bn_true``.
The graph is a smoother (the result's ``causal`` is False): every keyframe's estimate uses the whole record.

The graph (one per recording)
-----------------------------
Keyframes ``k = 0 .. K-1`` lie every ``step_s`` seconds (the graph's step) from the initial state ``imu.t0``;
the last keyframe is the last sample (the final interval is between 0.5 and 1.5 keyframe
intervals long). Each keyframe has a pose ``X(k)`` (``C_bn``, position) and a velocity ``V(k)``
(ENU, m/s); bias keys ``B(j)`` (accelerometer m/s^2, gyro rad/s, body frame). Factors:

* ``ImuFactor(X(k-1), V(k-1), X(k), V(k), B(j))`` from ``PreintegratedImuMeasurements`` between
  consecutive keyframes, built on ``MakeSharedU(g)`` with ``setOmegaCoriolis(omega_ie^n)``, the
  earth rate in ENU (plus the transport rate on a moving base, below). The navigation frame turns
  with the earth: without the Coriolis term gtsam would read the earth rate as a gyro bias and the
  heading (gyrocompassing, the whole point) would never move. The gyro and accelerometer
  white-noise densities of the IMU model set the preintegration covariance; the integration
  covariance is small. gtsam's tangent-space preintegration turns the interval's rotation to first order in each
  sample; the rates it is given are those that make it turn exactly as the samples do
  (:func:`baselines.graph_support.tangent_rates`: under seed 000's sway the first-order turn drifted alike on every
  interval and left the azimuth -4.2 arcmin off at 1-s keyframes, 3.3 deg at 2-s ones, on a perfect IMU).
* a tile factor of velocity, and one of position, on every keyframe with aiding rows nearest to it (its *tile*:
  the record split at the midpoints between keyframes; :mod:`baselines.graph_rows`, :mod:`baselines.graph_aiding`).
  Each row, valid at ``tau = t - delay`` anywhere between samples, is compared with what the IMU predicts there
  from the keyframe's state (the partial sample interpolated): ``V(k) + R(k) (U - Mb b_a)`` for a velocity,
  ``P(k) + V(k) (tau - t_k) + R(k) (U_p - Mb_p b_a)`` for a position, with ``U`` the velocity increments since the
  keyframe in its body frame (``U_p`` their integral), ``Mb`` what an accelerometer bias adds, and gravity and
  Coriolis since the keyframe taken from the row. The lever arm joins ``U``: ``C_{b_k}^{b(tau)} (omega_nb^b x l)``
  and ``C_{b_k}^{b(tau)} l`` (``R(k)`` times them is the antenna's offset), so the attitude Jacobian holds it; a row
  at rest has none. The factor holds the weighted means of its tile's rows per ENU axis (each row
  ``(vref_sigma / sigma_row)^2``, nothing on an axis it does not measure): any motion within a tile is followed (a
  mean of the rows against ``V(k)`` alone is biased by the velocity's curvature: 20 to 190 arcmin on a vehicle
  wobbling at 0.5 m/s rms, 0.1 to 2 Hz, with a perfect IMU and reference). A keyframe without rows (an outage,
  1-Hz rows on 0.5-s keyframes) has no such factor. The factors are linearised at the current solution (a
  ``LinearContainerFactor``, in C++) and rebuilt until the attitude moves by less than ``recompensate_rad``.
  Without aiding the base is fixed: a zero velocity at every increment end. ``vref_sigma`` is the noise of **one
  row**, independent between rows: a tile of n rows has ``vref_sigma / sqrt(n)``, plus what the IMU's own noise
  leaves in the prediction (:func:`baselines.graph_rows.tile_imu_variance`). In ``gtsam-robust`` each factor
  carries Huber weights (iteratively reweighted: 1 within ``huber_k`` sigmas of the whitened error's norm). With a
  perfect IMU and exact rows the final attitude is exact to 1e-4 arcmin on a car's drive with turns, at 10 or 1
  Hz, with positions only, a 1.5-m lever arm, a 50-ms latency or a 60-s outage (tests/test_factor_graph_aiding.py).
* a loose position prior (``GPSFactor``, ``position_sigma``) on ``X(0)``, on the axes that no position row
  measures: it fixes the otherwise free position (priors on every keyframe from integrated velocities would count
  the rows twice and take their random walk for independent errors). Where position rows measure, none: they fix
  it, and the site is only their ENU offsets' origin (a prior there would fight rows that start away from it). An
  axis that no row measures at all (the vertical of NMEA's VTG and of positions without a height) gets a prior on
  ``V(0)`` too (``UNMEASURED_VELOCITY_SIGMA``, 1 m/s): else LM wanders in the free vertical channel.
* a zero-mean prior on ``B(0)``, and when the IMU model's bias walks (``random_walk``, or an
  ``instability`` of correlation time ``tau``), random-walk factors
  ``BetweenFactorConstantBias(B(j-1), B(j))`` of sigma ``sqrt(q T_b)`` with
  ``q = random_walk^2 + 2 instability^2 / tau`` (the Kalman aligner's process noise) between
  biases held over ``bias_interval_s`` (30 s); otherwise one constant bias ``B(0)``.
* with ``init`` and ``init_sigma_deg``, a prior on the attitude of ``X(0)`` at ``init`` (the
  information a Kalman filter's initial covariance carries; none by default, so that ``init``
  is only a starting point and may be 180 deg off).

The IMU model
-------------
``imu`` (a :class:`fusionbench.imu.IMUSpec`) gives, per axis (:func:`noise_model`): the white-noise
densities (floored at 1e-5 deg/sqrt(h) and 0.1 ug/sqrt(Hz)); bias priors
``sqrt(bias^2 + bias_sigma^2 + instability^2)`` (the fixed bias is a datasheet figure whose sign
the estimator does not know, so it counts as a spread), floored at 0.01 deg/h and 10 ug like the
Kalman aligner's; the bias walk above. Its noise schedules are not used (estimating a change of
noise is ``gtsam-adaptive``'s job). Explicit ``gyro_noise``, ``accel_noise``, ``gyro_bias_sigma``,
``accel_bias_sigma`` override it. ``imu=None`` keeps the figures of earlier versions: seed000's
white noise (0.005 deg/sqrt(h), 6 ug/sqrt(Hz)), bias priors 0.1 deg/h and 100 ug, a constant bias.

The bias prior must not be tighter than the sensor's bias: on a stationary base the horizontal
accelerometer biases are collinear with the level angles and the east gyro bias nearly so with the
heading (over minutes); the zero-mean prior keeps those components at zero and the attitude lands on
the theoretical limits (:func:`fusionbench.metrics.theoretical_limits`). The north gyro bias,
however, is observable as a drift of the level angles, and a prior tighter than it leaks its drift
into them: with a prior equal to the bias, the north level angle lands within 3 % (0.003 arcmin) of
its limit on noise-free data (120 to 300 s), within 1 % at ten times the bias. It must not be much
looser either, which is what the fixed 0.1 deg/h did wrong on a moving base: there the east gyro
bias is separable from the heading only through the slowly growing transport rate, so a loose
prior lets the graph estimate it from data that hardly see it, and its estimation noise goes into
the heading. The vertical accelerometer bias is observable and also carries the vertical
scale-factor error. The up gyro bias turns the heading by ``eps_U t``, which minutes of data cannot
see, so the final heading carries about ``eps_U T / 2`` beyond the limit.

Why (measured)
--------------
paper001-moving-base (0.1 g east, 10 Hz, reference 0.1 m/s per sample, seed001 gyro with
2.6e-5 deg/sqrt(h) and 0.01 deg/h, 20 runs x 500 s): final azimuth error rms / spread about the
mean / predicted sigma with the bias known, arcmin. The earlier graph (seed000 noise, priors
0.1 deg/h and 100 ug, one prior of sigma ``vref_sigma`` per keyframe, position priors on
every keyframe): 3.86 / 3.75 / 2.56 (``kf``: 0.99 / 0.60). The bias priors from the IMU model
alone: 1.19 / 0.70; with its noise densities too: 0.93 / 0.59 / 0.43; with every sample weighted:
0.91 / 0.68 / 0.36; without the position priors (this graph): 0.95 / 0.53 / 0.55, the sigma now
matching the spread (the position priors claimed 0.36 for a spread of 0.68, the per-keyframe
weighting 1.63 for 0.48). So the loose gyro-bias prior was the cause (its estimation noise went into
the heading); weighting every sample barely moves the estimate here but makes its sigma right. On
paper001-r-jump the same steps take the azimuth from 23.5 to 2.4 arcmin (``kf`` 2.9); on a
stationary base nothing of it matters beyond the bias prior. The keyframe interval matters little:
0.5, 1, 2, 5 s give 1.18, 1.19, 1.19, 1.20 arcmin on the moving base (10 runs) at 0.8, 0.4, 0.2,
0.1 s per recording; 1 s keeps the history's resolution. At tactical grade the heading's limit
(east gyro bias over ``W cos L``: 1 deg/h is 4 to 8 deg) dominates, the data cannot tell heading
from bias, and a Kalman filter's initial attitude covariance decides the split: with the same prior
(``init_sigma_deg=(1, 1, 5)``, the filter's default) the graph matches ``kf`` at 34 N (static 110
against 115 arcmin over 20 runs, sway 157 against 167 and moving base 77 against 83 over 60),
except on the moving base at 45 S, 9 % worse over 150 runs (123 against 113, a larger common offset
in that split: mean -84 against -64); without the prior it lands on the limit (267 arcmin static).

gtsam-adaptive
--------------
A noise level that changes during the record (seed 001's Q x 100 and R x 100 tests) is not an
outlier problem (a Huber weight helps only where residuals are many sigmas) but a variance
problem. :class:`AdaptiveFactorGraphAligner` solves the graph, then estimates, per window of
``adapt_window_s`` (10 s), a variance factor of the velocity rows, one of the position rows and one of the
preintegrated IMU noise by variance-component estimation: for a group of factors whose true
covariance is ``lambda`` times the assumed one, ``E[sum b^T b] = lambda sum r`` with ``b`` the
whitened residuals at the solution and ``r = m - tr(A Sigma A^T)`` the redundancy numbers (``A``
the whitened Jacobian, ``Sigma`` the posterior covariance of the factor's keys,
:class:`baselines.graph_support.Posterior`); the rows add their scatter about what the solution
predicts at their times, less a line per tile (``n - 2`` degrees of freedom per tile and axis), so
their factor is sharp in every window, while the IMU's redundancy is small
(about 1 per 10 s on a stationary base, 0.01 on the 10-Hz moving base, where the 0.1-m/s reference
sees nothing of the IMU noise) and a window borrows from its neighbours until it has
``adapt_min_dof`` (10), with ``adapt_prior_dof`` (10) pseudo-degrees of freedom at the nominal
model. The rows are then weighted by ``1 / lambda`` in their tile means, each ImuFactor's
covariance is multiplied by its window's factor (the preintegration is reused:
``cloneWithNewNoiseModel``), and the graph is solved again from the previous solution, until no
factor changes by more than 5 % (at most ``adapt_iterations``, 6). 20 runs: static-q-jump azimuth
4.0 arcmin (``gtsam`` 24.8, ``kf`` 25.8, ``akf`` 22.0), paper001-r-jump 1.22 (``gtsam`` 2.38,
``akf`` 1.41); on nominal data it stays within a few % of ``gtsam``.

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
* On a moving base the ENU frame also turns with the transport rate ``omega_en^n``. Each interval then gets its
  own parameters: gravity at its latitude and height and ``setOmegaCoriolis(omega_ie^n + omega_en^n)`` at its
  mean velocity. Where gtsam's model and the ENU velocity equation ``dv/dt = f + g - (2 omega_ie + omega_en) x v``
  differ, the specific force of every sample gets ``C_nb (omega_en x v + omega x (omega x p))`` (the centrifugal
  term is in normal gravity already; p reaches tens of km), with the current attitude; the graph is rebuilt when
  the attitude moved by more than ``recompensate_rad``. The velocity and positions come from the rows
  (:func:`baselines.graph_aiding.motion`): velocity rows interpolated (differenced positions without them),
  integrated, shifted onto the positions; with rows elsewhere than at every increment end the compensation is
  then redone from the solution's own velocity and positions and solved again (one more pass): across a 60-s
  outage the interpolated velocity left 0.09 arcmin of azimuth with 10-Hz velocities and 2.8 with 1-Hz positions
  (a perfect IMU), the solution's nothing. A perfect IMU accelerating at 0.1 g to 245 m/s is aligned to a few
  thousandths of an arcmin, against 5 to 19 arcmin with the earth rate alone. A position is the integral of the
  ENU velocity from the site, which a position row's ENU offset is made (the meridians' convergence,
  :func:`baselines.graph_aiding.path_offsets`: ignored, 0.08 arcmin over 1.5 km).
* With ``init=None`` the coarse stage (``coarse``, :class:`fusionbench.coarse.InertialCoarseAligner`) gets the aiding.
* The graph is solved by Levenberg-Marquardt with a multifrontal QR factorisation and tolerances of
  1e-10: the whitened Jacobian has a condition number near 1e7 (from a metre-level position prior
  to a gyro bias of 1e-8 rad/s), so Cholesky on the information matrix (condition 1e14) fails.

Cost
----
Per recording with the marginals, 2 cores shared: a 600-s record at 100 Hz (600 keyframes) about
0.75 s (``gtsam``; two builds, the second at the first solution), 1.5 s (``gtsam-robust``, a few
reweightings), 2.5 to 3 s (``gtsam-adaptive``, up to six re-solutions each with the posterior
covariance of every factor); a 500-s record at 10 Hz 0.4, 0.7 and 0.9 to 1.4 s; the Kalman filter
0.4 and 0.3 s (CPU time, the same with the rows within 10 %). The coarse stage adds 0.25 s when ``init`` is None.
A car's 300-s drive at 50 Hz with rows at 10 or 1 Hz, velocity or position: 0.34 to 0.42, 0.5 to 0.6 and 0.6 to
0.8 s (the compensation's extra pass; rows at every increment 0.25, 0.39, 0.56 s).

Marginals
---------
``gtsam.Marginals`` (Cholesky on the information matrix) fails on this graph with an
IndeterminantLinearSystem error, so ``sigma_phi`` comes from a QR-eliminated Bayes net of the
graph linearised at the solution (:class:`baselines.graph_support.Posterior`, a backward covariance
recursion, linear in K). It includes the bias priors: the azimuth sigma is at least
``gyro_bias_sigma / (W cos L)`` and the level sigmas at least ``accel_bias_sigma / g``, the
unobservable parts. ``sigma_phi_noise`` is the same marginal with the biases known: the spread
around the limits that the sensor and reference noise alone cause.

The result's history is the optimised attitude at each keyframe (``t`` the keyframe times, the last
one the last sample).
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np

import gtsam
from gtsam.symbol_shorthand import B, V, X

from fusionbench import units
from fusionbench.aligner import AlignmentResult, Site
from fusionbench.claims import Supports
from fusionbench.aligner_base import AlignerBase
from fusionbench.attitude import dcm_to_rotvec, orthonormalize
from fusionbench.imu import IMUSpec, load_spec
from fusionbench.imudata import IMUData

from fusionbench.coarse import InertialCoarseAligner
from .graph_aiding import (POSITION_SIGMA, build_problem, keyframe_states, motion_from_solution, recording_rows,
                           row_scatter, tile_data)
from .graph_rows import tile_error, tile_factors, tile_imu_variance
from .graph_support import (Posterior, _interval_rotations, _propagate, compensated_increments,  # noqa: F401
                            keyframe_counts, marginal_sigmas, residual_statistics, tangent_rates)

__all__ = ["FactorGraphAligner", "RobustFactorGraphAligner", "AdaptiveFactorGraphAligner", "keyframe_counts",
           "compensated_increments", "noise_model"]

#: Smallest reference noise used, m/s: an exact reference still gives well-conditioned velocity factors.
VREF_SIGMA_FLOOR = 1e-3
#: Sigma of a prior on an axis that rows fix, m or m/s: no information.
UNFIXED_SIGMA = 1e6
#: Sigma of the prior on the first velocity on an axis that no row measures (a vertical), m/s: a road's climb.
UNMEASURED_VELOCITY_SIGMA = 1.0

#: Defaults without an IMU model (``imu=None``): white noise of the seed000 preset ("Zhou 2011"),
#: bias-prior sigmas ten times (gyro) and three times (accelerometer) seed000's biases.
GYRO_NOISE = 0.005 * units.DEG_PER_SQRT_H       # rad/sqrt(s)
ACCEL_NOISE = 6.0 * units.UG_PER_SQRT_HZ        # m/s/sqrt(s)
GYRO_BIAS_SIGMA = 0.1 * units.DEG_PER_H         # rad/s, 10 x seed000's 0.01 deg/h
ACCEL_BIAS_SIGMA = 100.0 * units.UG             # m/s^2, above seed000's 30 ug
#: Floors of the figures taken from an IMUSpec: white noise (a zero datasheet figure would make the
#: preintegrated covariance singular) and bias-prior sigmas (those of the Kalman aligner, so that a
#: zero figure does not freeze a bias).
GYRO_NOISE_FLOOR = 1e-5 * units.DEG_PER_SQRT_H
ACCEL_NOISE_FLOOR = 0.1 * units.UG_PER_SQRT_HZ
GYRO_BIAS_FLOOR = 0.01 * units.DEG_PER_H
ACCEL_BIAS_FLOOR = 10.0 * units.UG


def noise_model(spec):
    """The graph's IMU noise figures from an IMU model (see the module docstring).

    Parameters
    ----------
    spec : IMUSpec or None
        The sensor model; None gives the defaults (seed000's white noise, bias priors 0.1 deg/h and
        100 ug, constant bias).

    Returns
    -------
    dict
        ``gyro_noise`` (3,) rad/sqrt(s), ``accel_noise`` (3,) m/s/sqrt(s) (white-noise densities,
        floored); ``gyro_bias_sigma`` (3,) rad/s and ``accel_bias_sigma`` (3,) m/s^2: the zero-mean
        bias priors, ``sqrt(bias^2 + bias_sigma^2 + instability^2)`` per axis (the fixed bias is a
        figure whose sign the estimator does not know, so it counts as a spread), floored;
        ``gyro_bias_walk`` (3,) rad/s/sqrt(s) and ``accel_bias_walk`` (3,) m/s^2/sqrt(s): the
        bias's random walk, ``sqrt(random_walk^2 + 2 instability^2 / tau)`` (the Kalman aligner's
        process noise; zero for a constant bias); ``name``, the model's name.
    """
    if spec is None:
        return {"gyro_noise": np.full(3, GYRO_NOISE), "accel_noise": np.full(3, ACCEL_NOISE),
                "gyro_bias_sigma": np.full(3, GYRO_BIAS_SIGMA), "accel_bias_sigma": np.full(3, ACCEL_BIAS_SIGMA),
                "gyro_bias_walk": np.zeros(3), "accel_bias_walk": np.zeros(3), "name": "default"}
    if not isinstance(spec, IMUSpec):
        raise ValueError(f"imu: expected a fusionbench.imu.IMUSpec or None, found {type(spec).__name__}")
    out = {"name": spec.name}
    for sensor, e, noise_floor, bias_floor in (("gyro", spec.gyro, GYRO_NOISE_FLOOR, GYRO_BIAS_FLOOR),
                                               ("accel", spec.accel, ACCEL_NOISE_FLOOR, ACCEL_BIAS_FLOOR)):
        out[f"{sensor}_noise"] = np.maximum(np.asarray(e.white), noise_floor)
        spread = np.sqrt(np.square(e.bias) + np.square(e.bias_sigma) + np.square(e.instability))
        out[f"{sensor}_bias_sigma"] = np.maximum(spread, bias_floor)
        out[f"{sensor}_bias_walk"] = np.sqrt(np.square(e.random_walk) + 2 * np.square(e.instability) / e.tau)
    return out


def _scalar_or_axes(x):
    """A float when the three axes agree, else the (3,) array."""
    x = np.asarray(x, dtype=float)
    return float(x[0]) if np.all(x == x[0]) else x.copy()


#: Walk of a bias the model holds constant beside others that walk, per sqrt(s), as a fraction of its prior: 1e-3 of
#: the prior over an hour.
STILL_WALK = 1e-3 / np.sqrt(3600.0)


class FactorGraphAligner(AlignerBase):
    """Factor-graph fine alignment (method ``gtsam``): gtsam ImuFactors with earth-rate Coriolis,
    velocity factors from every reference sample and a bias with zero-mean priors, solved by
    Levenberg-Marquardt (see the module docstring). A smoother: each keyframe's estimate uses the
    whole record (the result's ``causal`` is False).

    Parameters
    ----------
    step_s : float
        The graph's step: the keyframe interval, s (default 1 s), rounded to a whole number of IMU samples.
    imu : str, path, IMUSpec or None
        The sensor model (a preset name, an IMU spec TOML file or an IMUSpec, :func:`fusionbench.imu.load_spec`;
        default the ``navigation`` preset) from which the white-noise densities, the bias priors and the bias
        random walk come (:func:`noise_model`); its noise schedules are not used (a change of noise level is
        what :class:`AdaptiveFactorGraphAligner` estimates). An IMU whose gyro bias hides the earth rate is
        refused (:func:`fusionbench.claims.check_azimuth_observable`). None:
        seed000's white noise, bias priors 0.1 deg/h and 100 ug, a constant bias. Its name is
        reported as the result's ``imu_model``.
    gyro_noise : float or (3,) float, optional
        Gyro white-noise density (angle random walk), rad/sqrt(s); overrides the model's.
    accel_noise : float or (3,) float, optional
        Accelerometer white-noise density (velocity random walk), m/s/sqrt(s); overrides the model's.
    gyro_bias_sigma : float or (3,) float, optional
        Sigma of the zero-mean gyro-bias prior, rad/s, body axes; overrides the model's. Not smaller
        than the sensor's bias (module docstring).
    accel_bias_sigma : float or (3,) float, optional
        Sigma of the zero-mean accelerometer-bias prior, m/s^2; overrides the model's.
    vref_sigma : float
        Noise of one velocity row without its own sigma (``Aiding.sigma_v``), m/s, each ENU axis, independent
        between rows (or of the zero velocity at each increment end without aiding); floored at 1 mm/s (an exact
        reference), like the rows' own. A scenario gives the graph its reference's noise. A keyframe's velocity
        factor holds the n rows of its tile: ``vref_sigma / sqrt(n)`` (module docstring).
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
        Rebuild the graph when the optimised attitude moved by more than this (rad) from the one at
        which the velocity factors were linearised and, on a moving base, the transport rate
        compensated (the preintegration is redone only where the compensation matters: angle moved
        times compensation above 1e-9 m/s^2).
    max_passes : int
        At most this many graph builds per recording (the robust variant: at least 10, for its
        reweighting).
    marginals : bool
        Compute ``sigma_phi`` and ``extra["sigma_phi_noise"]``.
    huber_k : float
        Huber threshold, in sigmas, of the robust variant.
    coarse : object, optional
        Aligner used when ``init`` is None (default :class:`fusionbench.coarse.InertialCoarseAligner`,
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
    # sway (conformance, 20 runs; gtsam-robust and gtsam-adaptive alike): seed 000's case 1.21, the mild sway 0.81-1.13,
    # the Table-1 sway at 60, 75, 80 N 1.07, 0.77, 1.05 (1.60 at 60 N before tangent_rates); tactical gyros (up to
    # 0.149 of the horizontal earth rate in the matrix) on a fixed base: static 0.88-0.93 (4.88 at 60 N before the
    # tiles held the IMU's own noise), swaying 0.80-1.44 with the levels on the bias limit (the sway separates the
    # accelerometer biases); not on a moving base (the tactical drive's levels at 0.95-1.0 of their tolerance), and
    # gtsam-adaptive not at all (1.59 at 60 N, static; docs/open-claims.md)
    # aiding: a car's 300-s drive with turns at 34 N and 60 N, navigation grade at 50 Hz, 6 runs each, rows of
    # 0.05 m/s or 0.5 m: velocity at 1, 0.5, 0.2, 0.1 Hz, azimuth rms 2.1, 2.6, 6.3, 10.2 arcmin (marginal sigma 2.6,
    # 3.5, 5.6, 8.0; 0.05 Hz 5.9 against 12); position only at 1, 0.2, 0.1 Hz 2.1, 2.9, 3.3 (2.5, 4.4, 5.9); outages
    # of 60, 100, 140 s from 150 s in 10-Hz velocities 0.9, 0.8, 0.8 (1.0, 1.1, 1.2), in 1-Hz positions 1.8, 1.9,
    # 1.8 (2.7, 3.0, 3.4); every axis within its sigma (rms of error over sigma 0.5 to 1.5)
    supports = Supports(bases=("static", "sway", "moving"), max_abs_lat_deg=80.0, max_bias_ratio=0.15,
                        max_bias_ratio_moving=0.05, aiding=("velocity", "position"), min_aiding_hz=0.1,
                        max_outage_s=140.0)
    #: Highest |latitude| accepted, deg: the horizontal earth rate W cos(L) that sets the heading vanishes at the poles.
    max_latitude_deg = 89.0
    #: Keys of the per-recording extras that are the same for every recording (kept once).
    _shared_extra = ("adapt_window_t",)

    def __init__(self, step_s=1.0, imu="navigation", gyro_noise=None, accel_noise=None, gyro_bias_sigma=None,
                 accel_bias_sigma=None, vref_sigma=0.01, position_sigma=1.0, integration_sigma=1e-6,
                 bias_interval_s=None, max_iterations=100, recompensate_rad=1e-3, max_passes=3, marginals=True,
                 huber_k=1.345, coarse=None, init_sigma_deg=None, aiding_position_sigma=POSITION_SIGMA):
        if not (isinstance(vref_sigma, (int, float)) and np.isfinite(vref_sigma) and vref_sigma >= 0):
            raise ValueError(f"vref_sigma: expected a non-negative standard deviation in m/s, found {vref_sigma!r}")
        vref_sigma = max(float(vref_sigma), VREF_SIGMA_FLOOR)  # an exact reference: a well-conditioned factor
        positive = dict(step_s=step_s, vref_sigma=vref_sigma, position_sigma=position_sigma,
                        aiding_position_sigma=aiding_position_sigma,
                        integration_sigma=integration_sigma, recompensate_rad=recompensate_rad, huber_k=huber_k,
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

    # --------------------------------------------------------------------------------- the model
    def _huber_weights(self, problem, data, values):
        """Huber weights of the tile factors at ``values``, ``{"v": (K,), "p": (K,)}`` (robust variant; all 1
        otherwise): 1 within ``huber_k`` sigmas of the whitened error's norm, ``huber_k / |e|`` beyond (gtsam's
        Huber on a block)."""
        K = problem["counts"].size
        out = {g: np.ones(K) for g in ("v", "p")}
        if not self.robust:
            return out
        R, t, v, b = keyframe_states(values, K, problem["seg"])
        for g, unit in (("v", self.vref_sigma), ("p", self.aiding_position_sigma)):
            if data[g] is not None:
                e = tile_error(data[g], R, t, v, b) / (unit * np.sqrt(data[g]["var"]))
                r = np.linalg.norm(np.where(np.isfinite(data[g]["var"]), e, 0.0), axis=1)
                out[g] = np.where(r <= self.huber_k, 1.0, self.huber_k / np.maximum(r, 1e-300))
        return out

    def estimate_only(self):
        """This aligner without the marginal covariances (``marginals=False``): the same attitudes, a third
        cheaper, for the runner's settling of a smoother (:func:`fusionbench.runner._prefix_settling`), which reads
        only the final attitude of each prefix."""
        lean = copy.copy(self)
        lean.marginals = False
        return lean

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
        uses attitude ``C_kf`` (K, 3, 3)."""
        phi, dv, dt, counts = problem["phi"], problem["dv"], problem["dt"], problem["counts"]
        w_in, c_n, g = problem["w_in"], problem["c_n"], problem["g"]
        K = counts.size
        acc = dv / dt
        if np.any(c_n):
            c_b, _ = _interval_rotations(phi, counts, np.einsum("kji,kj->ki", C_kf[:-1], c_n))
            acc = acc + c_b
        gyr = tangent_rates(phi, counts, dt)
        zero = gtsam.imuBias.ConstantBias()
        same = np.all(w_in == w_in[0]) and np.all(g == g[0])
        params = self._params(g[0], w_in[0]) if same else None
        pims = []
        for k in range(1, K):
            pim = gtsam.PreintegratedImuMeasurements(params if same else self._params(g[k - 1], w_in[k - 1]), zero)
            for i in range(counts[k - 1], counts[k]):
                pim.integrateMeasurement(acc[i], gyr[i], dt)
            pims.append(pim)
        return pims

    def _graph(self, pims, data, refs, seg, walk, at, imu_scale=None, huber=None):
        """The factor graph of one recording from its preintegrated intervals ``pims`` and its tile factors'
        ``data`` (:func:`baselines.graph_aiding.tile_data`), linearised at the values ``at``.

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
        lin = ([at.atPose3(X(k)) for k in range(K)], np.stack([at.atVector(V(k)) for k in range(K)]),
               [at.atConstantBias(key[2]) for key in keys])
        for g, unit in (("v", self.vref_sigma), ("p", self.aiding_position_sigma)):
            if data[g] is None:
                continue
            w = 1.0 if huber is None else huber[g][:, None]
            var = unit**2 * data[g]["var"] / w
            if g == "v":  # what the IMU's own noise leaves in the prediction (module docstring)
                var = var + tile_imu_variance(pims, lin[0], imu_scale)
            for k, f in tile_factors(data[g], np.sqrt(var), keys, lin):
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

    def _optimize(self, graph, values):
        lm = gtsam.LevenbergMarquardtParams()
        lm.setLinearSolverType("MULTIFRONTAL_QR")
        lm.setRelativeErrorTol(1e-10)
        lm.setAbsoluteErrorTol(1e-10)
        lm.setMaxIterations(self.max_iterations)
        opt = gtsam.LevenbergMarquardtOptimizer(graph, values, lm)
        return opt.optimize(), opt.iterations()

    def _solve(self, problem, C_kf, values=None, imu_scale=None, pims=None):
        """Optimise one recording from keyframe attitudes ``C_kf`` (K, 3, 3) (or from ``values``).

        Returns ``(graph, values, C_kf, iterations, passes, converged, imu_idx, vel_idx, pims, data, pos_idx)``.
        The tile factors are linearised at the current solution (their lever-arm terms and the turn of ENU taken
        with its attitude) and, on a moving base, the preintegration compensated for the transport rate with its
        attitude; the graph is rebuilt there until the attitude moves by less than ``recompensate_rad`` (and, in
        the robust variant, the Huber weights settle). ``pims``: intervals already preintegrated with an attitude
        within ``recompensate_rad`` of ``C_kf``.
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
        iterations, converged, moved = 0, True, 0.0
        huber = self._huber_weights(problem, data, values)
        c_max = np.abs(problem["c_n"]).max()
        passes = max(self.max_passes, 10) if self.robust else self.max_passes
        for n_pass in range(1, passes + 1):
            if pims is None:
                pims = self._preintegrate(problem, C_kf)
            if n_pass > 1 and moved > self.recompensate_rad:  # the lever arm and the turn of ENU at the new attitude
                data = tile_data(problem, C_kf)
            graph, imu_idx, idx = self._graph(pims, data, problem, seg, walk, values, imu_scale, huber)
            values, n_it = self._optimize(graph, values)
            iterations += n_it
            converged = converged and n_it < self.max_iterations  # a pass stopped at the limit may have stalled
            C_new = np.stack([values.atPose3(X(k)).rotation().matrix() for k in range(K)])
            moved = np.abs(dcm_to_rotvec(C_new @ np.swapaxes(C_kf, -1, -2))).max()
            C_kf = C_new
            new_huber = self._huber_weights(problem, data, values)
            settled = max(np.abs(new_huber[g] - huber[g]).max() for g in huber) <= 1e-3
            huber = new_huber
            if moved <= self.recompensate_rad and settled:
                break
            if moved > self.recompensate_rad and moved * c_max > 1e-9:  # the compensation matters
                pims = None
        return graph, values, C_kf, iterations, n_pass, converged, imu_idx, idx["v"], pims, data, idx["p"]

    def _refine(self, problem, sol):
        """Hook for the adaptive variant: the final solution and a dict of per-recording extras."""
        return sol, {}

    # ------------------------------------------------------------------------------------- align
    def _align(self, imu: IMUData, site: Site, aiding, init) -> AlignmentResult:
        """Align every recording of ``imu`` by factor-graph smoothing, from any heading.

        Parameters
        ----------
        imu : IMUData
            R recordings, body frame RFU (increments or rates).
        site : Site
            Latitude (|lat| <= 89 deg), longitude, height.
        aiding : fusionbench.aiding.Aiding, optional
            Velocity and/or position rows for the R recordings, each used at its time of validity with the lever
            arm (module docstring); a row without its own sigma has ``vref_sigma`` (velocity) or
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
            Naming the field: beside the input policy of :class:`fusionbench.aligner_base.AlignerBase` (latitude
            beyond 89 deg, a record shorter than ``min_duration_s``, aiding outside the record, a bad ``init``,
            non-finite samples), a keyframe interval shorter than the sample interval.
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
        T = np.diff(counts) * dt
        seg, walk = self._bias_segments(t_kf)
        coarse_final = None if init is not None else self.coarse.align(imu, site, aiding=aiding).C_bn_final

        C_out = np.empty((R, K, 3, 3))
        sig, sig_noise = np.full((R, K, 3), np.nan), np.full((R, K, 3), np.nan)
        bg, ba = np.empty((R, 3)), np.empty((R, 3))
        iters, passes, cost = np.zeros(R, int), np.zeros(R, int), np.empty(R)
        restarted = np.zeros(R, bool)
        per_run = []
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
            _, dR = _interval_rotations(problem["phi"], counts, None)
            if init is not None:
                start = _propagate(init[r], dR, problem["w_in"], T, forward=True)
            else:
                start = _propagate(orthonormalize(coarse_final[r]), dR, problem["w_in"], T, forward=False)
            sol = self._solve(problem, start)
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


class AdaptiveFactorGraphAligner(FactorGraphAligner):
    """Noise-adaptive factor-graph fine alignment (method ``gtsam-adaptive``).

    The graph of :class:`FactorGraphAligner`, whose reference-noise variance and IMU noise level are
    estimated per time window from the residuals of the solution, and the graph solved again with
    them (iterated variance-component estimation, module docstring). The record is cut into windows
    of ``adapt_window_s``; in each, variance factors (covariance multipliers): ``lambda_v`` of
    the velocity rows, ``lambda_p`` of the position rows and ``lambda_i`` of the preintegrated IMU noise
    (gyro and accelerometer together). From a solution, for each group, ``lambda = (nu + sum(lambda_old b^T b)) / (nu +
    sum(r))`` over the window, with the whitened residuals ``b`` and redundancy numbers ``r`` of
    its factors (:func:`baselines.graph_support.residual_statistics`) and, for the rows, their
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
    # as gtsam, but navigation-grade gyros only: with a tactical IMU on a fixed base at 60 N 1.59 bounds (gtsam 0.89)
    supports = replace(FactorGraphAligner.supports, max_bias_ratio=0.05, max_bias_ratio_moving=None)

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
