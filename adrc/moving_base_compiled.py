"""The ESO/TD aligner's step loop, compiled: the loop of :meth:`adrc.moving_base.ESOTDAligner._align`.

:func:`eso_td_steps` runs the ESO/TD steps of all the runs in one numba call: the strapdown over the step's samples
(position free, height held), the measurement of the rows valid in the step (:func:`adrc.eso_td_rows_compiled.measure`)
and the specific force (ENU, m/s^2) of the step, the ESO of eq. 6 on both level channels (a correction with rows, the
prediction alone without), eqs. 7, 9 and 12 with the fst TD (``td="fst"``) or the least-squares TD and its copies of the
ESO's filter (``td="ls"``), and the velocity reset at rows, on the estimator's own arrays
(:class:`adrc.eso_td_estimator.ESOTDEstimator`), passed as named groups (:mod:`adrc.eso_td_state`). It stops at each
attitude feedback (every ``feedback_every_s``, 10 s by default), which the estimator's NumPy code makes
(:meth:`~adrc.eso_td_estimator.ESOTDEstimator.feedback`, :func:`run_compiled`); the reported attitude, the strapdown's
turned by the estimate, is made from the histories in one NumPy call. Its NumPy oracle, ``tests/oracles/eso_td.py``,
makes the same operations in the same order, a step at a time over the runs. NumPy's einsum sums products in its own
order (:func:`_rotate_sum` follows it for the specific force on this machine's 4-lane vectors), and the lever-arm terms'
sums of three products differ from it in the last bit, so the loop and its oracle agree to rounding
(``tests/test_eso_td_aiding.py`` derives the tolerance).
"""

from __future__ import annotations

import numba
import numpy as np

from fusionbench.simulation import earth
from fusionbench.simulation.attitude import apply_misalignment
from fusionbench.simulation.strapdown_compiled import integrate_compiled

from .eso_td_estimator import expanding_memory_gains
from .eso_td_rows_compiled import measure, row_arrays
from .eso_td_state import TD, ESOCopy, EstimatorArrays, ForceESO, Histories, LevelESO, LSFits, Observers, Setup
from .primitives_compiled import eso2_step, fst_step

_E2, _A, _W_IE = earth.E2, earth.A, earth.OMEGA_IE


@numba.njit(cache=True)
def _rotate_sum(C, v, i):
    """Row ``i`` of ``C`` (3, 3) times ``v`` (3,), summed as NumPy's einsum does: (c0 v0 + c2 v2) + c1 v1."""
    return (C[i, 0] * v[0] + C[i, 2] * v[2]) + C[i, 1] * v[1]


@numba.njit(cache=True)
def _ls_add(S, origin, r, X, Y, forget, first):
    """:meth:`adrc.ls_differentiator.LeastSquaresDifferentiator.add` for run ``r``: S (5, R), origin (2, R) set at the
    ``first`` sample."""
    if first:
        origin[0, r], origin[1, r] = X, Y
    x, y = X - origin[0, r], Y - origin[1, r]
    S[0, r] = forget * S[0, r] + 1.0
    S[1, r] = forget * S[1, r] + x
    S[2, r] = forget * S[2, r] + x * x
    S[3, r] = forget * S[3, r] + y
    S[4, r] = forget * S[4, r] + x * y


@numba.njit(cache=True)
def _ls_slope(S, r):
    """The slope b of :meth:`adrc.ls_differentiator.LeastSquaresDifferentiator.fit` for run ``r``."""
    det = S[0, r] * S[2, r] - S[1, r] * S[1, r]
    return (S[0, r] * S[4, r] - S[1, r] * S[3, r]) / det if det > 0 else 0.0


