"""The linear error model behind :mod:`fusionbench.scoring.bound`: the record cut into filter steps, the psi-angle error
model of each step discretised exactly, and the measurements at the step ends (a per-increment velocity reference,
or a receiver's rows with their lever arm).

States, in this order: ``[phiE, phiN, phiU]`` (rad, ENU, ``C_est = (I - [phi x]) C_true``), ``[dvE, dvN]`` (m/s),
``[dpE, dpN]`` (m, east and north position error, only when positions are measured; the height is held), then a
block of 3 body-frame states (RFU) per bias kind the model has: a random constant with its walk, and a first-order
Gauss-Markov instability, for the gyro (rad/s) and the accelerometer (m/s^2), and last, where the base has a velocity
disturbance that the measurements do not report (:func:`disturbance_block`), the states of its model. Errors are
estimate minus truth.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg, signal

from fusionbench.simulation import attitude, earth

_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)

#: Floor of the per-step velocity-measurement standard deviation, m/s: an exact reference
#: (``vref_sigma = 0``) is taken as this, far below what any accelerometer's white noise adds to
#: the velocity over a step (1 ug/sqrt(Hz) gives 3e-6 m/s over 0.1 s).
VREF_FLOOR = 1e-9
#: Floor of a position row's standard deviation, m (an exact position).
POSITION_FLOOR = 1e-9
#: Initial standard deviation of the east and north position errors, m, when ``initial_sigma`` does not give them:
#: diffuse against any receiver's position noise.
INITIAL_POSITION_SIGMA = 1e3
#: Order of the Butterworth band-pass that models a base's velocity disturbance on each horizontal axis
#: (:func:`disturbance_block`; 2 states per order): order 8 changes seed 000's (Zhou 2011, ADRC gyrocompass) and a
#: tactical IMU's bounds on a moored base with 0.05 m/s by 0.1 % in azimuth and 2 % in level.
DISTURBANCE_ORDER = 4


def bound_error(name, expected, found):
    """The one-line ValueError naming the argument, what was expected and what was found."""
    return ValueError(f"{name}: expected {expected}, found {found}")


def positive(x, name, unit):
    """``x`` as a positive finite float, or :func:`bound_error`."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise bound_error(name, f"a positive number of {unit}", repr(x)) from None
    if not (np.isfinite(v) and v > 0):
        raise bound_error(name, f"a positive number of {unit}", v)
    return v


def step_grid(duration, step_s, rate_hz=None):
    """Step end times ``t_end`` (M,) s, step lengths ``T`` (M,) s and the number ``k`` of steps between two receiver
    epochs. Without a receiver ``ceil(duration / step_s)`` equal steps; with one at ``rate_hz``, steps of
    ``1 / (k rate_hz)`` with ``k = ceil(1 / (rate_hz step_s))`` (never longer than ``step_s``, every epoch
    ``j / rate_hz`` the end of step ``j k``), the last shortened to end at ``duration``."""
    if rate_hz is None:
        M = max(1, int(np.ceil(duration / step_s - 1e-9)))
        T = duration / M
        return T * np.arange(1, M + 1), np.full(M, T), None
    k = max(1, int(np.ceil(1.0 / (rate_hz * step_s) - 1e-9)))
    T0 = 1.0 / (rate_hz * k)
    M = max(1, int(np.ceil(duration / T0 - 1e-9)))
    t_end = T0 * np.arange(1, M + 1)
    T = np.full(M, T0)
    last = duration - (M - 1) * T0
    if abs(last - T0) > 1e-9 * T0:
        T[-1] = last
    t_end[-1] = duration
    return t_end, T, k


