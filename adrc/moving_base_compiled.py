"""The ESO/TD aligner's step loop, compiled: the loop of :meth:`adrc.moving_base.ESOTDAligner._align`.

:func:`eso_td_steps` runs the ESO/TD steps of all the runs in one numba call: the strapdown over the step's samples
(position free, height held), the measurement of the rows valid in the step (:func:`adrc.eso_td_rows_compiled.measure`)
and the specific force (ENU, m/s^2) of the step, the ESO of eq. 6 on both level channels (a correction with rows, the
prediction alone without), eqs. 7, 9 and 12 with the fst TD (``td="fst"``) or the least-squares TD and its copies of
the ESO's filter (``td="ls"``), and the velocity reset at rows, on the estimator's own arrays
(:class:`adrc.eso_td_estimator.ESOTDEstimator`). It stops at each attitude feedback (every ``feedback_every_s``, 10 s
by default), which the estimator's NumPy code makes (:meth:`~adrc.eso_td_estimator.ESOTDEstimator.feedback`,
:func:`run_compiled`); the reported attitude, the strapdown's turned by the estimate, is made from the histories in
one NumPy call. Its NumPy oracle, ``tests/oracles/eso_td.py``, makes the same operations in the same order, a step at
a time over the runs. NumPy's einsum sums products in its own order (:func:`_rotate_sum` follows it for the specific
force on this machine's 4-lane vectors), and the lever-arm terms' sums of three products differ from it in the last
bit, so the loop and its oracle agree to rounding (``tests/test_eso_td_aiding.py`` derives the tolerance).
"""

from __future__ import annotations

import numba
import numpy as np

from fusionbench import earth
from fusionbench.attitude import apply_misalignment
from fusionbench.strapdown_compiled import integrate_compiled

