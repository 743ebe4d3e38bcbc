"""What an optimal estimator attains in an alignment: the spread of its misalignment (:func:`attainable_bound`) and,
on any base, where the fixed biases put it (:func:`bias_limit`).

Both run the Kalman filter of the linear psi-angle error model with the true noise statistics
(:mod:`fusionbench.scoring.bound_model`), in square-root form, over the record: velocity measurements from a
per-increment reference (``vref_sigma``, ``vref_dt``) or a receiver's rows (``aiding``, a
:class:`fusionbench.simulation.aidingsim.AidingSpec`: velocity and/or position at its epochs, from an antenna on a
lever arm, with outages). Frames: ENU navigation frame, body RFU, ``C_bn`` body to ENU,
``C_est = (I - [phi x]) C_true``; SI units.

* On a fixed base every alignment lands on :func:`fusionbench.scoring.metrics.theoretical_limits` (give or take half a
  record of azimuth drift: :func:`bias_limit`), the part of the fixed biases (``spec.gyro.bias``,
  ``spec.accel.bias``) that no data separate from the attitude, and :func:`attainable_bound` is the noise part
  about it. A velocity disturbance of the base that the reference does not report is an unknown coloured process
  in the model (:func:`fusionbench.scoring.bound_model.disturbance_block`), not known motion.
* On a moving base, turns above all, the biases become partly observable and that closed form no longer says where
  an optimal estimator lands. :func:`bias_limit` generalises it: the mean misalignment of the optimal filter that
  carries the biases as states (zero-mean prior, the fixed part included) when the true fixed biases drive the
  true error, and the spread of that same filter's error about it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from threadpoolctl import threadpool_limits

from fusionbench.scoring import bound_model as bm
from fusionbench.scoring.bound_model import VREF_FLOOR, bound_error
from fusionbench.simulation.aidingsim import AidingSpec
from fusionbench.simulation.imu_model import IMUSpec, _psd_factor

__all__ = ["attainable_bound", "bias_limit", "BiasLimit", "VREF_FLOOR", "scenario_bound", "efficiency", "BOUND_KINDS"]

#: Scenario kinds whose metrics carry the attainable bound and the efficiency (:func:`scenario_bound`).
BOUND_KINDS = ("alignment", "moving-alignment")

_INITIAL_SIGMA = (1.0, 1.0, 1.0, 10.0, 10.0)


class BiasLimit(NamedTuple):
    """Result of :func:`bias_limit` (unpacks as ``t, limit, sigma``).

    Attributes
    ----------
    t : ndarray, shape (M,)
        Step end times, s.
    limit : ndarray, shape (M, 3)
        Mean misalignment ``[phiE, phiN, phiU]`` the fixed biases cause, rad (ENU).
    sigma : ndarray, shape (M, 3)
        Standard deviation of the same estimator's misalignment about ``limit``, rad (ENU).
    """

    t: np.ndarray
    limit: np.ndarray
    sigma: np.ndarray


def attainable_bound(spec, duration, site=None, trajectory=None, vref_sigma=0.0, vref_dt=0.01, step_s=0.5,
                     C_bn=None, initial_sigma=_INITIAL_SIGMA, aiding=None, vref_schedules=()):
    """Standard deviation of the misalignment an optimal estimator reaches, beyond the theoretical limit.

    Any stationary alignment lands on :func:`fusionbench.scoring.metrics.theoretical_limits`, the part of the error
    caused by the fixed (deterministic) biases ``spec.gyro.bias`` and ``spec.accel.bias``. This function gives the rest:
    the error covariance of the linear alignment error model with the true noise statistics and the fixed biases
    known, i.e. what the Kalman filter with the exact model (the optimal estimator for it) attains at each time.
    An aligner's error about the limit cannot have a smaller standard deviation (on a moving base, about
    :func:`bias_limit`'s limit, whose own ``sigma`` is the spread of an estimator that does not know the fixed
    biases: never below this one).

    Model (ENU psi-angle, as :mod:`baselines.kalman`), states ``[phiE, phiN, phiU, dvE, dvN]``
    (rad, m/s), ``[dpE, dpN]`` (m) when an aiding measures positions, plus, in the body frame and only where the
    spec has them, a random-bias state per axis with initial std ``bias_sigma`` driven by ``random_walk`` (a
    per-run constant plus a rate/acceleration random walk) and a first-order Gauss-Markov state (steady std
    ``instability``, correlation time ``tau``), for the gyro (eps) and the accelerometer (nab)::

        phi' = -[w_in x] phi - C_bn (eps + w_g)
        dv'  = ([f^n x] phi)[E,N] + (C_bn (nab + w_a))[E,N] - [(2 w_ie + w_en) x]_(2x2) dv
        dp'  = dv

    with ``w_g``, ``w_a`` the white noises (``spec.*.white``: rad/sqrt(s), m/s/sqrt(s), scaled by
    any ``spec.schedules`` factor). Scale-factor, axis-misalignment and quantisation errors and the
    vertical channel are not modelled (nor are they in the Kalman filter).

    Each step is discretised exactly (Van Loan) with ``C_bn``, ``f^n`` and the rates averaged over four
    Gauss-Legendre points of the step (a swaying base: keep the step a fraction of the sway periods). Measurements:

    * per-increment reference (``aiding`` None): ``ceil(duration / step_s)`` equal steps; at each step end the
      horizontal velocity error with noise variance ``vref_sigma^2 vref_dt / step`` per axis (times the mean over
      the step's samples of any ``vref_schedules`` factor), the information of all the reference samples of the
      step (their average, attributed to the step end: accurate while the velocity error changes little within a
      step compared with that noise);
    * a receiver (``aiding``): steps of ``1 / (k rate_hz)``, ``k = ceil(1 / (rate_hz step_s))``, so that every
      epoch ``j / rate_hz`` ends a step (the cost grows with the rate: 3000 steps at 10 Hz for 300 s). At each
      epoch outside the outages, the antenna's horizontal velocity error ``dv + ([u x] phi)[E,N]``,
      ``u = C_bn (omega_nb^b x l)``, and/or position error ``dp + ([d x] phi)[E,N]``, ``d = C_bn l``, with the
      rows' sigmas (scaled by the aiding's schedules). On a fixed base (a site, or a trajectory that does not
      translate) the velocity rows say the base is at rest: the IMU's velocity, no lever term. The rows count at
      their time of validity: the latency changes no information. The gyro noise in ``omega_nb^b`` of the lever
      term is not modelled (1.5 m times a 0.1 deg/s noise is 3 mm/s).

    A base's velocity disturbance (``trajectory.translation.disturbance``) that the measurements do not report, as
    the per-increment reference never does (it gives the nominal motion) nor a receiver on a fixed base (zero
    velocity, the site), is a coloured process the aligner does not know: its horizontal velocity, modelled as
    white noise through a band-pass over its band with its rms
    (:func:`fusionbench.scoring.bound_model.disturbance_block`), adds to the velocity error the rows measure (and its
    displacement to a position row's), and the kinematics are the nominal motion's (the disturbance's accelerations
    are not known motion). Each reference measurement is then the step's average of the velocity error and the
    disturbance, exactly. A receiver on a moving base measures the true velocity: there the disturbance is known
    motion, as the IMU senses it.

    The covariance is propagated and updated in square-root form (QR of the pre-arrays), which keeps it positive
    and accurate with a diffuse start and an exact reference.

    Parameters
    ----------
    spec : fusionbench.simulation.imu.IMUSpec
        The IMU; its noise parts (white, bias_sigma, random_walk, instability, tau, schedules) are used.
    duration : float
        Record length, s.
    site : fusionbench.methods.aligner.Site, optional
        Static base at this site (latitude, height). Exactly one of ``site`` and ``trajectory``.
    trajectory : fusionbench.simulation.trajectory.Trajectory, optional
        Swaying or moving base: its truth gives C_bn(t), f^n(t) = C_bn f^b, the earth and transport
        rates (ENU) along the path, evaluated over [0, duration] (past its own ``duration`` a
        profile continues as its definition extends it); its nominal motion's where its velocity disturbance is
        not measured (above).
    vref_sigma : float or (3,) array_like
        White-noise std of each velocity-reference sample, m/s (ENU; the east and north values
        are used). 0 means an exact velocity; the per-step measurement std is floored at
        :data:`VREF_FLOOR` (1e-9 m/s) so that the filter stays well defined. Must be 0 with ``aiding``.
    vref_dt : float
        Interval of the reference samples, s (unused with ``aiding``).
    step_s : float
        Longest filter step, s (0.5: fine for a static base and for sway periods of 2 s and more).
    C_bn : (3, 3) array_like, optional
        Attitude of the static base with ``site`` (body RFU to ENU; default identity: level,
        facing north). It matters through body-frame random biases, anisotropic noise and the lever arm.
    initial_sigma : (5,) or (7,) array_like
        Initial std of ``[phiE, phiN, phiU]`` (rad), ``[dvE, dvN]`` (m/s) and, with positions measured,
        ``[dpE, dpN]`` (m; default 1000 m). The default, 1 rad and 10 m/s, is diffuse: a few minutes of data carry
        1e5 times more information. The bias states start at their prior stds.
    aiding : fusionbench.simulation.aidingsim.AidingSpec, optional
        A receiver's rows in place of the per-increment reference: ``rate_hz``, ``velocity_sigma`` (3,) m/s ENU,
        ``position_sigma`` (3,) m ENU (the east and north values are used; 0 is exact, floored at 1e-9),
        ``lever_arm`` (3,) m body RFU, ``outages`` ((start, end), ...) s of valid time, ``schedules``.
    vref_schedules : sequence of fusionbench.simulation.imu.NoiseSchedule
        The per-increment reference's variance multiplied by ``factor`` for ``start <= t < end`` (s), as
        :class:`fusionbench.simulation.imu.VelocityReferenceSpec`'s ``schedules`` (their ``sensors`` ignored). Empty
        with ``aiding`` (the rows have their own).

    Returns
    -------
    t : ndarray, shape (M,)
        Step end times, s.
    sigma : ndarray, shape (M, 3)
        Std of ``[phiE, phiN, phiU]`` about the limit at ``t``, rad (ENU).

    Raises
    ------
    ValueError
        One line naming the argument, what was expected and what was found.
    """
    with threadpool_limits(1):  # small matrices: BLAS threads only contend (10-50 times slower on a busy machine)
        t_end, model = _setup(spec, duration, site, trajectory, vref_sigma, vref_dt, step_s, C_bn, initial_sigma,
                              aiding, vref_schedules, fixed_prior=False)
        sigma, _ = _square_root_filter(*model)
    return t_end, sigma


def bias_limit(spec, duration, site=None, trajectory=None, vref_sigma=0.0, vref_dt=0.01, step_s=0.5, C_bn=None,
               initial_sigma=_INITIAL_SIGMA, aiding=None, vref_schedules=()):
    """Where the fixed biases put an optimal estimator's misalignment, on any base, and its spread about it.

    The filter of :func:`attainable_bound` (same model, steps and measurements) with the fixed biases
    ``spec.gyro.bias`` and ``spec.accel.bias`` unknown to it: its random-constant bias states start at zero with
    a variance of ``bias^2 + bias_sigma^2`` per axis, so that with the Gauss-Markov states' ``instability^2`` the
    bias prior is ``bias^2 + bias_sigma^2 + instability^2``, the project's filters'. The true error starts with
    the true biases in those states and no noise; it and the filter's estimate go through the model's transitions
    and the filter's own gains (``d = x - x_hat``: ``d <- Phi d`` over a step, ``d <- (I - K H) d`` at an
    update, ``d_0`` the fixed biases), and the misalignment left after the filter's correction, ``d``'s attitude
    part, is the limit. It is linear in the fixed biases (one propagation per bias axis).

    * On a fixed base with a diffuse attitude prior it is :func:`fusionbench.scoring.metrics.theoretical_limits`, a
      steady state, plus what that steady state leaves out: at the limit the azimuth still turns,
      ``phiU' = wN phiE - eps_U``, and gyrocompassing sees the azimuth at mid-record on the average, so the
      azimuth limit gains ``(wN phiE - eps_U) T / 2`` after a record of T s (0.01 arcmin in 300 s for a
      0.005 deg/h vertical gyro bias); the level limits lag a little behind the tilts' drift (a north gyro bias).
    * On a moving base it also holds what the motion makes observable of the biases (and what the gains have not
      yet done with it at ``t``): an acceleration or a turn moves it away from the closed form (a car's turns
      take a tactical IMU's azimuth limit from 82 arcmin at rest to 1.2 arcmin in 300 s of
      :func:`fusionbench.simulation.drive.car_drive` with 10-Hz velocity).

    ``sigma`` is the spread of this filter's error about the limit (its covariance less the part of the fixed
    biases' prior: the noise part). It is never below :func:`attainable_bound` (an estimator that knows the fixed
    biases) and equals it where the biases are unobservable (a fixed base, at the end of a long record).

    Parameters
    ----------
    spec, duration, site, trajectory, vref_sigma, vref_dt, step_s, C_bn, initial_sigma, aiding, vref_schedules
        As :func:`attainable_bound`.

    Returns
    -------
    BiasLimit
        ``t`` (M,) s, ``limit`` (M, 3) rad and ``sigma`` (M, 3) rad, ``[phiE, phiN, phiU]`` (ENU).

    Raises
    ------
    ValueError
        One line naming the argument, what was expected and what was found.
    """
    with threadpool_limits(1):
        t_end, model = _setup(spec, duration, site, trajectory, vref_sigma, vref_dt, step_s, C_bn, initial_sigma,
                              aiding, vref_schedules, fixed_prior=True)
    *model, constant = model
    n = model[3].size
    bias = np.zeros(6)  # the fixed biases, gyro then accel (rad/s, m/s^2, body)
    D0 = np.zeros((n, 6))  # the true error's start for a unit bias of each axis
    for j, (sensor, e) in enumerate((("gyro", spec.gyro), ("accel", spec.accel))):
        if sensor in constant:
            bias[3 * j:3 * j + 3] = e.bias
            D0[constant[sensor]:constant[sensor] + 3, 3 * j:3 * j + 3] = np.eye(3)
    with threadpool_limits(1):
        sigma, D = _square_root_filter(*model, D0=D0)
    limit = D @ bias
    spread2 = sigma**2 - np.sum((D * bias) ** 2, axis=-1)
    return BiasLimit(t_end, limit, np.sqrt(np.clip(spread2, 0.0, None)))


def scenario_bound(scn, traj, duration, history=False):
    """The attainable bound (3,) rad at the end of the record ``traj`` (``duration`` s), ENU, of an alignment
    scenario ``scn`` (:class:`fusionbench.bench.scenarios.Scenario` of a kind in :data:`BOUND_KINDS`; else None), with
    the aiding the methods get (its ``reference_model()`` and the reference's noise schedules): on a fixed base the
    spread of an optimal estimator about the theoretical limit (:func:`attainable_bound`); on a moving one the
    spread of the optimal estimator that does not know the fixed biases about the limit it lands on, the
    scenario's limit there (``scn.moving_limit``: :func:`bias_limit`). With ``history`` its course ``(t (M,) s,
    sigma (M, 3) rad)``."""
    if scn.kind not in BOUND_KINDS:
        return None
    if not traj.translation.is_static():
        t, _, sigma = scn.moving_limit(traj)
    else:
        model = scn.reference_model()
        if "aiding" not in model:
            model["vref_schedules"] = tuple(scn.vref_spec.schedules)
        t, sigma = attainable_bound(scn.imu_spec, duration, trajectory=traj, **model)
    return (t, sigma) if history else sigma[-1]


def efficiency(phi_end, limits, bound):
    """The conformance matrix's efficiency per axis (3,): the RMS over runs of the final error ``phi_end`` (R, 3) rad
    minus the limit ``limits`` (3,) rad, over the attainable bound ``bound`` (3,) rad (1: an optimal estimator)."""
    return np.sqrt(np.mean((np.asarray(phi_end) - limits) ** 2, axis=0)) / np.asarray(bound)


def _setup(spec, duration, site, trajectory, vref_sigma, vref_dt, step_s, C_bn, initial_sigma, aiding, vref_schedules,
           fixed_prior):
    """Validate the arguments and build the model: the step end times (M,) and ``(Phi, L, idx, P0, meas)`` for
    :func:`_square_root_filter`, plus the random-constant blocks' indices with ``fixed_prior``."""
    if not isinstance(spec, IMUSpec):
        raise bound_error("spec", "an IMUSpec", type(spec).__name__)
    if (site is None) == (trajectory is None):
        raise bound_error("site, trajectory", "exactly one of them", "both" if site is not None else "neither")
    duration = bm.positive(duration, "duration", "s")
    step_s = bm.positive(step_s, "step_s", "s")
    vref_dt = bm.positive(vref_dt, "vref_dt", "s")
    try:
        vs = np.broadcast_to(np.asarray(vref_sigma, dtype=float), (3,))
    except (TypeError, ValueError):
        raise bound_error("vref_sigma", "a non-negative number of m/s or an ENU 3-vector", repr(vref_sigma)) from None
    if not (np.all(np.isfinite(vs)) and np.all(vs >= 0)):
        raise bound_error("vref_sigma", "non-negative m/s", vs.tolist())
    if aiding is not None:
        if not isinstance(aiding, AidingSpec):
            raise bound_error("aiding", "an AidingSpec", type(aiding).__name__)
        if np.any(vs != 0):
            raise bound_error("vref_sigma", "0 with aiding (the rows' sigmas are the aiding's)", vs.tolist())
        if len(vref_schedules):
            raise bound_error("vref_schedules", "none with aiding (the rows have their own schedules)",
                              f"{len(vref_schedules)} schedule(s)")
    position = aiding is not None and aiding.position_sigma is not None
    s0 = np.asarray(initial_sigma, dtype=float) if np.ndim(initial_sigma) else np.full(5, float(initial_sigma))
    if s0.shape not in ((5,), (7,)):
        raise bound_error("initial_sigma", "5 stds [phiE, phiN, phiU] rad, [dvE, dvN] m/s (and [dpE, dpN] m)",
                          f"shape {s0.shape}")
    if not (np.all(np.isfinite(s0)) and np.all(s0 > 0)):
        raise bound_error("initial_sigma", "positive finite stds", s0.tolist())
    s0 = np.concatenate([s0[:5], s0[5:] if s0.size == 7 else [bm.INITIAL_POSITION_SIGMA] * 2]) if position else s0[:5]

    dist, trajectory = bm.unreported_disturbance(trajectory, aiding)
    t_end, T, k = bm.step_grid(duration, step_s, None if aiding is None else aiding.rate_hz)
    M = t_end.size
    tq = ((t_end - T / 2)[:, None] + T[:, None] / 2 * bm._GL_X[None, :]).ravel()  # 4 points per step
    Cq, fq, w_in, w_cor = bm.kinematics(tq, M, site, trajectory, C_bn)
    F, Qc, P0, constant = bm.error_model(spec, tq, M, Cq, fq, w_in, w_cor, s0, _psd_factor, position, fixed_prior)
    rows = None
    if dist is not None:
        kinds = ("average",) if aiding is None else ("velocity", "position") if position else ("velocity",)
        F, Qc, P0, rows = bm.disturbance_block(dist, F, Qc, P0, kinds)
    Phi, L, idx = bm.discretise(F, Qc, T, () if rows is None else rows["reset"])
    if aiding is None:
        q = bm.vref_factor(t_end, T[0], vref_dt, vref_schedules)  # (M,)
        meas = bm.vref_rows(M, P0.size, np.maximum(vs[:2] * np.sqrt(q[:, None] * vref_dt / T[0]), VREF_FLOOR),
                            None if rows is None else rows["average"] / T[0])
    else:
        meas = bm.aiding_rows(aiding, duration, k, P0.size, site, trajectory, C_bn, rows)
    model = (Phi, L, idx, P0, meas)
    return t_end, model + (constant,) if fixed_prior else model