def kinematics(tq, M, site, trajectory, C_bn):
    """Attitude (M, 4, 3, 3), specific force and the rates in the attitude and Coriolis terms (M, 4, 3), ENU, at
    the 4 Gauss-Legendre points ``tq`` (4 M,) s of each of the M steps: of a fixed ``site`` (attitude ``C_bn``) or
    of a ``trajectory``'s truth."""
    if site is not None:
        C = np.eye(3) if C_bn is None else np.asarray(C_bn, dtype=float)
        if C.shape != (3, 3) or not np.all(np.isfinite(C)):
            raise bound_error("C_bn", "a finite 3x3 attitude matrix", f"shape {C.shape}")
        w_ie = earth.earth_rate_n(site.lat)
        return (np.broadcast_to(C, (M, 4, 3, 3)), np.broadcast_to(-earth.gravity_n(site.lat, site.h), (M, 4, 3)),
                np.broadcast_to(w_ie, (M, 4, 3)), np.broadcast_to(2 * w_ie, (M, 4, 3)))
    if C_bn is not None:
        raise bound_error("C_bn", "None with a trajectory (its truth gives the attitude)", "a matrix")
    tr = trajectory.truth(tq)
    _, f_b = trajectory.kinematics(tq)
    w_ie = earth.earth_rate_n(tr.lat)
    w_en = earth.transport_rate_n(tr.v_n, tr.lat, tr.h)
    return (tr.C_bn.reshape(M, 4, 3, 3), np.einsum("nij,nj->ni", tr.C_bn, f_b).reshape(M, 4, 3),
            (w_ie + w_en).reshape(M, 4, 3), (2 * w_ie + w_en).reshape(M, 4, 3))


def error_model(spec, tq, M, Cq, fq, w_in, w_cor, s0, psd_factor, position=False, fixed_prior=False):
    """The continuous error model over each step (step means of the 4 points): ``F`` and ``Qc`` (M, n, n), the
    initial variances ``P0`` (n,) and the first index of the gyro's and the accelerometer's random-constant block
    (``{"gyro": k, "accel": k}``, absent where there is none). ``s0``: initial stds of phi, dv (and dp with
    ``position``). With ``fixed_prior`` the fixed biases join the random constant's prior (variance ``bias^2 +
    bias_sigma^2``; with the instability's the project's filters' total), else they are known (prior
    ``bias_sigma``)."""
    w = _GL_W / 2  # weights of the step mean
    g, a = spec.gyro, spec.accel
    blocks = []  # (sensor, initial std (3,), process-noise PSD (3,), decay rate 1/s, a random constant)
    for sensor, e in (("gyro", g), ("accel", a)):
        fixed = np.asarray(e.bias, dtype=float) if fixed_prior else np.zeros(3)
        if any(e.bias_sigma) or any(e.random_walk) or any(fixed):
            blocks.append((sensor, np.hypot(fixed, e.bias_sigma), np.square(e.random_walk), 0.0, True))
        if any(e.instability):
            blocks.append((sensor, np.array(e.instability), 2 * np.square(e.instability) / e.tau, 1.0 / e.tau, False))
    nb = 7 if position else 5
    n = nb + 3 * len(blocks)
    Cm = np.einsum("q,mqij->mij", w, Cq)
    F = np.zeros((M, n, n))
    F[:, 0:3, 0:3] = -attitude.skew(np.einsum("q,mqi->mi", w, w_in))
    F[:, 3:5, 0:3] = attitude.skew(np.einsum("q,mqi->mi", w, fq))[:, :2]
    F[:, 3:5, 3:5] = -attitude.skew(np.einsum("q,mqi->mi", w, w_cor))[:, :2, :2]
    if position:
        F[:, 5:7, 3:5] = np.eye(2)
    Qc = np.zeros((M, n, n))
    qg = np.einsum("q,mq->m", w, psd_factor(tq, spec.schedules, "gyro").reshape(M, 4))
    qa = np.einsum("q,mq->m", w, psd_factor(tq, spec.schedules, "accel").reshape(M, 4))
    Qc[:, 0:3, 0:3] = qg[:, None, None] * np.einsum("q,mqij,j,mqkj->mik", w, Cq, np.square(g.white), Cq)
    Qc[:, 3:5, 3:5] = qa[:, None, None] * np.einsum("q,mqij,j,mqkj->mik", w, Cq, np.square(a.white), Cq)[:, :2, :2]
    P0 = np.zeros(n)
    P0[:nb] = np.square(s0)
    constant = {}
    for i, (sensor, sig0, q, decay, is_constant) in enumerate(blocks):
        k = nb + 3 * i
        if sensor == "gyro":
            F[:, 0:3, k:k + 3] = -Cm
        else:
            F[:, 3:5, k:k + 3] = Cm[:, :2]
        F[:, k:k + 3, k:k + 3] = -decay * np.eye(3)
        Qc[:, k:k + 3, k:k + 3] = np.diag(q)
        P0[k:k + 3] = np.square(sig0)
        if is_constant:
            constant[sensor] = k
    return F, Qc, P0, constant


