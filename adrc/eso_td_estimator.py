"""The estimator of the ESO/TD aligner (:class:`adrc.moving_base.ESOTDAligner`, seed 001: Zhao, Zhuang and Yang,
Control and Decision 22(2), 2007): one step of the level ESO (eqs. 5-6), the level angles (eqs. 7, 9), eq. 12's
azimuth through the least-squares or fst TD, the velocity reset at rows and the attitude feedback with the shifts
that keep every observer continuous. Frames: n = ENU, b = RFU; psi = [psiE, psiN, psiU] rad is the strapdown's
misalignment. The equations, their derivations and the measured design choices are in ``docs/methods/eso-td.md``.
"""

from __future__ import annotations

import numpy as np

from fusionbench import earth
from fusionbench.attitude import apply_misalignment, rotvec_to_dcm

from .ls_differentiator import LeastSquaresDifferentiator
from .primitives import FSTTrackingDifferentiator, SecondOrderESO

__all__ = ["ESOTDEstimator", "expanding_memory_gains"]


def expanding_memory_gains(k, h, n=1):
    """ESO gains (beta1 1/s, beta2 1/s^2) that make correction k (0, 1, ...) of eq. 6 the least-squares line
    through the k + 1 measurements so far, ``n`` steps of ``h`` s apart (Morrison's expanding-memory filter,
    g = 2 (2k + 1) / ((k + 1) (k + 2)), g' = 6 / ((k + 1) (k + 2)), in the ESO's form for gains applied n times over
    at a step with rows and predictions between (:mod:`adrc.eso_td_rows`): beta1 = (g + g' / n) / (n h),
    beta2 = g' / (n h)^2; with n = 1, (g + g') / h and g' / h^2)."""
    k = float(k)
    g = 2.0 * (2.0 * k + 1.0) / ((k + 1.0) * (k + 2.0))
    gp = 6.0 / ((k + 1.0) * (k + 2.0))
    return (g + gp / n) / (n * h), gp / (n * h)**2


