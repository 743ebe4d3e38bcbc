"""The NumPy reference of the ESO/TD aligner's compiled loop (:func:`adrc.moving_base_compiled.run_compiled`).

A Python loop over the ESO/TD steps with arrays over runs that makes the compiled loop's operations in its order:
the strapdown over the step's samples, the step's measurement from its rows (:func:`measure`), the ESO of eq. 6,
eqs. 7, 9 and 12 with the fst or least-squares TD (:func:`step`), the velocity reset at rows
(:func:`reset_velocity`) and the attitude feedback (the library's
:meth:`adrc.eso_td_estimator.ESOTDEstimator.feedback`, as the compiled loop calls it). It is the oracle of the
agreement tests (``tests/test_moving_base.py``, ``tests/test_eso_td_aiding.py``) and of
``benchmarks/perf_methods.py``; ``PATCH`` names the library's function it stands in for, for
``monkeypatch.setattr``.
"""

from __future__ import annotations

import numpy as np

from adrc.eso_td_estimator import expanding_memory_gains
from adrc.eso_td_rows import INTERVAL
from fusionbench.simulation import earth
from fusionbench.simulation.aiding_geometry import lever_offset, lever_velocity, rate_at
from fusionbench.simulation.attitude import apply_misalignment


def run_numpy(est, sd, dth_b, dv_b, hist_C, hist_psi, hist_fb, hist_y):
    """The arguments and effects of :func:`adrc.moving_base_compiled.run_compiled`: the steps of ``dth_b``, ``dv_b``
    (steps, R, m, 3) one at a time through the strapdown ``sd`` and the fresh estimator ``est`` (both advanced in
    place), the first ``steps`` entries of the histories ``hist_C``, ``hist_psi``, ``hist_fb``, ``hist_y`` written."""
    est.e_last, est.den0_prev, est.m_prev = None, None, None  # the loop's own state: the reset, eq. 12's integrands
    for j in range(dth_b.shape[0]):
        out = sd.run(dth_b[j], dv_b[j], record_every=1)
        st = sd.state
        psi = step(est, j, out["C_bn"], out["v_n"], dth_b[j], dv_b[j], st)
        hist_C[:, j] = apply_misalignment(st.C_bn, -psi)
        hist_y[:, j] = est.y
        reset_velocity(est, st)  # at rows (keeps eq. 1's neglected dv / R terms negligible)
        if est.feedback_due(j):
            psi = est.feedback(j, psi, st)
        hist_psi[:, j] = psi
        hist_fb[:, j] = est.psi_fb