def unreported_disturbance(trajectory, aiding):
    """The base's velocity disturbance where the measurements do not report it, and the trajectory whose truth the
    model's kinematics follow.

    The per-increment reference reports the nominal motion only, and so does a receiver on a fixed base (zero
    velocity, the site): the disturbance is then a random process unknown to the aligner, returned with the
    trajectory without it (its accelerations are not known motion). A receiver on a moving base measures the true
    velocity, disturbance included: ``(None, trajectory)``, as without a disturbance. A disturbance on the vertical
    axis only is left out with the vertical channel: ``(None, the trajectory without it)``."""
    from dataclasses import replace

    dist = None if trajectory is None else getattr(trajectory.translation, "disturbance", None)
    if dist is None or (aiding is not None and not trajectory.translation.is_static()):
        return None, trajectory
    try:
        rms = np.broadcast_to(np.asarray(dist.rms, dtype=float), (3,))
        lo, hi = (float(f) for f in dist.band)
    except (AttributeError, TypeError, ValueError):
        raise bound_error("trajectory", "a disturbance with an rms (3,) m/s and a band (2,) Hz",
                          type(dist).__name__) from None
    if not (np.all(np.isfinite(rms)) and np.all(rms >= 0) and 0 < lo < hi < np.inf):
        raise bound_error("trajectory", "a disturbance's rms >= 0 m/s and band 0 < low < high Hz",
                          f"rms {rms.tolist()}, band {[lo, hi]}")
    nominal = replace(trajectory, translation=replace(trajectory.translation, disturbance=None))
    return (dist if np.any(rms[:2] > 0) else None), nominal


def _band_pass(rms, f1, f2):
    """The order-:data:`DISTURBANCE_ORDER` Butterworth band-pass ``[f1, f2]`` Hz driven by white noise, scaled to a
    stationary output rms of ``rms`` m/s: ``(A, Q, c)``, ``x' = A x + w``, ``E[w w^T] = Q delta``, velocity ``c x``,
    in coordinates where its stationary covariance is the identity. A cascade of sections ``s / (s^2 + a1 s + a0)``
    (one per pair of poles), each section's output the next one's input: well scaled where the polynomial's
    companion form would span the band's powers."""
    _, poles, _ = signal.butter(DISTURBANCE_ORDER, [2 * np.pi * f1, 2 * np.pi * f2], "bandpass", analog=True,
                                output="zpk")
    m = 2 * DISTURBANCE_ORDER
    A, Q = np.zeros((m, m)), np.zeros((m, m))
    for i, p in enumerate(poles[poles.imag > 0]):  # y'' = -|p|^2 y + 2 Re(p) y' + input, output y'
        A[2 * i, 2 * i + 1] = 1.0
        A[2 * i + 1, 2 * i], A[2 * i + 1, 2 * i + 1] = -abs(p) ** 2, 2 * p.real
        if i:
            A[2 * i + 1, 2 * i - 1] = 1.0
    Q[1, 1] = 1.0
    P = linalg.solve_continuous_lyapunov(A, -Q)
    Q, P = Q * rms**2 / P[-1, -1], P * rms**2 / P[-1, -1]
    T = np.linalg.cholesky(P)  # x = T z: z's stationary covariance is I
    Ti = linalg.solve_triangular(T, np.eye(m), lower=True)
    return Ti @ A @ T, Ti @ Q @ Ti.T, T[-1]


