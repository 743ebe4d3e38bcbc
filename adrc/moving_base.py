"""ESO/TD moving-base alignment (seed 001: Zhao, Zhuang, Yang, Control and Decision 22(2), 2007).

The paper aligns a platform INS on a moving base with a second-order extended state observer (ESO)
per level velocity channel and a tracking differentiator (TD) built on Han's ``fst``. Here the
"platform" is the shared strapdown (:class:`fusionbench.strapdown.Strapdown`, position free, height
held) started from an initial attitude guess; its misalignment is estimated from its velocity
errors against a velocity reference and removed from the reported attitude (and, once settled,
fed back into the strapdown: see the last section).

Frames and signs
----------------
n = ENU, b = RFU (right, front, up). psi = [psiE, psiN, psiU] (rad) is the misalignment of the
strapdown attitude, ``C_sd = (I - [psi x]) C_true`` (the contract's phi). The reported attitude is
``C_est = exp([psi_hat x]) C_sd = apply_misalignment(C_sd, -psi_hat)``, i.e. (I + [psi_hat x]) C_sd
to first order, so its error is psi - psi_hat.

Error model (eqs. 1, 3, 4, 8, 10; moving base east/north with latitude L, W = w_ie + lambda_dot)
------------------------------------------------------------------------------------------------
``lambda_dot = vE / ((R_N + h) cos L)`` is the longitude rate (rad/s), ``L_dot = vN / (R_M + h)``
the latitude rate, f = [fE, fN, fU] the specific force in n (m/s^2, from the strapdown:
``f_n = C_bn dvel / dt``), nab = [nabE, nabN] the accelerometer biases and eps the gyro drifts in n::

    dvE' =  (2 w_ie + lambda_dot) sin L dvN - fU psiN + fN psiU + nabE            (eqs. 1, 3 row 1)
    dvN' = -(2 w_ie + lambda_dot) sin L dvE + fU psiE - fE psiU + nabN            (eqs. 4, 8)
    psiE' =  W sin L psiN - W cos L psiU - epsE                                    (eq. 10)
    psiN' = -W sin L psiE - L_dot psiU - epsN                                      (eq. 1 row 4)
    psiU' =  W cos L psiE + L_dot psiN - epsU                                      (eq. 1 row 5)

The paper writes g where the vertical specific force fU stands (equal on a static base; here fU is
about 0.7 % smaller at 390 m/s east, which would be a 0.14' level error on 20'); the gyro drift
enters with -eps for a strapdown (+eps for the paper's platform: only the sign of the limit term
changes). The velocity-error terms dv/R of a free strapdown (Schuler coupling) are not in eq. 1:
see "Velocity reset" below, which keeps them negligible.

ESO (eqs. 5-6), one per channel, step h
---------------------------------------
East channel (state z11 ~ dvE, extended state z12 ~ dvE' = 2 w sinL dvN - g psiN + fN psiU + nabE)::

    e1 = z11 - y1
    z11 <- z11 + h (z12 - beta11 e1)
    z12 <- z12 - h beta12 fal(e1, alpha1, delta1)                                  (eq. 6)

and likewise (z21, z22, beta21, beta22, alpha2, delta2) on the north channel, y2 ~ dvN. Units:
z*1 and y in m/s, z*2 in m/s^2, beta*1 in 1/s, beta*2 in 1/s^2 (for alpha = 1), delta in m/s.

**How the printed gains are read.** beta11 = 0.6, beta12 = 0.08 are *continuous* gains (1/s,
1/s^2) multiplied by h in the Euler step above, as in Han's discrete ESO. With alpha = 1, fal is
linear (fal(e, 1, delta) = e whatever delta, so delta = 2h plays no role) and the observer error
obeys s^2 + beta11 s + beta12 = (s + 0.2)(s + 0.4): time constants 5 s and 2.5 s, the level
estimates settle in about 25 s, and z12 follows dvE' through the low-pass
G(s) = beta12 / (s^2 + beta11 s + beta12) with a lag of beta11 / beta12 = 7.5 s on a ramp.
Discretised at h = 0.1 s the error matrix [[1 - h beta11, h], [-h beta12, 1]] has eigenvalues
0.98 and 0.96: stable. The gains are small, so the other readings converge too: per-step gains
(h beta = 0.6, 0.08, i.e. beta = 6 /s, 0.8 /s^2) give eigenvalues 0.986 and 0.414 (a 7 s and a
0.2 s mode), the "Han bandwidth" reading (beta11 = 0.6 / h, beta12 = 0.08 / h^2) 0.8 and 0.6 (a
0.5 s observer). What tells them apart is noise: the rms of z12 per unit white noise on y is 0.024,
0.088 and 0.92 /s for the three readings, so the continuous reading (kept here) passes 3.7 and 39
times less reference noise into psi, the only one compatible with an ESO "barely affected" by a
100-fold noise change, as the paper reports; the others are available by passing those numbers.

Level misalignment (eqs. 7, 9)
------------------------------
::

    psiN_hat = -(z12 - (2 w_ie + lambda_dot) sin L dvN_hat - fN psiU_hat) / fU    (eq. 7)
    psiE_hat =  (z22 + (2 w_ie + lambda_dot) sin L dvE_hat + fE psiU_hat) / fU    (eq. 9)

with dv_hat the estimated current velocity error of the strapdown (z11, z21 less the resets).
The biases make the limits psiE - psiE_hat = -nabN / fU, psiN - psiN_hat = nabE / fU (plus the
psiU error times fE / fU, fN / fU).

Azimuth (eqs. 11-12) and the TD (eqs. 13-15)
-------------------------------------------
::

    psiU_hat = ((w_ie + lambda_dot) sin L psiN_hat - psiE_hat') / ((w_ie + lambda_dot) cos L)  (eq. 12)

psiE_hat' comes from a TD with Han's fst (eqs. 14-15, :func:`fst`). On the moving base psiE_hat
itself contains fE psiU_hat / fU (eq. 9), so eq. 12 is implicit in psiU_hat. Differentiating
psiE_hat as printed, with the previous step's psiU_hat inside, closes a loop whose error decays as
exp(-t fU W cos L / fE): a 1650 s time constant at 0.1 g, far too slow for a 400 s alignment.
This module therefore differentiates only the measured part of eq. 9, q = (z22 + ... dvE_hat) / fU
(TD on q), and with p = -(z12 - ... dvN_hat) / fU, s = fE / fU, n = fN / fU solves eqs. 7, 9, 12
together, taking d(s psiU)/dt = s' psiU + s psiU' with psiU' from eq. 1 row 5 and s' from a second
TD on the specific force (filter factor ``force_h1``)::

    psiE = q + s psiU,   psiN = p + n psiU,   psiE' = q' + s (W cosL psiE + L_dot psiN) + s' psiU
    psiU [W cosL (1 + s^2) - W sinL n + s n L_dot + s'] = W sinL p - q' - s (W cosL q + L_dot p)

On a static base (s = n = 0) this is eq. 12 exactly. The azimuth error left by constant biases is
then, for an eastward base (derivation in ``tests/test_moving_base.py``)::

    psiU - psiU_hat = (-epsE + s epsU + W sinL nabE / fU + s W cosL nabN / fU + k) / Den,
    k = d(nabN / fU)/dt,   Den = W cosL (1 + s^2) - W sinL n + s'

i.e. the stationary limit -epsE / (w_ie cos L) + tan L nabE / g with the earth rate replaced by
w_ie + lambda_dot and small terms in s = fE / fU and in the slow decrease of fU with speed. On seed
001's base the limits at 400 s are [-0.434, 0.342, -0.867]' against [-0.344, 0.344, -2.525]' on a
static base: the longitude rate (7.4e-5 rad/s at 390 m/s) doubles W.

TD (eqs. 14-15), step h, "filter factor" h1, "speed factor" r::

    x1 <- x1 + h x2
    x2 <- x2 + h fst(x1, x2, v, r, h1)                                             (eq. 15)

With r = 500 and h1 = 5 h = 0.5 s (the paper's) the linear zone of fst is |x1 - v + h1 x2| <
h1^2 r = 125 (units of v), so for misalignment signals the TD is the linear critically damped
filter x1'' = -(x1 - v) / h1^2 - 2 x1' / h1 (double pole -1/h1; its Euler form has the double
eigenvalue 1 - h / h1), whose x2 is the derivative low-passed by 1 / (1 + h1 s)^2: exact in
steady state on a ramp, where x1 lags by 2 h1 v'.

Noise: eq. 12 divides the derivative of a level estimate by W cos L ~ 1e-4 rad/s, and between
1 / h1 and the ESO's poles the chain ESO -> TD passes velocity noise to psiE_hat' with a flat gain
1 / (g h1^2). With the paper's h1 = 0.5 s a 1 cm/s reference noise at 10 Hz gives about 9 deg rms of
azimuth noise; h1 = 20 s with a 1 cm/s, 100 Hz reference (averaged to 10 Hz) gives 1.5' rms, at the
price of a TD transient of about 8 h1 before the azimuth is valid (``settle_s``).

Velocity reset and attitude feedback (beyond the paper; why)
-----------------------------------------------------------
* **Velocity reset, every step**: after each step the strapdown's level velocity is set to the
  reference (``v <- v - (v_end - vref_end)``). Without it the velocity error of a 20' tilt grows to
  about 20 m/s in 400 s and its Schuler term -dvN / R in psiE' (3e-6 rad/s) would swamp the earth-rate
  term that eq. 12 reads (7e-7 rad/s for 40'): eq. 1 has no dv / R terms, and the reset keeps it
  valid (the velocity error stays at the centimetre level). The ESO is fed the *unreset* velocity
  error y = mean over the step of (v - vref) plus the sum of all past resets, which is continuous
  (reference noise does not accumulate: the resets telescope, y = integral of the acceleration
  error minus the mean reference noise of the step).
* **Attitude feedback** (``feedback_from_s``, ``feedback_every_s``; default: from ``settle_s``, 64 s
  with the paper's parameters, then every 10 s): the strapdown attitude is turned by the current
  estimate, ``C_sd <- exp([psi_hat x]) C_sd``, and the observers are moved to where they would be
  had the strapdown always carried the corrected error, so the reported attitude does not jump:

  - the velocity-error rates change by da = (exp([d x]) - I) f_n (exact; d x f_n to first order)
    and their slopes by da' = f x dpsi' - f' x d, dpsi' being the change of eq. 1 rows 3-5 for
    psi -> psi - d; the ESO moves z2 += da + da' l + e2, z1 += da l + da' l^2 / 2 + e1 (z1, z2 are
    already the predictions for the next step's mean velocity, l = (h + dt) / 2 ahead, made with
    the old rates; e1 = -da' / beta2, e2 = da' h / 2 + beta1 e1 is the change of the steady lag on a
    ramp, :meth:`SecondOrderESO.shift`); the specific-force TD moves by da (f_n turns with C_sd);
  - the TD on q moves by dq = (dz22 + (2 w_ie + lambda_dot) sinL ddvE_hat) / fU, where the
    Coriolis term's dvE_hat = z21 - resets grows by da_E (h + l), and dq' = da_N' / fU - dq fU' / fU:
    x1 += dq + (h - 2 h1) dq', x2 += dq' (its prediction for the next step and steady lag on a ramp).

  Why: in the open loop (``feedback_from_s=None``, the paper) the strapdown keeps its 20'-40'
  misalignment and the small-angle model errs by second-order terms: measured on seed 001, the final
  errors are off the limits by 0.12' (levels) and 0.34' (azimuth), as large as the limits; with the
  feedback they land on the limits within 0.02'. The shifts are exact to first order (a small
  correction leaves no transient at all); the first, large one (40') leaves an azimuth transient of
  up to 1.5' that is below 0.3' 6 s later and below 0.05' 14 s later, from the second-order terms
  (the composition psi -> psi - d + (d x psi) / 2 and the psi rates' terms in psi^2), which no
  model of the estimate can give. Runs whose estimate exceeds ``feedback_limit_deg`` (not settled)
  are not corrected.

The attitude is reported after every step: t (M,) the step ends, C_bn (R, M, 3, 3), and ``extra``:
``psi_hat_rad`` (R, M, 3) the estimate of the strapdown's current misalignment (removed from the
output), ``psi_feedback_rad`` (R, M, 3) the sum of the corrections fed back so far (their sum is the
estimate of the initial guess's misalignment, to first order), ``velocity_error_mps`` (R, M, 2) the
unreset level velocity error fed to the ESO.

The aligner needs an initial attitude within a few degrees (the model is small-angle; seed 001
starts from psi = 20', 20', 40'): ``init=None`` is refused.
"""

