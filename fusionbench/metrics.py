"""Alignment errors against truth, theoretical limits, settling time and statistics.

Errors are misalignment angles phi = [phiE, phiN, phiU] (rad, ENU) with
``C_bn_est = (I - [phi x]) C_bn_true`` (see :mod:`fusionbench.attitude`).

Theoretical limits of stationary alignment (any unbiased method, biases unobservable):
with the accelerometer bias ``nabla^n = C_bn nabla^b`` and gyro bias ``eps^n = C_bn eps^b``
resolved in ENU, g the local gravity and Omega the earth rate::

    phiE = -nabla_N / g
    phiN =  nabla_E / g
    phiU = -eps_E / (Omega cos L) + tan(L) nabla_E / g

:func:`attainable_bound` gives the rest: the standard deviation about that limit which an optimal
estimator reaches with the sensors' noise (white noise, random and drifting bias parts) and the
velocity reference's noise, on a static, swaying or moving base.
"""

from __future__ import annotations

import numpy as np

from . import attitude, earth


def misalignment_history(C_bn_est, C_bn_true):
    """phi (rad, ENU), shape (R, M, 3), of estimates (R, M, 3, 3) against truth (M, 3, 3).

    Run by run, so that the temporaries of the rotation-vector conversion are one run's (a 20-hour history at 1 s
    holds 72 000 attitudes a run; all runs at once cost about 22 MB a run over the result)."""
    C_est = np.asarray(C_bn_est, dtype=float)
    C_true = np.asarray(C_bn_true, dtype=float)
    out = np.empty(C_est.shape[:-1])
    for r in range(C_est.shape[0]):
        out[r] = attitude.misalignment(C_est[r], C_true)
    return out


def theoretical_limits(gyro_bias_b, accel_bias_b, C_bn, lat, h=0.0, f_n=None, w_in=None):
    """Limit misalignment (rad, ENU) of alignment with unknown constant biases, shape (..., 3).

    The steady state of the error model in which the level velocity errors stop changing and the east tilt
    stops drifting (the gyrocompass condition)::

        dvE' =  fN phiU - fU phiN + nabE = 0
        dvN' = -fE phiU + fU phiE + nabN = 0
        phiE' = wU phiN - wN phiU - epsE = 0

    with ``f^n = [fE, fN, fU]`` the base's specific force and ``w_in = [wE, wN, wU]`` the navigation
    frame's rate (the term wE is dropped with the level rows it multiplies). On a stationary or swaying
    base (``f_n = [0, 0, g]``, ``w_in`` the earth rate: the defaults) it is the classical limit of the
    module docstring; on a base accelerating steadily the specific force leans and the azimuth limit
    couples into the level by fN / g and fE / g (a gyro bias's azimuth limit of 5 deg comes with a
    level limit of 30 arcmin at 0.1 g).

    Parameters
    ----------
    gyro_bias_b : array_like, shape (..., 3)
        Gyro bias, body frame, rad/s.
    accel_bias_b : array_like, shape (..., 3)
        Accelerometer bias, body frame, m/s^2.
    C_bn : array_like, shape (..., 3, 3)
        True attitude.
    lat : float or array_like
        Latitude, rad.
    h : float or array_like
        Height, m.
    f_n : array_like, shape (..., 3), optional
        Mean specific force of the base, ENU, m/s^2 (default ``[0, 0, g]``: not accelerating).
    w_in : array_like, shape (..., 3), optional
        Rate of the navigation frame, ENU, rad/s (default the earth rate at ``lat``; add the transport
        rate on a moving base).
    """
    C = np.asarray(C_bn, dtype=float)
    eps = np.einsum("...ij,...j->...i", C, np.asarray(gyro_bias_b, dtype=float))
    nab = np.einsum("...ij,...j->...i", C, np.asarray(accel_bias_b, dtype=float))
    g = earth.gravity(lat, h)
    if f_n is None and w_in is None:  # the closed form
        wn = earth.OMEGA_IE * np.cos(lat)
        return np.stack(
            [-nab[..., 1] / g, nab[..., 0] / g, -eps[..., 0] / wn + np.tan(lat) * nab[..., 0] / g], axis=-1
        )
    f = np.broadcast_to(np.stack([np.zeros_like(g), np.zeros_like(g), g], -1) if f_n is None
                        else np.asarray(f_n, dtype=float), eps.shape)
    w = np.broadcast_to(earth.earth_rate_n(lat) if w_in is None else np.asarray(w_in, dtype=float), eps.shape)
    A = np.zeros(eps.shape + (3,))
    A[..., 0, 1], A[..., 0, 2] = -f[..., 2], f[..., 1]       # dvE' row
    A[..., 1, 0], A[..., 1, 2] = f[..., 2], -f[..., 0]       # dvN' row
    A[..., 2, 1], A[..., 2, 2] = w[..., 2], -w[..., 1]       # phiE' row
    b = -np.stack([nab[..., 0], nab[..., 1], -eps[..., 0]], axis=-1)
    return np.linalg.solve(A, b[..., None])[..., 0]