def measure(rows, j, C_bn, v_n, dth, df_k, v_prev, reset_sum, F_int, P, marks, w_in):
    """The measurement of step ``j`` from ``rows`` (an :class:`adrc.eso_td_rows.StepRows`; compiled:
    :func:`adrc.eso_td_rows_compiled.measure`).

    Parameters
    ----------
    j : int
        The step.
    C_bn, v_n : ndarray, shapes (R, m, 3, 3), (R, m, 3)
        The strapdown's attitude and velocity (ENU, m/s) after each of the step's samples.
    dth, df_k : ndarray, shape (R, m, 3)
        The samples' angle increments (body, rad) and velocity increments in ENU (``C_bn dv``, m/s).
    v_prev : ndarray, shape (R, 2)
        The strapdown's level velocity at the step's start (after the last reset), m/s.
    reset_sum, F_int : ndarray, shapes (R, 2), (R, 3)
        The velocity resets so far (m/s) and ``int f_n dt`` up to the step's start (m/s).
    P, marks : ndarray, shapes (R, 5), (R, n_marks, 8)
        With position intervals: the integrals of the unreset velocity (m) and of ``int f_n dt`` (m) up to the
        step's start, advanced to its end here; each mark's integrals and lever-arm offset ``C_bn l`` (m),
        written here when it falls in the step.
    w_in : ndarray, shape (R, 3)
        omega_in^n, rad/s (earth rate and transport rate, ENU).

    Returns
    -------
    None without rows in the step, else ``y`` (R, 2) the unreset level velocity error (m/s), ``F_bar`` (R, 3)
    ``int f_n dt`` at the rows' times (m/s), ``e_last`` (R, 2) the last row's error (m/s) and its ``age`` (s).
    """
    i0, i1 = rows.start[j], rows.start[j + 1]
    R, dt = v_n.shape[0], rows.dt
    v_ext = np.concatenate([v_prev[:, None], v_n[..., :2]], axis=1)  # the step's start, then each sample end
    F_ext = np.concatenate([np.zeros((R, 1, 3)), np.cumsum(df_k, axis=1)], axis=1)
    if rows.mark_k.size:
        vals = np.concatenate([v_ext + reset_sum[:, None], F_ext + F_int[:, None]], axis=-1)  # (R, m + 1, 5)
        P_ext = P[:, None] + np.concatenate([np.zeros((R, 1, 5)), np.cumsum(
            0.5 * dt * (vals[:, :-1] + vals[:, 1:]), axis=1)], axis=1)
        a, b = rows.mark_start[j], rows.mark_start[j + 1]
        k, w = rows.mark_k[a:b], rows.mark_w[a:b, None]
        marks[:, a:b, :5] = P_ext[:, k] + w * dt * ((1.0 - w / 2.0) * vals[:, k] + w / 2.0 * vals[:, k + 1])
        marks[:, a:b, 5:] = lever_offset(C_bn[:, k], rows.lever_arm)
        P[:] = P_ext[:, -1]
    if i1 == i0:
        return None
    k, w, lev = rows.k[i0:i1], rows.w[i0:i1, None], rows.lever[i0:i1] == 1
    v_at = (1.0 - w) * v_ext[:, k] + w * v_ext[:, k + 1]
    F_at = (1.0 - w) * F_ext[:, k] + w * F_ext[:, k + 1]
    if lev.any():
        C = C_bn[:, k[lev]]
        w_nb = rate_at(dth, dt, k[lev], w[lev, 0]) - np.einsum("rnji,rj->rni", C, w_in)  # omega_ib^b - C omega_in
        v_at[:, lev] += lever_velocity(C, w_nb, rows.lever_arm)[..., :2]
    e = v_at - rows.value[:, i0:i1]
    iv = rows.kind[i0:i1] == INTERVAL
    if iv.any():  # mean over the interval: the integrals' difference over its length
        d = (marks[:, rows.mark1[i0:i1][iv]] - marks[:, rows.mark0[i0:i1][iv]]) * rows.inv_T[i0:i1][iv, None]
        e[:, iv] = d[..., :2] + d[..., 5:7] - rows.value[:, i0:i1][:, iv] - reset_sum[:, None]
        F_at[:, iv] = d[..., 2:5] - F_int[:, None]
    return e.mean(axis=1) + reset_sum, F_int + F_at.mean(axis=1), e[:, -1], rows.age[i1 - 1]


def correct(est, obs, y):
    """One step of the observer ``obs`` (a :class:`adrc.primitives.SecondOrderESO` of ``est``): with the rows'
    measurement ``y``, its gains applied ``n`` times over; None (no rows): the prediction alone."""
    if y is None:
        obs.z1 = obs.z1 + est.h * obs.z2
        return
    b1, b2 = obs.beta1, obs.beta2
    obs.beta1, obs.beta2 = b1 * est.n, b2 * est.n
    obs.update(y)
    obs.beta1, obs.beta2 = b1, b2