@numba.njit(cache=True)
def eso_td_steps(sd_state, dth, dvel, rows, j0, j1, setup, obs, fits, est, hist):
    """ESO/TD steps ``j0`` to ``j1 - 1`` of all runs (module docstring), states updated in place.

    Parameters
    ----------
    sd_state : tuple
        ``Strapdown.compiled_state()`` (position free, height held).
    dth, dvel : ndarray, shape (steps, R, m, 3)
        Angle (rad) and velocity (m/s) increments, body frame, one block per step.
    rows : adrc.eso_td_rows_compiled.RowArrays
        The rows of each step and their times (:func:`adrc.eso_td_rows_compiled.row_arrays`).
    j0, j1 : int
        The steps to make, ``j0 .. j1 - 1``.
    setup : adrc.eso_td_state.Setup
        The constants: which TD and gains, the steps, the TDs' factors, the fits' forgetting, the gain table.
    obs : adrc.eso_td_state.Observers
        The level ESO (eq. 6), its copies on the specific force, the unit quadratic and the regressor (td="ls"), the
        fst TDs on the specific force and on q (td="fst"); the other TD's are dummies.
    fits : adrc.eso_td_state.LSFits
        td="ls": the fits of eq. 12 and of p's drift, eq. 12's integrals (dummies with td="fst").
    est : adrc.eso_td_state.EstimatorArrays
        The estimator's running arrays: the rows' clock and times, the resets, the corrections fed back, the level
        velocity at the step's start, ``int f_n dt``, the position intervals' integrals and marks, and ``now``, what
        :meth:`adrc.eso_td_estimator.ESOTDEstimator.feedback` reads of the step just made.
    hist : adrc.eso_td_state.Histories
        Written at each step j: the strapdown's attitude, psi before any feedback, the corrections so far, the
        unreset velocity error (NaN without rows).
    """
    C0, v0, lat0, lon0, h0, vp0, thp, dvp = sd_state
    is_ls, eso_ls, td_from, td_ready = setup.td_is_ls, setup.eso_start_is_ls, setup.td_from, setup.td_ready
    sc, gain_tab, forget = setup.steps_per_row, setup.gain_table, setup.forget
    h, dt, td_r, force_h1, q_h1 = setup.h, setup.dt, setup.td_r, setup.force_h1, setup.q_h1
    eso, eso_f = obs.eso, obs.eso_f
    z1, z2, b1, b2, fl1, fl2 = eso.z1, eso.z2, eso.beta1, eso.beta2, eso.beta1_floor, eso.beta2_floor
    alpha, delta, lin_div = eso.alpha, eso.delta, eso.lin_div
    fz1, fz2, fb1, fb2, ffl1, ffl2 = eso_f.z1, eso_f.z2, eso_f.beta1, eso_f.beta2, eso_f.beta1_floor, eso_f.beta2_floor
    qz1, qz2, xz1, xz2 = obs.eso_q.z1, obs.eso_q.z2, obs.eso_x.z1, obs.eso_x.z2
    fx1, fx2, qx1, qx2 = obs.td_f.x1, obs.td_f.x2, obs.td_q.x1, obs.td_q.x2
    S_ls, org_ls, S_p, org_p = fits.S_ls, fits.origin_ls, fits.S_p, fits.origin_p
    X_int, Xb_int, M_int, XX_int, s_jumps = fits.X_int, fits.Xb_int, fits.M_int, fits.XX_int, fits.s_jumps
    den_a_prev, den_b_prev, m_prev = fits.den_a_prev, fits.den_b_prev, fits.m_prev
    clock, times, reset_sum, psi_fb, v_prev = est.clock, est.times, est.reset_sum, est.psi_fb, est.v_prev
    F_int, P, marks, now = est.F_int, est.P, est.marks, est.now
    start, age, offset, tau2 = rows.start, rows.age, rows.offset, rows.tau2
    runs, m = dth.shape[1], dth.shape[2]
    out_C, out_v, out_p = np.empty((runs, m, 3, 3)), np.empty((runs, m, 3)), np.empty((runs, m, 3))
    nocmd = np.zeros((runs, 0, 3))
    y, fn, df_k, Fbar, e_last = np.empty(2), np.empty(3), np.empty((m, 3)), np.empty(3), np.empty(2)
    cs, w_in = np.zeros((m + 1, 3)), np.empty(3)
    for j in range(j0, j1):
        integrate_compiled(C0, v0, lat0, lon0, h0, vp0, thp, dvp, dth[j], dvel[j], nocmd, dt, False, True, 1,
                           out_C, out_v, out_p)
        upd = start[j + 1] > start[j]
        first = upd and clock[0] == 0
        if upd:
            if first:
                clock[1], times[0] = j, offset[j]
            clock[2], times[1], times[2] = j, offset[j], tau2[j]
            if eso_ls:  # the least-squares line through the rows so far, down to the floor
                k = min(clock[0], gain_tab.shape[1] - 1)
                g1, g2 = gain_tab[0, k], gain_tab[1, k]
                for c in range(2):
                    b1[c], b2[c] = max(g1, fl1[c]), max(g2, fl2[c])
                if is_ls:
                    for c in range(3):
                        fb1[c], fb2[c] = max(g1, ffl1[c]), max(g2, ffl2[c])
            clock[0] += 1
        started = clock[0] > 0
        if is_ls and started:  # the ESO's response to the unit quadratic (its gains: the ESO's)
            cq = (j - clock[1]) * h + (times[1] - times[0]) * dt
            if first:
                qz1[0] = qz1[1] = (cq * cq + times[2]) / 2.0
                qz2[0] = qz2[1] = 0.0
            for c in range(2):
                if upd:
                    qz1[c], qz2[c] = eso2_step(qz1[c], qz2[c], (cq * cq + times[2]) / 2.0, h, b1[c] * sc, b2[c] * sc,
                                               1.0, 1.0, 1.0)
                else:
                    qz1[c] = qz1[c] + h * qz2[c]
        for r in range(runs):
            # the specific force (ENU, m/s^2) and its integral from the step's start
            for k in range(m):
                for i in range(3):
                    df_k[k, i] = _rotate_sum(out_C[r, k], dvel[j, r, k], i)
            for i in range(3):
                s_ = 0.0
                for k in range(m):
                    s_ += df_k[k, i]
                    cs[k + 1, i] = cs[k, i] + df_k[k, i]
                fn[i] = s_ / h
            lat = lat0[r]
            sl, cl = np.sin(lat), np.cos(lat)
            w = 1.0 - _E2 * (sl * sl)  # earth.radii
            rn = _A / np.sqrt(w)
            rm = rn * (1.0 - _E2) / w
            lon_rate = v0[r, 0] / ((rn + h0[r]) * cl)
            lat_rate = v0[r, 1] / (rm + h0[r])
            W = _W_IE + lon_rate
            cor = (2.0 * _W_IE + lon_rate) * sl
            w_in[0], w_in[1], w_in[2] = -lat_rate, W * cl, W * sl  # omega_in^n
            measure(r, j, rows, out_C, out_v, dth[j], cs, v_prev, reset_sum, F_int, P, marks, w_in, dt, y, Fbar, e_last)
            for i in range(3):
                F_int[r, i] += cs[m, i]
            if not started:  # no row yet: nothing to estimate
                for c in range(2):
                    hist.y[r, j, c], v_prev[r, c] = np.nan, v0[r, c]
                for i in range(3):
                    hist.psi[r, j, i], hist.psi_fb[r, j, i] = 0.0, psi_fb[r, i]
                hist.C_sd[r, j] = C0[r]
                continue
            for c in range(2):
                hist.y[r, j, c] = y[c] if upd else np.nan
            if first:
                z1[r, 0], z1[r, 1], z2[r, 0], z2[r, 1] = y[0], y[1], 0.0, 0.0
            for c in range(2):  # eq. 6
                if upd:
                    z1[r, c], z2[r, c] = eso2_step(z1[r, c], z2[r, c], y[c], h, b1[c] * sc, b2[c] * sc, alpha[c],
                                                   delta[c], lin_div[c])
                else:
                    z1[r, c] = z1[r, c] + h * z2[r, c]
            if is_ls:  # int f_n dt at the rows' times, as y is the velocity there
                if first:
                    for i in range(3):
                        fz1[r, i], fz2[r, i] = Fbar[i], fn[i]
                for i in range(3):  # G f_n: the specific force as z2 sees it
                    if upd:
                        fz1[r, i], fz2[r, i] = eso2_step(fz1[r, i], fz2[r, i], Fbar[i], h, fb1[i] * sc, fb2[i] * sc,
                                                         1.0, 1.0, 1.0)
                    else:
                        fz1[r, i] = fz1[r, i] + h * fz2[r, i]
                    fn[i] = fz2[r, i]
            fE, fN, fU = fn[0], fn[1], fn[2]
            p = -(z2[r, 0] - cor * (z1[r, 1] - reset_sum[r, 1])) / fU  # eq. 7 without the fN psiU term
            q = (z2[r, 1] + cor * (z1[r, 0] - reset_sum[r, 0])) / fU   # eq. 9 without the fE psiU term
            s, n = fE / fU, fN / fU
            for i in range(3):
                if first:
                    fx1[r, i], fx2[r, i] = fn[i], 0.0
                fx1[r, i], fx2[r, i] = fst_step(fx1[r, i], fx2[r, i], fn[i], h, td_r, force_h1)
            fitted = False
            if not is_ls:
                if first:
                    qx1[r], qx2[r] = q, 0.0
                qx1[r], qx2[r] = fst_step(qx1[r], qx2[r], q, h, td_r, q_h1)  # eq. 15
                ds = fx2[r, 0] / fU - fE * fx2[r, 2] / (fU * fU)  # s' = (fE / fU)'
                den = W * cl * (1.0 + s * s) - W * sl * n + s * n * lat_rate + ds
                psiU = (W * sl * p - qx2[r] - s * (W * cl * q + lat_rate * p)) / den
            else:  # eq. 12 integrated (docs/methods/eso-td.md)
                den0 = W * cl * (1.0 + s * s) - W * sl * n + s * n * lat_rate
                m_known = W * sl * p - s * (W * cl * q + lat_rate * p)
                den_a, den_b = W * cl, den0 - W * cl
                if not first:
                    X_int[r] += 0.5 * h * (den_a + den_a_prev[r])
                    Xb_int[r] += 0.5 * h * (den_b + den_b_prev[r])
                    M_int[r] += 0.5 * h * (m_known + m_prev[r])
                den_a_prev[r], den_b_prev[r], m_prev[r] = den_a, den_b, m_known
                XX_int[r] += X_int[r] * h
                if first:
                    xz1[r], xz2[r] = XX_int[r], X_int[r]
                if upd:
                    xz1[r], xz2[r] = eso2_step(xz1[r], xz2[r], XX_int[r], h, b1[1] * sc, b2[1] * sc, 1.0, 1.0, 1.0)
                else:
                    xz1[r] = xz1[r] + h * xz2[r]
                X = xz2[r] + Xb_int[r] + s - s_jumps[r]
                fits.X[r] = X
                if j >= td_from and upd:  # a prediction adds nothing to the fits
                    _ls_add(S_ls, org_ls, r, X, q - M_int[r], forget, S_ls[0, r] == 0.0)
                    _ls_add(S_p, org_p, r, qz2[0], p, forget, S_p[0, r] == 0.0)
                fitted = j >= td_ready and S_ls[0, r] > 0.0
                psiU = -_ls_slope(S_ls, r) if fitted else 0.0
            psiE = q + s * psiU
            if is_ls and fitted:
                # psiE through the ESO's filter lags a ramp: add the ramp the fit gives (and p's drift to psiN)
                late = (j - clock[2]) * h - times[1] * dt
                psiE = psiE + (b1[1] / b2[1] - h - dt / 2.0 + late) * (m_known - psiU * den0)
                psiN = p + n * psiU + (b1[0] / b2[0] - h - dt / 2.0 + late) * _ls_slope(S_p, r)
            else:
                psiN = p + n * psiU
            hist.psi[r, j, 0], hist.psi[r, j, 1], hist.psi[r, j, 2] = psiE, psiN, psiU
            hist.C_sd[r, j] = C0[r]
            # what the feedback reads of this step
            for i in range(3):
                now[r, i], now[r, 3 + i] = fn[i], fx2[r, i]
            now[r, 6], now[r, 7], now[r, 8], now[r, 9], now[r, 10], now[r, 11] = W, sl, cl, lat_rate, cor, s
            # velocity reset at rows (keeps eq. 1's neglected dv / R terms negligible)
            for c in range(2):
                if upd:
                    e_now = e_last[c] + z2[r, c] * age[start[j + 1] - 1]  # the last row's error, now
                    v0[r, c] -= e_now
                    reset_sum[r, c] += e_now
                v_prev[r, c] = v0[r, c]
            for i in range(3):
                hist.psi_fb[r, j, i] = psi_fb[r, i]