def settling_time(t, x, band, target=0.0):
    """First time after which ``|x - target|`` stays inside ``band`` until the end.

    Settling is measured against the truth: ``x`` is an error history (estimate minus truth, e.g. phiU
    in arcmin) and ``target`` the error a method should settle on, the theoretical limit (constant, or
    a history like ``x`` when the limit moves with the attitude). A method that settles on a wrong
    value does not settle.

    Parameters
    ----------
    t : array_like, shape (M,)
        Times, s.
    x : array_like, shape (..., M)
        Error histories, e.g. phiU in arcmin.
    band : float
        Half-width of the band, same units as ``x``.
    target : float or array_like broadcastable to ``x``
        Where the error should settle (the limit), same units as ``x``.

    Returns
    -------
    ndarray, shape (...)
        Settling time, s: ``t[0]`` if always inside; ``t[-1]`` for a history that ends outside the band
        (not settled: :func:`settled` tells these apart).
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    outside = np.abs(x - target) > band
    any_out = outside.any(axis=-1)
    last_out = x.shape[-1] - 1 - np.argmax(outside[..., ::-1], axis=-1)
    idx = np.where(any_out, np.minimum(last_out + 1, x.shape[-1] - 1), 0)
    return t[idx]


def settled(x, band, target=0.0):
    """Whether each history ``x`` (..., M) ends inside ``band`` around ``target`` (bool, shape (...))."""
    x = np.asarray(x, dtype=float)
    target = np.broadcast_to(np.asarray(target, dtype=float), x.shape)
    return np.abs(x[..., -1] - target[..., -1]) <= band


def stats(x):
    """``{"mean", "std", "rms", "max_abs"}`` of the values in ``x`` (floats, same units as x)."""
    x = np.asarray(x, dtype=float).ravel()
    return {
        "mean": float(np.mean(x)),
        "std": float(np.std(x)),
        "rms": float(np.sqrt(np.mean(x**2))),
        "max_abs": float(np.max(np.abs(x))),
    }


# ------------------------------------------------------------------------------ attainable bound
#: Floor of the per-step velocity-measurement standard deviation, m/s: an exact reference
#: (``vref_sigma = 0``) is taken as this, far below what any accelerometer's white noise adds to
#: the velocity over a step (1 ug/sqrt(Hz) gives 3e-6 m/s over 0.1 s).
VREF_FLOOR = 1e-9

_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)


def _expm(A):
    """exp(A) of a stack of matrices (K, m, m): Taylor series of degree 12 after scaling to norm 1/2, then squaring."""
    nrm = float(np.max(np.sum(np.abs(A), axis=-2)))
    s = max(0, int(np.ceil(np.log2(nrm / 0.5)))) if nrm > 0 else 0
    X = A / 2.0**s
    eye = np.eye(A.shape[-1])
    E = eye + X / 12.0
    for k in range(11, 0, -1):
        E = eye + (X @ E) / k
    for _ in range(s):
        E = E @ E
    return E


def _bound_error(name, expected, found):
    return ValueError(f"{name}: expected {expected}, found {found}")


def _positive(x, name, unit):
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise _bound_error(name, f"a positive number of {unit}", repr(x)) from None
    if not (np.isfinite(v) and v > 0):
        raise _bound_error(name, f"a positive number of {unit}", v)
    return v


def attainable_bound(spec, duration, site=None, trajectory=None, vref_sigma=0.0, vref_dt=0.01, step_s=0.5,
                     C_bn=None, initial_sigma=(1.0, 1.0, 1.0, 10.0, 10.0)):
    """Standard deviation of the misalignment an optimal estimator reaches, beyond the theoretical limit.

    Any stationary alignment lands on :func:`theoretical_limits`, the part of the error caused by
    the fixed (deterministic) biases ``spec.gyro.bias`` and ``spec.accel.bias``. This function gives
    the rest: the error covariance of the linear alignment error model with the true noise
    statistics and the fixed biases known, i.e. what the Kalman filter with the exact model (the
    optimal estimator for it) attains at each time. An aligner's error about the limit cannot have
    a smaller standard deviation.

    Model (ENU psi-angle, as :mod:`baselines.kalman`), states ``[phiE, phiN, phiU, dvE, dvN]``
    (rad, m/s) plus, in the body frame and only where the spec has them, a random-bias state per
    axis with initial std ``bias_sigma`` driven by ``random_walk`` (a per-run constant plus a
    rate/acceleration random walk) and a first-order Gauss-Markov state (steady std
    ``instability``, correlation time ``tau``), for the gyro (eps) and the accelerometer (nab)::

        phi' = -[w_in x] phi - C_bn (eps + w_g)
        dv'  = ([f^n x] phi)[E,N] + (C_bn (nab + w_a))[E,N] - [(2 w_ie + w_en) x]_(2x2) dv

    with ``w_g``, ``w_a`` the white noises (``spec.*.white``: rad/sqrt(s), m/s/sqrt(s), scaled by
    any ``spec.schedules`` factor). Scale-factor, axis-misalignment and quantisation errors, the
    vertical channel and position errors are not modelled (nor are they in the Kalman filter).

    The record is cut into ``ceil(duration / step_s)`` equal steps; each step is discretised
    exactly (Van Loan, :func:`scipy.linalg.expm`) with ``C_bn``, ``f^n`` and the rates averaged
    over four Gauss-Legendre points of the step (a swaying base: keep the step a fraction of the
    sway periods). At each step end the horizontal velocity error is measured with noise variance
    ``vref_sigma^2 vref_dt / step`` per axis, the information of all the reference samples of the
    step (their average, attributed to the step end: accurate while the velocity error changes
    little within a step compared with that noise). The covariance is propagated and updated in
    square-root form (QR of the pre-arrays), which keeps it positive and accurate with a diffuse
    start and an exact reference.

    Parameters
    ----------
    spec : fusionbench.imu.IMUSpec
        The IMU; its noise parts (white, bias_sigma, random_walk, instability, tau, schedules) are used.
    duration : float
        Record length, s.
    site : fusionbench.aligner.Site, optional
        Static base at this site (latitude, height). Exactly one of ``site`` and ``trajectory``.
    trajectory : fusionbench.trajectory.Trajectory, optional
        Swaying or moving base: its truth gives C_bn(t), f^n(t) = C_bn f^b, the earth and transport
        rates (ENU) along the path, evaluated over [0, duration] (past its own ``duration`` a
        profile continues as its definition extends it).
    vref_sigma : float or (3,) array_like
        White-noise std of each velocity-reference sample, m/s (ENU; the east and north values
        are used). 0 means an exact velocity; the per-step measurement std is floored at
        :data:`VREF_FLOOR` (1e-9 m/s) so that the filter stays well defined.
    vref_dt : float
        Interval of the reference samples, s.
    step_s : float
        Filter step, s (0.5: fine for a static base and for sway periods of 2 s and more).
    C_bn : (3, 3) array_like, optional
        Attitude of the static base with ``site`` (body RFU to ENU; default identity: level,
        facing north). It matters only through body-frame random biases and anisotropic noise.
    initial_sigma : (5,) array_like
        Initial std of ``[phiE, phiN, phiU]`` (rad) and ``[dvE, dvN]`` (m/s). The default, 1 rad
        and 10 m/s, is diffuse: a few minutes of data carry 1e5 times more information.
        The bias states start at their prior stds.

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
    from .imu import IMUSpec, _psd_factor

    if not isinstance(spec, IMUSpec):
        raise _bound_error("spec", "an IMUSpec", type(spec).__name__)
    if (site is None) == (trajectory is None):
        raise _bound_error("site, trajectory", "exactly one of them", "both" if site is not None else "neither")
    duration = _positive(duration, "duration", "s")
    step_s = _positive(step_s, "step_s", "s")
    vref_dt = _positive(vref_dt, "vref_dt", "s")
    try:
        vs = np.broadcast_to(np.asarray(vref_sigma, dtype=float), (3,))
    except (TypeError, ValueError):
        raise _bound_error("vref_sigma", "a non-negative number of m/s or an ENU 3-vector", repr(vref_sigma)) from None
    if not (np.all(np.isfinite(vs)) and np.all(vs >= 0)):
        raise _bound_error("vref_sigma", "non-negative m/s", vs.tolist())
    try:
        s0 = np.broadcast_to(np.asarray(initial_sigma, dtype=float), (5,))
    except (TypeError, ValueError):
        raise _bound_error("initial_sigma", "5 stds [phiE, phiN, phiU] rad, [dvE, dvN] m/s", repr(initial_sigma)) from None
    if not (np.all(np.isfinite(s0)) and np.all(s0 > 0)):
        raise _bound_error("initial_sigma", "positive finite stds", s0.tolist())

    M = max(1, int(np.ceil(duration / step_s - 1e-9)))
    T = duration / M
    t_end = T * np.arange(1, M + 1)
    tq = ((t_end - T / 2)[:, None] + T / 2 * _GL_X[None, :]).ravel()  # 4 points per step
    Cq, fq, w_in, w_cor = _bound_kinematics(tq, M, site, trajectory, C_bn)
    F, Qc, P0 = _bound_model(spec, tq, M, Cq, fq, w_in, w_cor, s0, _psd_factor)
    Phi, L = _discretise(F, Qc, T)
    r_sd = np.maximum(vs[:2] * np.sqrt(vref_dt / T), VREF_FLOOR)
    return t_end, _square_root_filter(Phi, L, P0, r_sd, M)