def disturbance_block(dist, F, Qc, P0, rows):
    """Append a model of a base's velocity disturbance that the measurements do not report to the continuous error
    model ``F``, ``Qc`` (M, n, n) and the initial variances ``P0`` (n,).

    The disturbance (:class:`fusionbench.simulation.translation.VelocityDisturbance`) has on each ENU axis an rms
    velocity spread uniformly over its band ``[f1, f2]`` Hz (its spectrum over the random frequencies and phases). Its
    velocity ``v_d`` on each horizontal axis with an rms is modelled as white noise through a Butterworth band-pass
    of order :data:`DISTURBANCE_ORDER` over that band (its spectrum peaks at 97 % of the flat one, is half of that at
    the band's edges and under 0.3 % of it a factor 2 beyond them), stationary from the start with that rms. The term ``[a_d x] phi`` of
    its acceleration ``a_d`` in the velocity error is second order in what the aligner does not know and left out:
    a horizontal disturbance turned by the azimuth error is one of the same statistics.

    ``rows`` says what the disturbance adds to the measurements: ``"average"`` (the per-increment reference: the
    average over a step of ``dv + v_d``, from accumulators ``A' = dv + v_d`` (m) that restart at every step),
    ``"velocity"`` and/or ``"position"`` (a receiver on a fixed base: ``v_d`` at the row's time, and the
    displacement since the start from ``D' = v_d``, ``D(0) = 0``, m).

    Returns
    -------
    F, Qc : ndarray, shape (M, N, N)
    P0 : ndarray, shape (N,)
    out : dict
        ``(2, N)`` coefficients of the state giving what the disturbance makes of each kind of row in ``rows`` (E
        and N; the ``"average"`` ones the accumulators, to divide by the step length), and ``"reset"`` the indices
        of the accumulators.
    """
    M, n = F.shape[:2]
    m = 2 * DISTURBANCE_ORDER
    rms = np.asarray(dist.rms, dtype=float)[:2]
    axes = [a for a in range(2) if rms[a] > 0]
    kinds = [k for k in ("average", "position") if k in rows]
    N = n + m * len(axes) + 2 * len(kinds)
    Fx, Qx, Px = np.zeros((M, N, N)), np.zeros((M, N, N)), np.zeros(N)
    Fx[:, :n, :n], Qx[:, :n, :n], Px[:n] = F, Qc, P0
    vel = np.zeros((2, N))  # v_d (E, N) from the state
    for i, a in enumerate(axes):
        x = n + m * i
        Fx[:, x:x + m, x:x + m], Qx[:, x:x + m, x:x + m], vel[a, x:x + m] = _band_pass(rms[a], *dist.band)
        Px[x:x + m] = 1.0
    out, j = {"velocity": vel, "reset": []}, n + m * len(axes)
    for kind in kinds:
        rate = vel.copy()  # A' = dv + v_d, D' = v_d
        if kind == "average":
            rate[0, 3] = rate[1, 4] = 1.0
            out["reset"] = [j, j + 1]
        Fx[:, j:j + 2, :] = rate
        out[kind] = np.eye(N)[j:j + 2]
        j += 2
    return Fx, Qx, Px, out