class ESOTDEstimator:
    """The estimator of :class:`ESOTDAligner` over R runs, stepped once per ESO/TD step (the names and equations of
    ``docs/methods/eso-td.md``).

    :meth:`step` takes one step's strapdown output and the rows valid in it and returns the estimate ``psi`` of the
    strapdown's misalignment (eqs. 6, 7, 9, 12); :meth:`reset_velocity` resets the velocity at rows;
    :meth:`feedback` turns the strapdown by the estimate and moves every observer to where it would be had the
    strapdown always carried the corrected error ("Velocity reset and attitude feedback").

    Parameters
    ----------
    aligner : ESOTDAligner
        The options (gains, the TD, the feedback schedule).
    runs : int
        R.
    h : float
        Step, s (the aligner's ``step_s`` in whole samples: Han's h of :mod:`adrc.primitives`).
    dt : float
        Sample interval, s.
    m : int
        Samples per step.
    rows : adrc.eso_td_rows.StepRows
        The measurement of each step (none: the observers predict; module :mod:`adrc.eso_td_rows`).

    Attributes
    ----------
    eso : SecondOrderESO
        The level channels' ESO (eq. 6), batch (R, 2): z1 the unreset velocity errors [dvE, dvN] (m/s), z2 their
        rates (m/s^2); gains beta1, beta2 (expanding memory down to the floor with ``eso_start="ls"``).
    td_f : FSTTrackingDifferentiator
        fst TD on the specific force f_n (R, 3): x2 its rate (s' of eq. 12 with td="fst", f' in the feedback).
    td_q : FSTTrackingDifferentiator
        td="fst": fst TD on q, the measured part of eq. 9 (x2 its rate, eq. 15).
    td_ls, td_p : LeastSquaresDifferentiator
        td="ls": eq. 12 integrated (Y = q - int m against X; slope -psiU) and p against time (psiN's drift).
    eso_f, eso_q, eso_x : SecondOrderESO
        td="ls": copies of the ESO's filter on the specific force, on a unit quadratic (its exact ramp lag) and
        on the regressor X.
    y : ndarray, shape (R, 2)
        The unreset level velocity error fed to the ESO at the last step (NaN without rows), m/s.
    clock, times : ndarray
        Rows read so far, the first step with rows and the last (int); those steps' row time offsets (samples) and
        the last one's spread (s^2) (:class:`adrc.eso_td_rows.StepRows`).
    reset_sum : ndarray, shape (R, 2)
        Velocity resets so far, m/s.
    psi_fb : ndarray, shape (R, 3)
        Attitude corrections fed back so far, rad.
    """

    def __init__(self, aligner, runs, h, dt, m, rows):
        self.a, self.R, self.h, self.dt, self.m, self.rows, self.n = aligner, runs, h, dt, m, rows, rows.steps_per_row
        R = runs
        self.h1 = aligner.td_h1_for(h)
        self.b1_floor, self.b2_floor = b1_floor, b2_floor = np.array(aligner.beta1), np.array(aligner.beta2)
        self.eso = SecondOrderESO((R, 2), h, b1_floor, b2_floor, aligner.alpha, aligner.deltas_for(h))
        if aligner.td == "fst":
            self.td_q = FSTTrackingDifferentiator((R,), h, aligner.td_r, self.h1)
        else:
            forget = 1.0 if aligner.td_memory_s is None else float(np.exp(-h / aligner.td_memory_s))
            self.td_ls = LeastSquaresDifferentiator((R,), forget)
            self.td_p = LeastSquaresDifferentiator((R,), forget)   # p against time: psiN's drift (-epsN), for its lag
            self.X_int, self.Xb_int, self.M_int = np.zeros(R), np.zeros(R), np.zeros(R)  # int of den0's parts and of m
            self.den0_prev = self.m_prev = None
            self.td_from = rows.first_step + max(0, int(np.ceil(aligner.td_start_s / h - 1e-9)))  # from the 1st row
            self.td_ready = self.td_from + int(np.ceil(aligner.td_min_s / h - 1e-9))
        self.td_f = FSTTrackingDifferentiator((R, 3), h, aligner.td_r, aligner.force_h1)  # f_n' (s', feedback shifts)
        if aligner.td == "ls":  # f_n through the ESO's own filter, for s, n, fU consistent with z2 (the method's page)
            self.eso_f = SecondOrderESO((R, 3), h, b1_floor[[0, 1, 1]], b2_floor[[0, 1, 1]], 1.0, 1.0)
            self.eso_f_b1, self.eso_f_b2 = self.eso_f.beta1.copy(), self.eso_f.beta2.copy()
            # the ESO's own response to a unit quadratic Q = tau^2 / 2 (tau from the first rows' mean time), with the
            # same gains and rows: its errors are the exact lag of a ramp in y' (feedback shifts)
            self.eso_q = SecondOrderESO((2,), h, b1_floor, b2_floor, 1.0, 1.0)
            self.eso_x = SecondOrderESO((R,), h, b1_floor[1], b2_floor[1], 1.0, 1.0)  # G X, the regressor as q sees it
            self.XX_int = np.zeros(R)       # int X dt, eso_x's input
            self.s_jumps = np.zeros(R)      # jumps of fE / fU at feedbacks (X stays continuous)
        # first feedback at the first step ending at or after feedback_from_s (step j ends at t0 + (j + 1) h)
        self.fb_from = (None if aligner.feedback_from_s is None
                        else rows.first_step + max(0, int(np.ceil(aligner.feedback_from_s / h - 1 - 1e-9))))
        self.fb_every = max(1, int(round(aligner.feedback_every_s / h)))
        self.reset_sum, self.psi_fb, self.F_int = np.zeros((R, 2)), np.zeros((R, 3)), np.zeros((R, 3))  # F: int f_n dt
        self.v_prev, self.e_last = rows.v0[:, :2].copy(), None  # the level velocity at the step's start; the reset
        self.P, self.marks = np.zeros((R, 5)), np.zeros((R, rows.mark_k.size, 8))  # position intervals' integrals
        self.clock, self.times = np.zeros(3, np.int64), np.zeros(3)

    def q_time(self, j, offset):
        """Time (s) of rows ``offset`` samples from step ``j``'s mean sample end, from the first rows' mean time."""
        return (j - self.clock[1]) * self.h + (offset - self.times[0]) * self.dt

    def _correct(self, obs, y):
        """One step of the observer ``obs`` (a :class:`SecondOrderESO`): with the rows' measurement ``y``, its gains
        applied ``n`` times over; None (no rows): the prediction alone."""
        if y is None:
            obs.z1 = obs.z1 + self.h * obs.z2
            return
        b1, b2 = obs.beta1, obs.beta2
        obs.beta1, obs.beta2 = b1 * self.n, b2 * self.n
        obs.update(y)
        obs.beta1, obs.beta2 = b1, b2

    def step(self, j, C_bn, v_n, dth, dv, st):
        """Step ``j`` from the strapdown's attitude ``C_bn`` (R, m, 3, 3) and velocity ``v_n`` (R, m, 3) after
        each of the step's samples, the samples' increments ``dth``, ``dv`` (R, m, 3, body: rad, m/s), the strapdown's
        state ``st`` at the step's end and the rows valid in the step; returns psi (R, 3), rad (0 before any row)."""
        a, h, dt, R = self.a, self.h, self.dt, self.R
        eso, clock, times = self.eso, self.clock, self.times
        f_n = np.einsum("rkij,rkj->ri", C_bn, dv) / h  # specific force, ENU, m/s^2
        lat = st.lat
        rm, rn = earth.radii(lat)
        sl, cl = np.sin(lat), np.cos(lat)
        lon_rate = st.v_n[:, 0] / ((rn + st.h) * cl)
        lat_rate = st.v_n[:, 1] / (rm + st.h)
        W = earth.OMEGA_IE + lon_rate
        cor = (2.0 * earth.OMEGA_IE + lon_rate) * sl     # Coriolis coefficient of eqs. 4, 7, 9
        df_k = np.einsum("rkij,rkj->rki", C_bn, dv)
        meas = self.rows.measure(j, C_bn, v_n, dth, df_k, self.v_prev, self.reset_sum, self.F_int, self.P,
                                 self.marks, np.stack([-lat_rate, W * cl, W * sl], axis=-1))  # omega_in^n
        self.F_int = self.F_int + df_k.sum(axis=1)
        y, F_bar, e_last, age = (None, None, None, None) if meas is None else meas
        self.y = np.full((R, 2), np.nan) if y is None else y  # unreset level velocity error, m/s
        if y is None and clock[0] == 0:  # no row yet: nothing to estimate
            return np.zeros((R, 3))
        first = clock[0] == 0
        if y is not None:
            if first:
                eso.reset(y)
                clock[1], times[0] = j, self.rows.offset[j]
            clock[2], times[1], times[2] = j, self.rows.offset[j], self.rows.tau2[j]
            if a.eso_start == "ls":  # the least-squares line through the rows so far, down to the floor
                b1, b2 = expanding_memory_gains(clock[0], h, self.n)
                eso.beta1, eso.beta2 = np.maximum(b1, self.b1_floor), np.maximum(b2, self.b2_floor)
            clock[0] += 1
        self._correct(eso, y)                             # eq. 6, both channels
        self.e_last = None if y is None else e_last + eso.z2 * age  # the reset: the last row's error, now
        z1, z2 = eso.z1, eso.z2
        fE, fN, fU = f_n[:, 0], f_n[:, 1], f_n[:, 2]
        if a.td == "ls":
            eso_f, eso_q = self.eso_f, self.eso_q
            # int f_n dt at the rows' times, as y is the velocity there
            if first:
                eso_f.reset(F_bar, f_n)
            if a.eso_start == "ls" and y is not None:
                eso_f.beta1, eso_f.beta2 = np.maximum(b1, self.eso_f_b1), np.maximum(b2, self.eso_f_b2)
            self._correct(eso_f, F_bar)
            f_n = eso_f.z2                                # G f_n: the specific force as z2 sees it
            c = self.q_time(j, times[1])
            if first:
                eso_q.reset((c * c + times[2]) / 2.0)
            if a.eso_start == "ls":
                eso_q.beta1, eso_q.beta2 = eso.beta1, eso.beta2
                self.eso_x.beta1, self.eso_x.beta2 = eso.beta1[1], eso.beta2[1]
            self._correct(eso_q, None if y is None else (c * c + times[2]) / 2.0)
            fE, fN, fU = f_n[:, 0], f_n[:, 1], f_n[:, 2]
        dv_hat = z1 - self.reset_sum                           # current strapdown velocity error
        p = -(z2[:, 0] - cor * dv_hat[:, 1]) / fU         # eq. 7 without the fN psiU term
        q = (z2[:, 1] + cor * dv_hat[:, 0]) / fU          # eq. 9 without the fE psiU term
        s, n = fE / fU, fN / fU
        if first:
            self.td_f.reset(f_n)
        _, df = self.td_f.update(f_n)
        if a.td == "fst":
            if first:
                self.td_q.reset(q)
            _, dq = self.td_q.update(q)                        # eq. 15
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
            if self.den0_prev is not None:
                self.X_int += 0.5 * h * (den_a + self.den0_prev[0])
                self.Xb_int += 0.5 * h * (den_b + self.den0_prev[1])
                self.M_int += 0.5 * h * (m_known + self.m_prev)
            self.den0_prev, self.m_prev = (den_a, den_b), m_known
            self.XX_int += self.X_int * h
            if first:
                self.eso_x.reset(self.XX_int, self.X_int)
            self._correct(self.eso_x, None if y is None else self.XX_int)
            # int s' dt = s - s(0), with s = G fE / G fU already through the ESO's filter
            X = self.X = self.eso_x.z2 + self.Xb_int + s - self.s_jumps
            if j >= self.td_from and y is not None:  # a prediction adds nothing to the fits
                self.td_ls.add(X, q - self.M_int)
                self.td_p.add(np.broadcast_to(self.eso_q.z2[0], (R,)), p)
            fitted = j >= self.td_ready and self.td_ls.origin is not None
            psiU = -self.td_ls.fit(X)[1] if fitted else np.zeros(R)
        psiE = q + s * psiU
        if a.td == "ls" and fitted:
            # q + s psiU is psiE through the ESO's filter, which lags a ramp by beta1 / beta2 (less the
            # step's own delay, plus the time since the last rows): add the ramp the fit gives, psiE' = m - psiU den0
            late = (j - clock[2]) * h - times[1] * dt
            lag = eso.beta1[1] / eso.beta2[1] - h - dt / 2.0 + late
            psiE = psiE + lag * (m_known - psiU * den0)
            lagN = eso.beta1[0] / eso.beta2[0] - h - dt / 2.0 + late
            psiN = p + n * psiU + lagN * self.td_p.fit(self.eso_q.z2[0])[1]  # p's drift (mostly -epsN), the same lag
        else:
            psiN = p + n * psiU
        # what the feedback needs of this step
        self._now = f_n, df, W, sl, cl, lat_rate, cor, s
        return np.stack([psiE, psiN, psiU], axis=-1)

    def reset_velocity(self, st):
        """After a step with rows: the strapdown's level velocity ``st.v_n`` less the last row's error (the reset,
        kept in ``reset_sum``); and the velocity the next step starts from."""
        if self.e_last is not None:
            st.v_n[:, :2] -= self.e_last
            self.reset_sum += self.e_last
        self.v_prev = st.v_n[:, :2].copy()

    def feedback_due(self, j):
        """Whether the attitude is fed back after step ``j`` (``feedback_from_s``, ``feedback_every_s``; not before
        the first row)."""
        return (self.fb_from is not None and j >= self.fb_from and (j - self.fb_from) % self.fb_every == 0
                and self.clock[0] > 0)

    def feedback(self, j, psi, st):
        """After step ``j``: turn the strapdown's attitude ``st.C_bn`` by the estimate ``psi`` (R, 3) where it is in
        the small-angle range, shift the observers accordingly; returns the estimate left (R, 3), rad."""
        a, h, dt, R = self.a, self.h, self.dt, self.R
        eso = self.eso
        f_n, df, W, sl, cl, lat_rate, cor, s = self._now  # of the step just made
        fE, fN, fU = f_n[:, 0], f_n[:, 1], f_n[:, 2]
        # runs whose estimate is out of the small-angle range (not settled) are not corrected
        ok = np.linalg.norm(psi, axis=-1) <= a.feedback_limit
        d = np.where(ok[:, None], psi, 0.0)
        st.C_bn[:] = apply_misalignment(st.C_bn, -d)
        # exact change of the velocity-error rate: (exp([d x]) - I) f_n (= d x f_n to first order)
        Rd = rotvec_to_dcm(d)
        da = np.einsum("rij,rj->ri", Rd, f_n) - f_n
        # change of the psi rates (eq. 1 rows 3-5 for psi -> psi - d) and of the velocity-error
        # accelerations: the ESO's steady ramp lag changes with them
        dE = -(W * sl * d[:, 1] - W * cl * d[:, 2])
        dN = W * sl * d[:, 0] + lat_rate * d[:, 2]
        dU = -(W * cl * d[:, 0] + lat_rate * d[:, 1])
        # d/dt (f x (-d) ) = f x dpsi' + f' x (-d), horizontal components; f x dpsi' (ENU) the ramp of the rate
        ramp = np.stack([fN * dU - fU * dN, fU * dE - fE * dU, fE * dN - fN * dE], axis=-1)
        da_rate = ramp[:, :2] - np.stack([df[:, 1] * d[:, 2] - df[:, 2] * d[:, 1],
                                          df[:, 2] * d[:, 0] - df[:, 0] * d[:, 2]], axis=-1)
        lead = (h + dt) / 2.0 + self.times[1] * dt  # to the time of the next rows' prediction
        if a.td == "fst":
            cor_dv = cor[:, None] * da[:, :2] * (h + lead)  # Coriolis of dv_hat's change from the next step on
            _, dz2 = eso.shift(da[:, :2], da_rate, lead=lead)
        else:
            # the past as if corrected: y + (Rd - I)(F - F_now), F = int f_n dt, whose ESO copy eso_f gives the
            # ESO's exact response (a turning or accelerating base's too); da is its z2 part (G f). Only the
            # ramp of the psi rates' change, f x dpsi', is new, with the ESO's exact lag from its response to Q
            dF = self.eso_f.z1 - self.F_int
            dz1f = (np.einsum("rij,rj->ri", Rd, dF) - dF)[:, :2]
            da_rate = ramp[:, :2]
            c_next = self.q_time(j + 1, self.times[1])
            e1, e2 = self.eso_q.z1 - (c_next * c_next + self.times[2]) / 2.0, self.eso_q.z2 - c_next
            dz1 = dz1f + da_rate * ((lead**2 + self.times[2]) / 2.0 + e1)  # the rows' spread: tau2 / 2
            cor_dv = cor[:, None] * (dz1f + h * da[:, :2])
            dz2 = da[:, :2] + da_rate * (lead + e2)
            eso.z1, eso.z2 = eso.z1 + dz1, eso.z2 + dz2
            # int f_n dt changes as the velocity does (its up channel with the north one's lag)
            e1, e2 = e1[[0, 1, 1]], e2[[0, 1, 1]]
            self.eso_f.z1 = (self.eso_f.z1 + np.einsum("rij,rj->ri", Rd, dF) - dF
                             + ramp * ((lead**2 + self.times[2]) / 2.0 + e1))
            self.eso_f.z2 = self.eso_f.z2 + da + ramp * (lead + e2)
        # the TD's input q moves with the ESO's states: z22 (lag included) and, in the Coriolis
        # term, dv_hat = z21 - resets, which from the next step on is dz1 + h da larger
        dq_step = (dz2[:, 1] + cor_dv[:, 0]) / fU
        dp_step = -(dz2[:, 0] - cor_dv[:, 1]) / fU
        dq_rate = da_rate[:, 1] / fU - dq_step * df[:, 2] / fU
        if a.td == "fst":
            self.td_q.x1 += dq_step + (h - 2.0 * self.h1) * dq_rate  # prediction for the next step, less the lag
            self.td_q.x2 += dq_rate
        elif self.td_ls.origin is not None:
            # the fit's past moves by the line the correction would have made: its value now by the
            # jump of q (referred back from the next step's prediction), its slope -psiU by d_U
            self.td_ls.shift(dq_step - dq_rate * lead, d[:, 2], self.X)
            # p's past: its value by the jump of p, its slope by the change of psiN' (eq. 1 row 4)
            self.td_p.shift(dp_step - dN * lead, dN, np.broadcast_to(self.eso_q.z2[0], (R,)))
        self.td_f.x1 += da  # the strapdown's f_n turns with its attitude: f_n <- exp([d x]) f_n
        self.rows.turn_marks(j, self.m, Rd, ramp, self.P, self.marks, self.F_int)  # position spans
        if a.td == "ls":
            self.s_jumps += self.eso_f.z2[:, 0] / self.eso_f.z2[:, 2] - s
        self.psi_fb += d
        return psi - d