def _bound_kinematics(tq, M, site, trajectory, C_bn):
    """Attitude (M, 4, 3, 3), specific force and the rates in the attitude and Coriolis terms (M, 4, 3), ENU, at
    the 4 Gauss-Legendre points of each of the M steps: of a fixed ``site`` (attitude ``C_bn``) or of a
    ``trajectory``'s truth."""
    if site is not None:
        C = np.eye(3) if C_bn is None else np.asarray(C_bn, dtype=float)
        if C.shape != (3, 3) or not np.all(np.isfinite(C)):
            raise _bound_error("C_bn", "a finite 3x3 attitude matrix", f"shape {C.shape}")
        w_ie = earth.earth_rate_n(site.lat)
        return (np.broadcast_to(C, (M, 4, 3, 3)), np.broadcast_to(-earth.gravity_n(site.lat, site.h), (M, 4, 3)),
                np.broadcast_to(w_ie, (M, 4, 3)), np.broadcast_to(2 * w_ie, (M, 4, 3)))
    if C_bn is not None:
        raise _bound_error("C_bn", "None with a trajectory (its truth gives the attitude)", "a matrix")
    tr = trajectory.truth(tq)
    _, f_b = trajectory.kinematics(tq)
    w_ie = earth.earth_rate_n(tr.lat)
    w_en = earth.transport_rate_n(tr.v_n, tr.lat, tr.h)
    return (tr.C_bn.reshape(M, 4, 3, 3), np.einsum("nij,nj->ni", tr.C_bn, f_b).reshape(M, 4, 3),
            (w_ie + w_en).reshape(M, 4, 3), (2 * w_ie + w_en).reshape(M, 4, 3))


