"""The estimator of the ESO/TD aligner (:class:`adrc.moving_base.ESOTDAligner`, seed 001: Zhao, Zhuang and Yang,
Control and Decision 22(2), 2007): the states of the level ESO (eqs. 5-6), of eq. 12's least-squares or fst TD and
of their copies, the clock of the rows, and the attitude feedback with the shifts that keep every observer
continuous. The steps themselves (the ESO, the level angles of eqs. 7 and 9, eq. 12's azimuth, the velocity reset at
rows) are the compiled loop's (:mod:`adrc.moving_base_compiled`; its NumPy oracle is ``tests/oracles/eso_td.py``),
on this object's arrays. Frames: n = ENU, b = RFU; psi = [psiE, psiN, psiU] rad is the strapdown's misalignment. The
equations, their derivations and the measured design choices are in ``docs/methods/eso-td.md``.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation.attitude import apply_misalignment, rotvec_to_dcm

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

    The compiled loop (:func:`adrc.moving_base_compiled.run_compiled`) steps its states in place: from one step's
    strapdown output and the rows valid in it, the estimate ``psi`` of the strapdown's misalignment (eqs. 6, 7, 9,
    12) and the velocity reset at rows. :meth:`feedback` turns the strapdown by the estimate and moves every observer
    to where it would be had the strapdown always carried the corrected error ("Velocity reset and attitude
    feedback").

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
        self.v_prev = rows.v0[:, :2].copy()  # the level velocity at the step's start
        self.P, self.marks = np.zeros((R, 5)), np.zeros((R, rows.mark_k.size, 8))  # position intervals' integrals
        self.clock, self.times = np.zeros(3, np.int64), np.zeros(3)

    def q_time(self, j, offset):
        """Time (s) of rows ``offset`` samples from step ``j``'s mean sample end, from the first rows' mean time."""
        return (j - self.clock[1]) * self.h + (offset - self.times[0]) * self.dt

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