from .eso_td_estimator import expanding_memory_gains
from .eso_td_rows_compiled import measure, row_arrays
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
def eso_td_steps(sd_state, dth, dvel, rw, j0, j1, ints, consts, gain_tab, eso, eso_f, eso_q, eso_x, td, ls, clock,
                 times, rows_t, reset_sum, psi_fb, v_prev, P, marks, now, hist_Csd, hist_psi, hist_fb, hist_y):
    """ESO/TD steps ``j0`` to ``j1 - 1`` of all runs (module docstring), states updated in place.

    Parameters
    ----------
    sd_state : tuple
        ``Strapdown.compiled_state()`` (position free, height held).
    dth, dvel : ndarray, shape (steps, R, m, 3)
        Angle (rad) and velocity (m/s) increments, body frame, one block per step.
    rw : tuple
        The rows (:func:`adrc.eso_td_rows_compiled.row_arrays`).
    ints : ndarray of int
        ``is_ls`` (td="ls"), ``eso_ls`` (eso_start="ls"), ``td_from``, ``td_ready``, the steps per row ``n``.
    consts : ndarray
        ``h`` (s), ``dt`` (s), ``td_r`` (1/s^2), ``force_h1``, the fst TD's ``h1`` (s), the fit's forgetting factor.
    gain_tab : ndarray, shape (2, N)
        The expanding-memory gains beta1, beta2 of rows 0 .. N - 1 (the last one below the floors), or empty.
    eso, eso_f : tuple
        ``(z1, z2, beta1, beta2, floor1, floor2, alpha, delta, lin_div)`` of the level ESO (R, 2) and of its copy on
        the specific force (R, 3; td="ls"): states, the gains' law (applied ``n`` times over at a step with rows),
        floor gains, fal's exponent, zone and ``delta ** (1 - alpha)`` per channel.
    eso_q, eso_x : tuple
        ``(z1, z2)`` of the ESO's copies on the unit quadratic (2,) and on the regressor X (R,) (td="ls").
    td : tuple
        ``(x1, x2)`` of the fst TD on the specific force (R, 3), and of the fst TD on q (R,) (td="fst").
    ls : tuple
        td="ls": ``S`` (5, R) and ``origin`` (2, R) of the fit of eq. 12 and of p's drift; the integrals
        ``ints`` (6, R): X_int, Xb_int, M_int, XX_int, s_jumps, X; the previous step's den_a, den_b, m (3, R);
        ``F_int`` (R, 3).
    clock, times : ndarray, shapes (3,), (3,)
        :attr:`adrc.eso_td_estimator.ESOTDEstimator.clock` and ``times``.
    rows_t : tuple
        The steps' row time offsets (samples) and spreads (s^2) (:class:`adrc.eso_td_rows.StepRows`).
    reset_sum, psi_fb, v_prev, P, marks : ndarray
        Velocity resets so far (R, 2, m/s), attitude corrections fed back so far (R, 3, rad), the level velocity at
        the step's start (R, 2, m/s), the position intervals' integrals (R, 5) and marks (R, n_marks, 8).
    now : ndarray, shape (R, 12)
        Written at each step: f_n (3, m/s^2), f_n' (3), W, sin L, cos L, L', the Coriolis coefficient, fE / fU (the
        quantities :meth:`adrc.eso_td_estimator.ESOTDEstimator.feedback` reads).
    hist_Csd, hist_psi, hist_fb, hist_y : ndarray
        Written at each step j: the strapdown's attitude (R, steps, 3, 3), the estimate psi before any feedback
        (R, steps, 3, rad), the corrections so far (R, >= steps, 3), the unreset velocity error (R, >= steps, 2; NaN
        without rows).
    """
    C0, v0, lat0, lon0, h0, vp0, thp, dvp = sd_state
    is_ls, eso_ls, td_from, td_ready, sc = ints[0] == 1, ints[1] == 1, ints[2], ints[3], float(ints[4])
    h, dt, td_r, force_h1, q_h1, forget = consts
    z1, z2, b1, b2, fl1, fl2, alpha, delta, lin_div = eso
    fz1, fz2, fb1, fb2, ffl1, ffl2 = eso_f[0], eso_f[1], eso_f[2], eso_f[3], eso_f[4], eso_f[5]
    qz1, qz2 = eso_q
    xz1, xz2 = eso_x
    fx1, fx2, qx1, qx2 = td
    S_ls, org_ls, S_p, org_p, acc, prev, F_int = ls
    offset, tau2 = rows_t
    start, age = rw[0], rw[13]
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
            measure(r, j, rw, out_C, out_v, dth[j], cs, v_prev, reset_sum, F_int, P, marks, w_in, dt, y, Fbar, e_last)
            for i in range(3):
                F_int[r, i] += cs[m, i]
            if not started:  # no row yet: nothing to estimate
                for c in range(2):
                    hist_y[r, j, c], v_prev[r, c] = np.nan, v0[r, c]
                for i in range(3):
                    hist_psi[r, j, i], hist_fb[r, j, i] = 0.0, psi_fb[r, i]
                hist_Csd[r, j] = C0[r]
                continue
            for c in range(2):
                hist_y[r, j, c] = y[c] if upd else np.nan
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
                    acc[0, r] += 0.5 * h * (den_a + prev[0, r])
                    acc[1, r] += 0.5 * h * (den_b + prev[1, r])
                    acc[2, r] += 0.5 * h * (m_known + prev[2, r])
                prev[0, r], prev[1, r], prev[2, r] = den_a, den_b, m_known
                acc[3, r] += acc[0, r] * h
                if first:
                    xz1[r], xz2[r] = acc[3, r], acc[0, r]
                if upd:
                    xz1[r], xz2[r] = eso2_step(xz1[r], xz2[r], acc[3, r], h, b1[1] * sc, b2[1] * sc, 1.0, 1.0, 1.0)
                else:
                    xz1[r] = xz1[r] + h * xz2[r]
                X = xz2[r] + acc[1, r] + s - acc[4, r]
                acc[5, r] = X
                if j >= td_from and upd:  # a prediction adds nothing to the fits
                    _ls_add(S_ls, org_ls, r, X, q - acc[2, r], forget, S_ls[0, r] == 0.0)
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
            hist_psi[r, j, 0], hist_psi[r, j, 1], hist_psi[r, j, 2] = psiE, psiN, psiU
            hist_Csd[r, j] = C0[r]
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
                hist_fb[r, j, i] = psi_fb[r, i]