def _bound_model(spec, tq, M, Cq, fq, w_in, w_cor, s0, psd_factor):
    """The continuous error model over each step (step means of the 4 points): ``F`` and ``Qc`` (M, n, n) and the
    initial variances ``P0`` (n,); states phi (0:3, rad), dv (3:5, m/s), then a bias block of 3 per bias kind
    the spec has (a random constant with its walk; a Gauss-Markov instability), body frame."""
    w = _GL_W / 2  # weights of the step mean
    g, a = spec.gyro, spec.accel
    blocks = []  # (sensor, initial std (3,), process-noise PSD (3,), decay rate 1/s)
    for sensor, e in (("gyro", g), ("accel", a)):
        if any(e.bias_sigma) or any(e.random_walk):
            blocks.append((sensor, np.array(e.bias_sigma), np.square(e.random_walk), 0.0))
        if any(e.instability):
            blocks.append((sensor, np.array(e.instability), 2 * np.square(e.instability) / e.tau, 1.0 / e.tau))
    n = 5 + 3 * len(blocks)
    Cm = np.einsum("q,mqij->mij", w, Cq)
    F = np.zeros((M, n, n))
    F[:, 0:3, 0:3] = -attitude.skew(np.einsum("q,mqi->mi", w, w_in))
    F[:, 3:5, 0:3] = attitude.skew(np.einsum("q,mqi->mi", w, fq))[:, :2]
    F[:, 3:5, 3:5] = -attitude.skew(np.einsum("q,mqi->mi", w, w_cor))[:, :2, :2]
    Qc = np.zeros((M, n, n))
    qg = np.einsum("q,mq->m", w, psd_factor(tq, spec.schedules, "gyro").reshape(M, 4))
    qa = np.einsum("q,mq->m", w, psd_factor(tq, spec.schedules, "accel").reshape(M, 4))
    Qc[:, 0:3, 0:3] = qg[:, None, None] * np.einsum("q,mqij,j,mqkj->mik", w, Cq, np.square(g.white), Cq)
    Qc[:, 3:5, 3:5] = qa[:, None, None] * np.einsum("q,mqij,j,mqkj->mik", w, Cq, np.square(a.white), Cq)[:, :2, :2]
    P0 = np.zeros(n)
    P0[:5] = np.square(s0)
    for i, (sensor, sig0, q, decay) in enumerate(blocks):
        k = 5 + 3 * i
        if sensor == "gyro":
            F[:, 0:3, k:k + 3] = -Cm
        else:
            F[:, 3:5, k:k + 3] = Cm[:, :2]
        F[:, k:k + 3, k:k + 3] = -decay * np.eye(3)
        Qc[:, k:k + 3, k:k + 3] = np.diag(q)
        P0[k:k + 3] = np.square(sig0)
    return F, Qc, P0