from __future__ import annotations

import numpy as np

from fusionbench import earth
from fusionbench.aligner import AlignmentResult, Site, coarse_then_fine, initial_attitude
from fusionbench.attitude import apply_misalignment, rotvec_to_dcm
from fusionbench.compass import check_compass_latitude
from fusionbench.strapdown import NavState, Strapdown

from .primitives import FSTTrackingDifferentiator, SecondOrderESO, fst  # noqa: F401 (re-exported)

__all__ = ["fst", "FSTTrackingDifferentiator", "SecondOrderESO", "ESOTDAligner"]


# ---------------------------------------------------------------------------------------- aligner
class ESOTDAligner:
    """ESO/TD moving-base alignment (method ``eso-td``), seed 001; defaults are the paper's.

    Parameters
    ----------
    T : float
        ESO/TD step, s (0.1, the paper's sample period). Rounded to a whole number of IMU samples;
        a faster IMU's velocities are averaged over each step, a slower one runs at its own interval.
    alpha1, alpha2 : float
        fal exponents of the east and north ESO (1: linear).
    delta1, delta2 : float, optional
        fal linear zones, m/s (default 2 h; no effect when alpha = 1).
    beta11, beta12, beta21, beta22 : float
        ESO gains, continuous (1/s, 1/s^2): 0.6, 0.08 on both channels (see the module docstring).
    td_h1 : float, optional
        TD filter factor, s (default 5 h).
    td_r : float
        TD speed factor, 1/s^2 on rad signals (500).
    force_h1 : float
        Filter factor (s) of the TD that differentiates the specific force f_n (for s' = (fE / fU)' in
        eq. 12 and f' in the feedback shifts): 5 s, so that accelerometer noise stays out of the
        denominator of eq. 12 (with 0.5 s, 50 ug/sqrt(Hz) would make s' as large as W cos L; with
        5 s, 3 % of it) while its start-up transient (8 force_h1) ends before the first feedback.
    feedback_from_s : float, "auto" or None
        Time of the first attitude feedback into the strapdown, s from the start of the record;
        "auto" (default): ``settle_s``; None: open loop, as the paper.
    feedback_every_s : float
        Interval of the feedback after the first, s.
    feedback_limit_deg : float
        Runs whose |psi_hat| exceeds this (deg) are not corrected at a feedback instant.
    coarse_s : float
        Without an initial attitude, the inertial-frame coarse alignment runs this long first, s.

    Attributes
    ----------
    settle_s : float
        max(12 / (slowest ESO pole), 8 force_h1) + 8 h1, s: when the estimates are settled (64 s with
        the paper's parameters). Also ``min_duration_s``.
    """

    name = "eso-td"
    description = ("ESO/TD moving-base alignment (seed 001): 2nd-order ESO per level velocity channel, "
                   "fst TD for the azimuth (eqs. 6-15); needs an initial attitude and a velocity reference")

    def __init__(self, T=0.1, alpha1=1.0, alpha2=1.0, delta1=None, delta2=None, beta11=0.6, beta12=0.08,
                 beta21=0.6, beta22=0.08, td_h1=None, td_r=500.0, force_h1=5.0, feedback_from_s="auto",
                 feedback_every_s=10.0, feedback_limit_deg=2.0, coarse_s=60.0):
        self.T = float(T)
        self.coarse_s = float(coarse_s)
        self.alpha = (float(alpha1), float(alpha2))
        self._delta = (delta1, delta2)
        self.beta1 = (float(beta11), float(beta21))
        self.beta2 = (float(beta12), float(beta22))
        self._td_h1 = td_h1
        self.td_r = float(td_r)
        self.force_h1 = float(force_h1)
        self.feedback_every_s = float(feedback_every_s)
        if self.feedback_every_s <= 0:
            raise ValueError(f"feedback_every_s: expected a positive interval in s, found {feedback_every_s}")
        self.feedback_limit = float(feedback_limit_deg) * np.pi / 180.0
        # settling: the ESO's initial error (~g psi) must fall by ~1e-5 before eq. 12 can read its
        # derivative (12 time constants of the slow pole; the specific-force TD settles meanwhile,
        # 8 force_h1), then the TD's transient (8 h1)
        slow = min(_slow_rate(b1, b2) for b1, b2 in zip(self.beta1, self.beta2))
        self.settle_s = float(np.ceil(max(12.0 / slow, 8.0 * self.force_h1) + 8.0 * self.td_h1_for(self.T)))
        if isinstance(feedback_from_s, str):
            if feedback_from_s != "auto":
                raise ValueError(f"feedback_from_s: expected a time in s, 'auto' or None, found {feedback_from_s!r}")
            feedback_from_s = self.settle_s
        self.feedback_from_s = None if feedback_from_s is None else float(feedback_from_s)
        self.min_duration_s = self.settle_s

    def td_h1_for(self, h):
        """The TD filter factor used with step ``h`` (s): ``td_h1`` or 5 h."""
        return 5.0 * h if self._td_h1 is None else float(self._td_h1)

    def deltas_for(self, h):
        """The fal linear zones (east, north) used with step ``h``: ``delta1``, ``delta2`` or 2 h."""
        return tuple(2.0 * h if d is None else float(d) for d in self._delta)

    def align(self, imu, site: Site, vref=None, init=None) -> AlignmentResult:
        """Align R recordings on a moving base; see the module docstring.

        Parameters
        ----------
        imu : IMUData
            Body RFU increments or rates.
        site : Site
            Position at the initial state.
        vref : ndarray, shape (R, M, 3), optional
            Reference velocity (ENU, m/s) at each increment end; zero (static base) if None.
        init : ndarray, shape (R, 3, 3) or (3, 3), optional
            Initial attitude C_bn within a few degrees (the small-angle model; seed 001 starts from
            20', 20', 40'). None: an inertial-frame coarse alignment over the first ``coarse_s``
            seconds first, which assumes a stationary or swaying base.
        """
        if init is None:  # any heading: inertial-frame coarse alignment first (stationary or swaying base)
            from baselines.coarse import InertialCoarseAligner

            return coarse_then_fine(imu, site, vref, InertialCoarseAligner(history_points=20), self.coarse_s,
                                    lambda rest, vr, C0: self.align(rest, site, vr, C0))
        check_compass_latitude(site.lat, self.name)
        if imu.duration < self.min_duration_s:
            raise ValueError(f"duration: {self.name} needs at least {self.min_duration_s:g} s, "
                             f"found {imu.duration:g} s")
        t, dth, dvel = imu.increments()
        R, dt = imu.runs, imu.dt
        C0 = initial_attitude(init, R)
        if vref is None:
            vref = np.zeros((R, t.size, 3))
        vref = np.asarray(vref, dtype=float)
        if vref.shape != (R, t.size, 3):
            raise ValueError(f"vref: expected shape ({R}, {t.size}, 3), found {vref.shape}")
        m = max(1, int(round(self.T / dt)))
        h = m * dt
        steps = t.size // m

        def blocks(a):  # (steps, R, m, 3), one contiguous block per step
            return np.ascontiguousarray(a[:, :steps * m].reshape(R, steps, m, 3).swapaxes(0, 1))

        dth_b, dv_b, vref_b = blocks(dth), blocks(dvel), blocks(vref)
        # initial velocity at t0: the reference extrapolated back one increment
        v0 = vref[:, 0] - (vref[:, 1] - vref[:, 0]) if t.size > 1 else vref[:, 0]
        v0 = v0 * np.array([1.0, 1.0, 0.0])
        sd = Strapdown(NavState.broadcast(R, C0, v_n=v0, lat=site.lat, lon=site.lon, h=site.h), dt,
                       position_fixed=False, height_fixed=True)

        h1 = self.td_h1_for(h)
        eso = SecondOrderESO((R, 2), h, self.beta1, self.beta2, self.alpha, self.deltas_for(h))
        td_q = FSTTrackingDifferentiator((R,), h, self.td_r, h1)
        td_f = FSTTrackingDifferentiator((R, 3), h, self.td_r, self.force_h1)  # f_n' (s', feedback shifts)
        # first feedback at the first step ending at or after feedback_from_s (step j ends at t0 + (j + 1) h)
        fb_from = None if self.feedback_from_s is None else max(0, int(np.ceil(self.feedback_from_s / h - 1 - 1e-9)))
        fb_every = max(1, int(round(self.feedback_every_s / h)))

        reset_sum = np.zeros((R, 2))
        psi_fb = np.zeros((R, 3))
        records = steps + (t.size > steps * m)  # one more for the samples after the last step (time rule)
        hist_t = np.empty(records)
        hist_C = np.empty((R, records, 3, 3))
        hist_psi = np.empty((R, records, 3))
        hist_fb = np.empty((R, records, 3))
        hist_y = np.empty((R, records, 2))
        for j in range(steps):
            out = sd.run(dth_b[j], dv_b[j], record_every=1)
            dv_samples = out["v_n"][..., :2] - vref_b[j][..., :2]
            y = dv_samples.mean(axis=1) + reset_sum          # unreset level velocity error, m/s
            f_n = np.einsum("rkij,rkj->ri", out["C_bn"], dv_b[j]) / h  # specific force, ENU, m/s^2
            st = sd.state
            lat = st.lat
            rm, rn = earth.radii(lat)
            sl, cl = np.sin(lat), np.cos(lat)
            lon_rate = st.v_n[:, 0] / ((rn + st.h) * cl)
            lat_rate = st.v_n[:, 1] / (rm + st.h)
            W = earth.OMEGA_IE + lon_rate
            cor = (2.0 * earth.OMEGA_IE + lon_rate) * sl     # Coriolis coefficient of eqs. 4, 7, 9
            fE, fN, fU = f_n[:, 0], f_n[:, 1], f_n[:, 2]

            if j == 0:
                eso.reset(y)
            z1, z2 = eso.update(y)                            # eq. 6, both channels
            dv_hat = z1 - reset_sum                           # current strapdown velocity error
            p = -(z2[:, 0] - cor * dv_hat[:, 1]) / fU         # eq. 7 without the fN psiU term
            q = (z2[:, 1] + cor * dv_hat[:, 0]) / fU          # eq. 9 without the fE psiU term
            s, n = fE / fU, fN / fU
            if j == 0:
                td_q.reset(q)
                td_f.reset(f_n)
            _, dq = td_q.update(q)                            # eq. 15
            _, df = td_f.update(f_n)
            ds = df[:, 0] / fU - fE * df[:, 2] / fU**2        # s' = (fE / fU)'
            # eqs. 7, 9, 12 solved together (module docstring)
            den = W * cl * (1.0 + s * s) - W * sl * n + s * n * lat_rate + ds
            psiU = (W * sl * p - dq - s * (W * cl * q + lat_rate * p)) / den
            psi = np.stack([q + s * psiU, p + n * psiU, psiU], axis=-1)

            hist_t[j] = t[(j + 1) * m - 1]
            hist_C[:, j] = apply_misalignment(st.C_bn, -psi)
            hist_y[:, j] = y

            # velocity reset to the reference (keeps eq. 1's neglected dv / R terms negligible)
            dv_end = out["v_n"][:, -1, :2] - vref_b[j][:, -1, :2]
            st.v_n[:, :2] -= dv_end
            reset_sum += dv_end

            if fb_from is not None and j >= fb_from and (j - fb_from) % fb_every == 0:
                # runs whose estimate is out of the small-angle range (not settled) are not corrected
                ok = np.linalg.norm(psi, axis=-1) <= self.feedback_limit
                d = np.where(ok[:, None], psi, 0.0)
                st.C_bn[:] = apply_misalignment(st.C_bn, -d)
                # exact change of the velocity-error rate: (exp([d x]) - I) f_n (= d x f_n to first order)
                da = np.einsum("rij,rj->ri", rotvec_to_dcm(d), f_n) - f_n
                # change of the psi rates (eq. 1 rows 3-5 for psi -> psi - d) and of the velocity-error
                # accelerations: the ESO's steady ramp lag changes with them
                dE = -(W * sl * d[:, 1] - W * cl * d[:, 2])
                dN = W * sl * d[:, 0] + lat_rate * d[:, 2]
                dU = -(W * cl * d[:, 0] + lat_rate * d[:, 1])
                # d/dt (f x (-d) ) = f x dpsi' + f' x (-d), horizontal components
                da_rate = np.stack([fN * dU - fU * dN - (df[:, 1] * d[:, 2] - df[:, 2] * d[:, 1]),
                                    fU * dE - fE * dU - (df[:, 2] * d[:, 0] - df[:, 0] * d[:, 2])], axis=-1)
                _, dz2 = eso.shift(da[:, :2], da_rate, lead=(h + dt) / 2.0)
                # the TD's input q moves with the ESO's states: z22 (lag included) and, in the Coriolis
                # term, dv_hat = z21 - resets, which from the next step on is da (h + lead) larger
                lead = (h + dt) / 2.0
                dq_step = (dz2[:, 1] + cor * da[:, 0] * (h + lead)) / fU
                dq_rate = da_rate[:, 1] / fU - dq_step * df[:, 2] / fU
                td_q.x1 += dq_step + (h - 2.0 * h1) * dq_rate  # prediction for the next step, less the lag
                td_q.x2 += dq_rate
                td_f.x1 += da  # the strapdown's f_n turns with its attitude: f_n <- exp([d x]) f_n
                psi_fb += d
                psi = psi - d
            hist_psi[:, j] = psi
            hist_fb[:, j] = psi_fb
        if records > steps:  # the samples after the last step, through the strapdown, the last estimate removed
            sd.run(dth[:, steps * m:], dvel[:, steps * m:], record_every=t.size - steps * m)
            hist_t[-1], hist_C[:, -1] = t[-1], apply_misalignment(sd.state.C_bn, -hist_psi[:, -2])
            hist_psi[:, -1], hist_fb[:, -1], hist_y[:, -1] = hist_psi[:, -2], hist_fb[:, -2], hist_y[:, -2]
        return AlignmentResult(self.name, hist_t, hist_C, {"psi_hat_rad": hist_psi, "psi_feedback_rad": hist_fb,
                                                           "velocity_error_mps": hist_y})


def _slow_rate(beta1, beta2):
    """Slowest decay rate (1/s) of the linear ESO error, the roots of s^2 + beta1 s + beta2."""
    disc = beta1 * beta1 - 4.0 * beta2
    if disc < 0:
        return beta1 / 2.0
    return (beta1 - np.sqrt(disc)) / 2.0