def run_compiled(est, sd, dth_b, dv_b, hist_C, hist_psi, hist_fb, hist_y):
    """The step loop of :meth:`adrc.moving_base.ESOTDAligner._align`: :func:`eso_td_steps` between the attitude
    feedbacks, each made by ``est.feedback`` (NumPy, once per feedback). Its NumPy oracle: ``run_numpy`` in
    ``tests/oracles/eso_td.py``, with the same arguments and effects.

    Parameters
    ----------
    est : adrc.eso_td_estimator.ESOTDEstimator
        The estimator, fresh (its states, and the rows' marks, are advanced in place).
    sd : fusionbench.strapdown.Strapdown
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
    ints = np.array([is_ls, eso_ls, getattr(est, "td_from", 0), getattr(est, "td_ready", 0), n], dtype=np.int64)
    consts = np.array([h, est.dt, a.td_r, a.force_h1, est.h1, est.td_ls.forget if is_ls else 1.0], dtype=float)
    e = est.eso
    e.beta1, e.beta2 = e.beta1.copy(), e.beta2.copy()  # written in place (they may be the floors' own arrays)
    alpha, delta = (np.broadcast_to(x, (2,)).astype(float) for x in (e.alpha, e.delta))
    eso_consts = (est.b1_floor, est.b2_floor, alpha, delta, delta ** (1.0 - alpha))
    zeros, fe = np.zeros, est.eso_f if is_ls else None
    if is_ls:
        fe.beta1, fe.beta2 = fe.beta1.copy(), fe.beta2.copy()
        ls = (est.td_ls.S, zeros((2, R)), est.td_p.S, zeros((2, R)),
              np.stack([est.X_int, est.Xb_int, est.M_int, est.XX_int, est.s_jumps, zeros(R)]), zeros((3, R)), est.F_int)
        est.X_int, est.Xb_int, est.M_int, est.XX_int, est.s_jumps, est.X = ls[4]  # the object's arrays: rows of one
    else:
        ls = (zeros((5, R)), zeros((2, R)), zeros((5, R)), zeros((2, R)), zeros((6, R)), zeros((3, R)), est.F_int)
    hist_Csd, psi_pre, now = np.empty((R, steps, 3, 3)), np.empty((R, steps, 3)), np.empty((R, 12))
    feedbacks = set() if est.fb_from is None else set(range(est.fb_from, steps, est.fb_every))
    rw, rows_t = row_arrays(est.rows), (est.rows.offset, est.rows.tau2)
    j0 = 0
    for jf in sorted(feedbacks | {steps - 1}):
        # the observers' current arrays (a feedback replaces some), dummies for those of the other TD
        eso = (e.z1, e.z2, e.beta1, e.beta2) + eso_consts
        eso_f = (fe.z1, fe.z2, fe.beta1, fe.beta2, est.eso_f_b1, est.eso_f_b2) if is_ls else (
            zeros((R, 3)), zeros((R, 3))) + (zeros(3),) * 4
        eso_q = (est.eso_q.z1, est.eso_q.z2) if is_ls else (zeros(2), zeros(2))
        eso_x = (est.eso_x.z1, est.eso_x.z2) if is_ls else (zeros(R), zeros(R))
        td = (est.td_f.x1, est.td_f.x2) + ((zeros(R), zeros(R)) if is_ls else (est.td_q.x1, est.td_q.x2))
        eso_td_steps(sd.compiled_state(), dth_b, dv_b, rw, j0, jf + 1, ints, consts, gain_tab, eso, eso_f, eso_q,
                     eso_x, td, ls, est.clock, est.times, rows_t, est.reset_sum, est.psi_fb, est.v_prev, est.P,
                     est.marks, now, hist_Csd, psi_pre, hist_fb, hist_y)
        hist_psi[:, j0:jf + 1] = psi_pre[:, j0:jf + 1]
        if jf in feedbacks and est.feedback_due(jf):
            if is_ls and ls[0][0, 0] > 0:  # the fits have started: their origins
                est.td_ls.origin, est.td_p.origin = tuple(ls[1]), tuple(ls[3])
            est._now = (now[:, 0:3].copy(), now[:, 3:6].copy()) + tuple(np.ascontiguousarray(now[:, 6:12].T))
            hist_psi[:, jf] = est.feedback(jf, psi_pre[:, jf], sd.state)
            hist_fb[:, jf] = est.psi_fb
        j0 = jf + 1
    hist_C[:, :steps] = apply_misalignment(hist_Csd, -psi_pre)