def _discretise(F, Qc, T):
    """Transition ``Phi`` and a square root ``L`` of the process noise ``Qd = L L^T`` over a step of ``T`` s (Van
    Loan); one discretisation when every step has the same model (a static base)."""
    n = F.shape[1]
    if np.all(F == F[0]) and np.all(Qc == Qc[0]):
        F, Qc = F[:1], Qc[:1]
    # Van Loan: expm([[-F, Qc], [0, F^T]] T) = [[., Phi^-1 Qd], [0, Phi^T]]
    A = np.zeros((F.shape[0], 2 * n, 2 * n))
    A[:, :n, :n] = -F * T
    A[:, :n, n:] = Qc * T
    A[:, n:, n:] = np.swapaxes(F, 1, 2) * T
    E = _expm(A)
    Phi = np.swapaxes(E[:, n:, n:], 1, 2)
    Qd = Phi @ E[:, :n, n:]
    Qd = 0.5 * (Qd + np.swapaxes(Qd, 1, 2))
    # Qd = L L^T from the eigen-decomposition of Qd scaled to a unit diagonal (its entries span
    # many orders of magnitude: rad^2, (m/s)^2, bias units)
    dq = np.sqrt(np.diagonal(Qd, axis1=1, axis2=2))
    dq = np.where(dq > 0, dq, 1.0)
    lam, V = np.linalg.eigh(Qd / (dq[:, :, None] * dq[:, None, :]))
    return Phi, dq[:, :, None] * V * np.sqrt(np.clip(lam, 0.0, None))[:, None, :]


def _square_root_filter(Phi, L, P0, r_sd, M):
    """The attitude sigmas (M, 3) rad of a square-root Kalman filter over M steps, measuring dvE, dvN with noise
    std ``r_sd`` (2,) m/s at each step."""
    n = P0.size
    S = np.diag(np.sqrt(P0))  # P = S S^T
    pre = np.zeros((n + 2, n + 2))
    pre[0, 0], pre[1, 1] = r_sd
    sigma = np.empty((M, 3))
    for j in range(M):
        i = min(j, Phi.shape[0] - 1)
        # time update: P- = Phi P Phi^T + Qd, as R^T R of the QR of [S^T Phi^T; L^T]
        S = np.linalg.qr(np.vstack([(Phi[i] @ S).T, L[i].T]), mode="r").T
        # measurement update of dvE, dvN (H S = rows 3, 4 of S): QR of [[R^1/2, 0], [(H S)^T, S^T]]
        pre[2:, :2] = S[3:5].T
        pre[2:, 2:] = S.T
        S = np.linalg.qr(pre, mode="r")[2:, 2:].T
        sigma[j] = np.sqrt(np.sum(S[:3] ** 2, axis=1))
    return sigma