def run_compiled(est, sd, dth_b, dv_b, hist_C, hist_psi, hist_fb, hist_y):
    """The step loop of :meth:`adrc.moving_base.ESOTDAligner._align`: :func:`eso_td_steps` between the attitude
    feedbacks, each made by ``est.feedback`` (NumPy, once per feedback). Its NumPy oracle: ``run_numpy`` in
    ``tests/oracles/eso_td.py``, with the same arguments and effects.

    Parameters
    ----------
    est : adrc.eso_td_estimator.ESOTDEstimator
        The estimator, fresh (its states, and the rows' marks, are advanced in place).
    sd : fusionbench.simulation.strapdown.Strapdown
        The strapdown (advanced in place).
    dth_b, dv_b : ndarray, shape (steps, R, m, 3)
        Increments (rad, m/s, body), one block per step.
    hist_C, hist_psi, hist_fb, hist_y : ndarray
        The histories (R, records, ...): the attitude reported, the estimate psi after any feedback, the corrections
        so far, the unreset velocity error; the first ``steps`` entries are written.
    """

    a, R, h, steps, n = est.a, est.R, est.h, dth_b.shape[0], est.n
    is_ls, eso_ls = a.td == "ls", a.eso_start == "ls"
    gain_tab = []
    while eso_ls and len(gain_tab) < steps and not (
            gain_tab and gain_tab[-1][0] <= est.b1_floor.min() and gain_tab[-1][1] <= est.b2_floor.min()):
        gain_tab.append(expanding_memory_gains(len(gain_tab), h, n))  # until below every floor (then the floors hold)
    gain_tab = np.array(gain_tab, dtype=float).reshape(-1, 2).T.copy()
    setup = Setup(td_is_ls=is_ls, eso_start_is_ls=eso_ls, td_from=int(getattr(est, "td_from", 0)),
                  td_ready=int(getattr(est, "td_ready", 0)), steps_per_row=float(n), h=float(h), dt=float(est.dt),
                  td_r=float(a.td_r), force_h1=float(a.force_h1), q_h1=float(est.h1),
                  forget=float(est.td_ls.forget) if is_ls else 1.0, gain_table=gain_tab)
    e = est.eso
    e.beta1, e.beta2 = e.beta1.copy(), e.beta2.copy()  # written in place (they may be the floors' own arrays)
    alpha, delta = (np.broadcast_to(x, (2,)).astype(float) for x in (e.alpha, e.delta))
    eso_consts = (est.b1_floor, est.b2_floor, alpha, delta, delta ** (1.0 - alpha))
    zeros, fe = np.zeros, est.eso_f if is_ls else None
    if is_ls:
        fe.beta1, fe.beta2 = fe.beta1.copy(), fe.beta2.copy()
        est.X = zeros(R)  # the fit's regressor, which the feedback reads
        fits = LSFits(est.td_ls.S, zeros((2, R)), est.td_p.S, zeros((2, R)), est.X_int, est.Xb_int, est.M_int,
                      est.XX_int, est.s_jumps, est.X, zeros(R), zeros(R), zeros(R))
    else:
        fits = LSFits(zeros((5, R)), zeros((2, R)), zeros((5, R)), zeros((2, R)), *(zeros(R) for _ in range(9)))
    hist_Csd, psi_pre, now = np.empty((R, steps, 3, 3)), np.empty((R, steps, 3)), np.empty((R, 12))
    hist = Histories(hist_Csd, psi_pre, hist_fb, hist_y)
    feedbacks = set() if est.fb_from is None else set(range(est.fb_from, steps, est.fb_every))
    rows = row_arrays(est.rows)
    j0 = 0
    for jf in sorted(feedbacks | {steps - 1}):
        # the observers' current arrays (a feedback replaces some), dummies for those of the other TD
        obs = Observers(
            LevelESO(e.z1, e.z2, e.beta1, e.beta2, *eso_consts),
            ForceESO(fe.z1, fe.z2, fe.beta1, fe.beta2, est.eso_f_b1, est.eso_f_b2) if is_ls else ForceESO(
                zeros((R, 3)), zeros((R, 3)), *(zeros(3) for _ in range(4))),
            ESOCopy(est.eso_q.z1, est.eso_q.z2) if is_ls else ESOCopy(zeros(2), zeros(2)),
            ESOCopy(est.eso_x.z1, est.eso_x.z2) if is_ls else ESOCopy(zeros(R), zeros(R)),
            TD(est.td_f.x1, est.td_f.x2),
            TD(zeros(R), zeros(R)) if is_ls else TD(est.td_q.x1, est.td_q.x2))
        arrays = EstimatorArrays(est.clock, est.times, est.reset_sum, est.psi_fb, est.v_prev, est.F_int, est.P,
                                 est.marks, now)
        eso_td_steps(sd.compiled_state(), dth_b, dv_b, rows, j0, jf + 1, setup, obs, fits, arrays, hist)
        hist_psi[:, j0:jf + 1] = psi_pre[:, j0:jf + 1]
        if jf in feedbacks and est.feedback_due(jf):
            if is_ls and fits.S_ls[0, 0] > 0:  # the fits have started: their origins
                est.td_ls.origin, est.td_p.origin = tuple(fits.origin_ls), tuple(fits.origin_p)
            est._now = (now[:, 0:3].copy(), now[:, 3:6].copy()) + tuple(np.ascontiguousarray(now[:, 6:12].T))
            hist_psi[:, jf] = est.feedback(jf, psi_pre[:, jf], sd.state)
            hist_fb[:, jf] = est.psi_fb
        j0 = jf + 1
    hist_C[:, :steps] = apply_misalignment(hist_Csd, -psi_pre)