def _van_loan(F, Qc, T):
    """``Phi^-1 Qd`` and ``Phi^T`` of stacks (K, n, n): the upper-right and lower-right blocks of
    ``exp([[-F, Qc], [0, F^T]] T)`` (Van Loan), ``T`` (K,) s. The exponential is computed by its blocks (the
    lower-left one is zero): a Taylor series of degree 12 after scaling the whole matrix to norm 1/2, then squaring,
    at half the cost of the 2n x 2n products."""
    Tm = np.asarray(T, dtype=float)[:, None, None]
    X11, X12, X22 = -F * Tm, Qc * Tm, np.swapaxes(F, 1, 2) * Tm
    nrm = float(max(np.max(np.sum(np.abs(X11), axis=-2)),
                    np.max(np.sum(np.abs(X12), axis=-2) + np.sum(np.abs(X22), axis=-2))))
    s = max(0, int(np.ceil(np.log2(nrm / 0.5)))) if nrm > 0 else 0
    X11, X12, X22 = X11 / 2.0**s, X12 / 2.0**s, X22 / 2.0**s
    eye = np.eye(F.shape[-1])
    E11, E12, E22 = eye + X11 / 12.0, X12 / 12.0, eye + X22 / 12.0
    for k in range(11, 0, -1):
        E12 = (X11 @ E12 + X12 @ E22) / k
        E11 = eye + (X11 @ E11) / k
        E22 = eye + (X22 @ E22) / k
    for _ in range(s):
        E12 = E11 @ E12 + E12 @ E22
        E11 = E11 @ E11
        E22 = E22 @ E22
    return E12, E22


def discretise(F, Qc, T, reset=()):
    """Transitions ``Phi`` and square roots ``L`` of the process noise ``Qd = L L^T`` (U, n, n) over steps of ``T``
    (M,) s (Van Loan), and the index (M,) of each step's pair; one pair per step length when every step has the same
    model (a static base). The states ``reset`` (accumulators) restart from zero at every step: their columns of
    ``Phi`` are zero."""
    n = F.shape[1]
    if np.all(F == F[0]) and np.all(Qc == Qc[0]):
        T, idx = np.unique(T, return_inverse=True)
        F, Qc = np.broadcast_to(F[0], (T.size, n, n)), np.broadcast_to(Qc[0], (T.size, n, n))
    else:
        idx = np.arange(T.size)
    E12, E22 = _van_loan(F, Qc, T)
    Phi = np.swapaxes(E22, 1, 2)
    Qd = Phi @ E12
    Phi[:, :, list(reset)] = 0.0
    Qd = 0.5 * (Qd + np.swapaxes(Qd, 1, 2))
    # Qd = L L^T from the eigen-decomposition of Qd scaled to a unit diagonal (its entries span
    # many orders of magnitude: rad^2, (m/s)^2, bias units); the rows of states without process noise (a random
    # constant bias) stay exactly zero: the rounding of the unit-scaled eigenvectors there would be 1e-16 in bias
    # units, e.g. (rad/s)^2, a gyro bias's whole prior for a navigation-grade gyro
    dq = np.sqrt(np.clip(np.diagonal(Qd, axis1=1, axis2=2), 0.0, None))
    scale = np.where(dq > 0, dq, 1.0)
    lam, V = np.linalg.eigh(Qd / (scale[:, :, None] * scale[:, None, :]))
    return Phi, dq[:, :, None] * V * np.sqrt(np.clip(lam, 0.0, None))[:, None, :], idx


def vref_factor(t_end, T, vref_dt, schedules):
    """The mean variance factor (M,) of the reference samples of each step of ``T`` s ending at ``t_end`` (M,) s,
    samples every ``vref_dt`` s from ``vref_dt`` on, under ``schedules`` (``start``, ``end``, ``factor``: the
    variance times ``factor`` for ``start <= t < end``), 1 without."""
    q = np.ones(t_end.size)
    if not len(schedules):
        return q
    ts = vref_dt * np.arange(1, int(np.floor(t_end[-1] / vref_dt + 1e-9)) + 1)
    qs = np.ones(ts.size)
    for s in schedules:
        try:
            start, end, factor = float(s.start), float(s.end), float(s.factor)
        except (AttributeError, TypeError, ValueError):
            raise bound_error("vref_schedules", "NoiseSchedule items (start, end, factor)", repr(s)) from None
        qs = np.where((ts >= start) & (ts < end), qs * factor, qs)
    step = np.clip(np.ceil(ts / T - 1e-9).astype(int) - 1, 0, t_end.size - 1)
    n = np.bincount(step, minlength=t_end.size)
    return np.where(n > 0, np.bincount(step, qs, minlength=t_end.size) / np.maximum(n, 1), q)