def _square_root_filter(Phi, L, idx, P0, meas, D0=None):
    """A square-root Kalman filter over the M steps (step j: ``Phi[idx[j]]``, ``L[idx[j]]``; ``meas`` the steps with
    a measurement (K,), their ``H`` (K, m, n) and noise stds (K, m)). Returns the attitude sigmas (M, 3) rad and,
    with ``D0`` (n, c), the attitude rows (M, 3, c) of ``D0`` carried through the transitions and the updates
    ``I - K H`` with the filter's gains (else None)."""
    steps, H, r_sd = meas
    n, m = P0.size, H.shape[1]
    at = np.full(idx.size, -1)
    at[steps] = np.arange(steps.size)
    S = np.diag(np.sqrt(P0))  # P = S S^T
    pre = np.zeros((m + n, m + n))
    sigma = np.empty((idx.size, 3))
    D = None if D0 is None else np.array(D0, dtype=float)
    Dphi = None if D0 is None else np.empty((idx.size, 3, D.shape[1]))
    for j, i in enumerate(idx):
        # time update: P- = Phi P Phi^T + Qd, as R^T R of the QR of [S^T Phi^T; L^T]
        S = np.linalg.qr(np.vstack([(Phi[i] @ S).T, L[i].T]), mode="r").T
        if D is not None:
            D = Phi[i] @ D
        kk = at[j]
        if kk >= 0:
            # measurement update: QR of [[R^1/2, 0], [(H S)^T, S^T]] = [[A, B], [0, S+^T]], A^T B = H P-
            pre[:m, :m] = np.diag(r_sd[kk])
            pre[m:, :m] = (H[kk] @ S).T
            pre[m:, m:] = S.T
            post = np.linalg.qr(pre, mode="r")
            S = post[m:, m:].T
            if D is not None:  # K = P- H^T (A^T A)^-1 = B^T A^-T
                K = np.linalg.solve(post[:m, :m], post[:m, m:]).T  # A: m x m, m <= 4
                D = D - K @ (H[kk] @ D)
        sigma[j] = np.sqrt(np.sum(S[:3] ** 2, axis=1))
        if D is not None:
            Dphi[j] = D[:3]
    return sigma, Dphi