def step(est, j, C_bn, v_n, dth, dv, st):
    """Step ``j`` of the estimator ``est`` (an :class:`adrc.eso_td_estimator.ESOTDEstimator`) from the strapdown's
    attitude ``C_bn`` (R, m, 3, 3) and velocity ``v_n`` (R, m, 3) after each of the step's samples, the samples'
    increments ``dth``, ``dv`` (R, m, 3, body: rad, m/s), the strapdown's state ``st`` at the step's end and the rows
    valid in the step; returns psi (R, 3), rad (0 before any row). Sets ``est.y``, the unreset level velocity error
    (R, 2, m/s; NaN without rows), and ``est.e_last``, the reset (:func:`reset_velocity`)."""
    a, h, dt, R = est.a, est.h, est.dt, est.R
    eso, clock, times = est.eso, est.clock, est.times
    f_n = np.einsum("rkij,rkj->ri", C_bn, dv) / h  # specific force, ENU, m/s^2
    lat = st.lat
    rm, rn = earth.radii(lat)
    sl, cl = np.sin(lat), np.cos(lat)
    lon_rate = st.v_n[:, 0] / ((rn + st.h) * cl)
    lat_rate = st.v_n[:, 1] / (rm + st.h)
    W = earth.OMEGA_IE + lon_rate
    cor = (2.0 * earth.OMEGA_IE + lon_rate) * sl     # Coriolis coefficient of eqs. 4, 7, 9
    df_k = np.einsum("rkij,rkj->rki", C_bn, dv)
    meas = measure(est.rows, j, C_bn, v_n, dth, df_k, est.v_prev, est.reset_sum, est.F_int, est.P,
                   est.marks, np.stack([-lat_rate, W * cl, W * sl], axis=-1))  # omega_in^n
    est.F_int = est.F_int + df_k.sum(axis=1)
    y, F_bar, e_last, age = (None, None, None, None) if meas is None else meas
    est.y = np.full((R, 2), np.nan) if y is None else y  # unreset level velocity error, m/s
    if y is None and clock[0] == 0:  # no row yet: nothing to estimate
        return np.zeros((R, 3))
    first = clock[0] == 0
    if y is not None:
        if first:
            eso.reset(y)
            clock[1], times[0] = j, est.rows.offset[j]
        clock[2], times[1], times[2] = j, est.rows.offset[j], est.rows.tau2[j]
        if a.eso_start == "ls":  # the least-squares line through the rows so far, down to the floor
            b1, b2 = expanding_memory_gains(clock[0], h, est.n)
            eso.beta1, eso.beta2 = np.maximum(b1, est.b1_floor), np.maximum(b2, est.b2_floor)
        clock[0] += 1
    correct(est, eso, y)                          # eq. 6, both channels
    est.e_last = None if y is None else e_last + eso.z2 * age  # the reset: the last row's error, now
    z1, z2 = eso.z1, eso.z2
    fE, fN, fU = f_n[:, 0], f_n[:, 1], f_n[:, 2]
    if a.td == "ls":
        eso_f, eso_q = est.eso_f, est.eso_q
        # int f_n dt at the rows' times, as y is the velocity there
        if first:
            eso_f.reset(F_bar, f_n)
        if a.eso_start == "ls" and y is not None:
            eso_f.beta1, eso_f.beta2 = np.maximum(b1, est.eso_f_b1), np.maximum(b2, est.eso_f_b2)
        correct(est, eso_f, F_bar)
        f_n = eso_f.z2                                # G f_n: the specific force as z2 sees it
        c = est.q_time(j, times[1])
        if first:
            eso_q.reset((c * c + times[2]) / 2.0)
        if a.eso_start == "ls":
            eso_q.beta1, eso_q.beta2 = eso.beta1, eso.beta2
            est.eso_x.beta1, est.eso_x.beta2 = eso.beta1[1], eso.beta2[1]
        correct(est, eso_q, None if y is None else (c * c + times[2]) / 2.0)
        fE, fN, fU = f_n[:, 0], f_n[:, 1], f_n[:, 2]
    dv_hat = z1 - est.reset_sum                           # current strapdown velocity error
    p = -(z2[:, 0] - cor * dv_hat[:, 1]) / fU         # eq. 7 without the fN psiU term
    q = (z2[:, 1] + cor * dv_hat[:, 0]) / fU          # eq. 9 without the fE psiU term
    s, n = fE / fU, fN / fU
    if first:
        est.td_f.reset(f_n)
    _, df = est.td_f.update(f_n)
    if a.td == "fst":
        if first:
            est.td_q.reset(q)
        _, dq = est.td_q.update(q)                        # eq. 15
        ds = df[:, 0] / fU - fE * df[:, 2] / fU**2    # s' = (fE / fU)'
        # eqs. 7, 9, 12 solved together (docs/methods/eso-td.md)
        den = W * cl * (1.0 + s * s) - W * sl * n + s * n * lat_rate + ds
        psiU = (W * sl * p - dq - s * (W * cl * q + lat_rate * p)) / den
    else:
        # eq. 12 integrated: Y = q - int m = a - psiU X with X = int den (docs/methods/eso-td.md); X from
        # the raw specific force, then through the ESO's filter like q (the lag q carries)
        den0 = W * cl * (1.0 + s * s) - W * sl * n + s * n * lat_rate
        m_known = W * sl * p - s * (W * cl * q + lat_rate * p)
        # den0 = W cosL + (the terms in s, n): those come through the ESO's filter already (s, n are
        # G f ratios), W cosL does not and goes through a copy of the ESO (eso_x)
        den_a, den_b = W * cl, den0 - W * cl
        if est.den0_prev is not None:
            est.X_int += 0.5 * h * (den_a + est.den0_prev[0])
            est.Xb_int += 0.5 * h * (den_b + est.den0_prev[1])
            est.M_int += 0.5 * h * (m_known + est.m_prev)
        est.den0_prev, est.m_prev = (den_a, den_b), m_known
        est.XX_int += est.X_int * h
        if first:
            est.eso_x.reset(est.XX_int, est.X_int)
        correct(est, est.eso_x, None if y is None else est.XX_int)
        # int s' dt = s - s(0), with s = G fE / G fU already through the ESO's filter
        X = est.X = est.eso_x.z2 + est.Xb_int + s - est.s_jumps
        if j >= est.td_from and y is not None:  # a prediction adds nothing to the fits
            est.td_ls.add(X, q - est.M_int)
            est.td_p.add(np.broadcast_to(est.eso_q.z2[0], (R,)), p)
        fitted = j >= est.td_ready and est.td_ls.origin is not None
        psiU = -est.td_ls.fit(X)[1] if fitted else np.zeros(R)
    psiE = q + s * psiU
    if a.td == "ls" and fitted:
        # q + s psiU is psiE through the ESO's filter, which lags a ramp by beta1 / beta2 (less the
        # step's own delay, plus the time since the last rows): add the ramp the fit gives, psiE' = m - psiU den0
        late = (j - clock[2]) * h - times[1] * dt
        lag = eso.beta1[1] / eso.beta2[1] - h - dt / 2.0 + late
        psiE = psiE + lag * (m_known - psiU * den0)
        lagN = eso.beta1[0] / eso.beta2[0] - h - dt / 2.0 + late
        psiN = p + n * psiU + lagN * est.td_p.fit(est.eso_q.z2[0])[1]  # p's drift (mostly -epsN), the same lag
    else:
        psiN = p + n * psiU
    # what the feedback needs of this step
    est._now = f_n, df, W, sl, cl, lat_rate, cor, s
    return np.stack([psiE, psiN, psiU], axis=-1)


def reset_velocity(est, st):
    """After a step with rows: the strapdown's level velocity ``st.v_n`` less the last row's error (the reset, kept
    in ``est.reset_sum``); and the velocity the next step starts from (``est.v_prev``)."""
    if est.e_last is not None:
        st.v_n[:, :2] -= est.e_last
        est.reset_sum += est.e_last
    est.v_prev = st.v_n[:, :2].copy()


#: (module, attribute, oracle): the library function this oracle replaces.
PATCH = ("adrc.moving_base", "run_compiled", run_numpy)