def vref_rows(M, n, r_sd, H=None):
    """The per-increment reference as measurements: at every step end dvE, dvN (or the rows ``H`` (2, n): the step's
    average of dv and an unreported disturbance) with stds ``r_sd`` (2,) or (M, 2) m/s. Returns the measuring steps
    (M,), ``H`` (M, 2, n) and the stds (M, 2)."""
    if H is None:
        H = np.zeros((2, n))
        H[0, 3] = H[1, 4] = 1.0
    return np.arange(M), np.broadcast_to(H, (M, 2, n)), np.broadcast_to(r_sd, (M, 2))


def aiding_rows(aiding, duration, k, n, site, trajectory, C_bn, disturbance=None):
    """A receiver's rows as measurements (the horizontal rows of the antenna's velocity and/or position, at their
    time of validity; the latency does not change the information).

    The antenna's velocity error is ``dv + [u x] phi`` with ``u = C_bn (omega_nb^b x l)`` (zero on a fixed base,
    whose rows say it is at rest) and its position error ``dp + [d x] phi`` with ``d = C_bn l`` (ENU), from
    ``C_est (omega x l) = (I - [phi x]) u``; on a fixed base with an unreported disturbance, plus its velocity and
    displacement (``disturbance``: the ``"velocity"`` and ``"position"`` (2, n) rows of :func:`disturbance_block`).
    Returns the steps ending at a row (K,) (epoch j ends step j k), ``H`` (K, m, n) (velocity rows first) and the
    rows' stds (K, m), m/s and m, scaled by the aiding's schedules."""
    from fusionbench.simulation.aiding_geometry import lever_offset, lever_velocity
    from fusionbench.simulation.aidingsim import epochs

    tv = epochs(aiding.rate_hz, duration)
    if tv.size == 0:
        raise bound_error("aiding", f"a rate giving at least one row in {duration:g} s", f"{aiding.rate_hz:g} Hz")
    step = k * np.arange(1, tv.size + 1) - 1
    keep = np.ones(tv.size, bool)
    for a, b in aiding.outages:
        keep &= ~((tv >= a) & (tv < b))
    q = np.ones(tv.size)
    for s in aiding.schedules:
        q = np.where((tv >= s.start) & (tv < s.end), q * s.factor, q)
    tv, step, q = tv[keep], step[keep], q[keep]
    K = tv.size
    if site is not None:
        C, w_nb, fixed = np.broadcast_to(np.eye(3) if C_bn is None else C_bn, (K, 3, 3)), np.zeros((K, 3)), True
    else:
        (C, w_nb), fixed = trajectory.attitude.attitude(tv), trajectory.translation.is_static()
    lever = np.asarray(aiding.lever_arm, dtype=float)
    H, sd = [], []
    for kind, sigma, col, lever_term, floor in (
            ("velocity", aiding.velocity_sigma, 3, None if fixed else lever_velocity(C, w_nb, lever), VREF_FLOOR),
            ("position", aiding.position_sigma, 5, lever_offset(C, lever), POSITION_FLOOR)):
        if sigma is None:
            continue
        h = np.zeros((K, 2, n)) + (0.0 if disturbance is None else disturbance[kind])
        if lever_term is not None:
            h[:, :, 0:3] = attitude.skew(lever_term)[:, :2]
        h[:, 0, col] = h[:, 1, col + 1] = 1.0
        H.append(h)
        sig = np.broadcast_to(np.asarray(sigma, dtype=float), (3,))[:2]
        sd.append(np.maximum(sig[None, :] * np.sqrt(q)[:, None], floor))
    return step, np.concatenate(H, axis=1), np.concatenate(sd, axis=1)
