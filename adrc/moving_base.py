"""ESO/TD alignment (seed 001: Zhao, Zhuang, Yang, Control and Decision 22(2), 2007): moving base with a
velocity reference, stationary or swaying base without one.

The paper aligns a platform INS on a moving base with a second-order extended state observer (ESO)
per level velocity channel and a tracking differentiator (TD) built on Han's ``fst``. Here the
"platform" is the shared strapdown (:class:`fusionbench.strapdown.Strapdown`, position free, height
held) started from an initial attitude guess (or an inertial-frame coarse alignment); its misalignment
is estimated from its velocity errors against a velocity reference (zero on a stationary or swaying
base) and removed from the reported attitude (and, once settled, fed back into the strapdown: see
"Velocity reset and attitude feedback"). The paper's printed configuration is :data:`PAPER_PARAMETERS`;
the class defaults differ in how the ESO starts and how eq. 12's derivative is taken ("The default
configuration"), because the printed TD cannot read the azimuth on a stationary base ("Why the printed
TD fails on a stationary base").

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

Why the printed TD fails on a stationary base
---------------------------------------------
On a stationary or swaying base the azimuth is observable only through the earth rate: psiE drifts at
-W cosL psiU (eq. 10), 1e-8 rad/s for 1' at 34 deg. What limits its reading is information that accrues
with time: the gyro's angle random walk makes psiE a random walk, so its mean slope over T is known to
ARW / sqrt(T) (the bound sqrt(ARW^2 / (W^2 cos^2 L T) + (instability / (W cos L))^2) of any method: 4.8'
for seed 000's 0.005 deg/sqrt(h) over 300 s at 34 deg), and a reference's white noise averages out as
T^-2.5. The printed TD differentiates psiE_hat with a fixed 0.5-s filter, so eq. 12 passes the gyro noise
with a 0.5-s bandwidth and the velocity noise twice differentiated: measured from init=None over 300 s at
100 Hz, 8 runs, the printed configuration (open loop) ends 23' rms from the limit with seed 000's IMU (4.9
times the bound), 18' with navigation grade (8.9 times), 1200' with a zero reference carrying 0.05 m/s
of white noise per sample, and on seed 000's 5/7/9-deg sway 1500' (the strapdown's velocity carries
1e-5 m/s at the sway frequencies, which the 0.5-s TD differentiates twice: +-3' with a perfect IMU even
with the attitude feedback, 0.96' at the last sample). A longer fixed h1 trades that noise against a lag
and still never averages more than h1 seconds. What the azimuth needs is a memory that grows with the
data, as a least-squares fit's does.

The default configuration
-------------------------
**ESO started as a least-squares fit** (``eso_start="ls"``). Eq. 6 with beta1 = (g + g') / h, beta2 =
g' / h^2 and Morrison's expanding-memory gains g = 2 (2k + 1) / ((k + 1)(k + 2)), g' = 6 / ((k + 1)(k + 2))
at step k (:func:`expanding_memory_gains`) is exactly the least-squares line through the velocity errors
so far: it has no start-up transient, whatever the initial tilt. Its gains fall as 4 / t and 6 / t^2
until they reach the floor beta1 = 2 w0, beta2 = w0^2 (critically damped, w0 = 0.05 rad/s, after
2.45 / w0 = 48.9 s), where it stays a fixed-bandwidth ESO: the level angles must follow the strapdown's
drift (psiN' = -epsN, psiE' = -W cosL dpsiU), which a growing memory would lag by t / 2. The floor
trades the level noise (z2's rms per unit white noise on y is sqrt(h w0^3 / 4): with a 0.1 m/s, 10-Hz
reference, 0.06' at w0 = 0.05, 0.18' at 0.1, 0.84' with the printed gains, and on the moving base psiE
carries fE / fU = 0.1 of the azimuth error too) against its lag behind a random-walking tilt (a tactical
gyro's 0.1 deg/sqrt(h)): over 16 runs, the moving base's worst level error is 0.21' (seed 001's IMU) and
0.37' (navigation) at w0 = 0.05 against 0.63' and 0.78' at 0.1, while a tactical IMU's static levels stay
0.56-0.86' off the bias-only limit for any w0 from 0.05 to 0.14 (the Kalman filter is 0.9' off there).

**Eq. 12 integrated and fitted by least squares** (``td="ls"``). With p, q the measured parts of eqs. 7
and 9 (psiN = p + n psiU, psiE = q + s psiU) eq. 12 is q' = m - psiU den with the known
m = W sinL p - s (W cosL q + L_dot p) and den = den0 + s', den0 = W cosL (1 + s^2) - W sinL n + s n L_dot
(the joint solution below). With psiU constant over the fit (it moves by W cosL psiE, 1e-4 of itself per
second at the limits) its integral is a straight line::

    Y = q - int m dt = a - psiU X,    X = int den0 dt + s        (int s' dt = s: no derivative of f)

and psiU is minus the least-squares slope of Y against X over all the samples since the fit started
(:class:`LeastSquaresDifferentiator`, a TD whose x1 is the fitted value and x2 the slope, with a memory
that grows; ``td_memory_s`` makes it fade). On a stationary base X = W cosL t and this is eq. 12 averaged
over the record: an angle random walk's slope with 6/5 the variance of the end-point difference, so over
the fit (300 - 60 - 48.9 s of a 300-s record) sqrt(1.2 x 300 / 191) = 1.37 times the bound, measured
1.3-1.5 (seed 000, navigation grade; instability adds). The bias terms make it converge to the usual
limit, -epsE / (W cosL) + tanL nabE / g on a stationary base and, on the moving base, their weighted
mean over the fit (W doubles at 390 m/s east: the end's instantaneous limit, eq. 12's, differs by a
fraction of an arcminute).

**Everything through the ESO's filter.** q is z22 / fU: psiE passed through the ESO's filter, whose lag
grows from t / 2 (expanding memory) to beta1 / beta2 = 40 s; a regressor that does not carry the same lag
reads the slope short (57 % after 10 s of fit from a 4-deg error). So X's integral part goes through a
copy of the ESO (``eso_x``, fed with int X dt), s, n and fU come from the specific force through another
copy fed exactly as y is (the step mean of int f_n dt over the step's samples: the 0.1-2 Hz accelerations
of a 0.05 m/s base disturbance, which couple with psiU through fE psiU as on a moving base, would otherwise
reach X and q with different phases), and the ESO's lag of a ramp, needed when the attitude is corrected, is read from a third copy's response to a
unit quadratic (``eso_q``) rather than from its steady state, which it has not reached after the switch
to the floor gains. The reported levels add back the lag of the ramps the fit knows: psiE' = m - psiU den0
times (beta1 / beta2 - h - dt / 2) on psiE, and p's least-squares drift (mostly -epsN: 0.67' for a 1-deg/h
gyro) times the same on psiN.

Measured from init=None (8 runs, 300 s at 100 Hz; moving base 16 runs, 500 s): static, mild and
seed-000 sways, latitudes 0 to +-75 deg, headings 0, 90, +-179 deg, seed 000, navigation and tactical
presets, zero reference with 0 or 0.05 m/s per sample: levels within 0.07' of the limits (tactical:
0.88-0.90', 1.68' at 75 deg), azimuth rms 0.58-1.83 times the bound. Moving base (0.1 g east, 0.05 or
0.1 m/s per sample at 10 or 100 Hz): levels within 0.38', azimuth rms 0.5-1.35 times the Kalman filter's.
With the reference's noise per sample fixed, a lower sample rate is a larger noise density: at 20 Hz a
0.05 m/s zero reference gives 3.05 times the bound (navigation grade, 60 deg), the bound not counting
the reference. And while the strapdown still carries a large azimuth error, that disturbance's coupling
is modelled to first order only: from a start d degrees off in azimuth, a 0.05 m/s disturbance leaves
about 0.35' per degree at 34 deg and 1.1' per degree at 75 deg (noise-free IMU; seed 000's bound is
4.8' and 15' there), and a 60-s coarse start on such a base is a few degrees off.

Velocity reset and attitude feedback (beyond the paper; why)
-----------------------------------------------------------
* **Velocity reset, at rows**: after each step with rows the strapdown's level velocity is set to the
  reference (``v <- v - e``, e the last row's velocity error; a position span's carried to the step's end
  with the ESO's rate). Without it the velocity error of a 20' tilt grows to
  about 20 m/s in 400 s and its Schuler term -dvN / R in psiE' (3e-6 rad/s) would swamp the earth-rate
  term that eq. 12 reads (7e-7 rad/s for 40'): eq. 1 has no dv / R terms, and the reset keeps it
  valid (the velocity error stays at the centimetre level). The ESO is fed the *unreset* velocity
  error y = mean over the step's rows of the antenna's velocity error at each row's time of validity
  (:mod:`adrc.eso_td_rows`: lever arm, latency, positions, steps without rows) plus the sum of all past
  resets, which is continuous (the resets telescope: reference noise does not accumulate).
* **Attitude feedback** (``feedback_from_s``, ``feedback_every_s``; default: from the ESO's floor time,
  48.9 s, levels first and the azimuth once it is reported; ``settle_s`` with td="fst"; then every 10 s):
  the strapdown attitude is turned by the current
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
    x1 += dq + (h - 2 h1) dq', x2 += dq' (its prediction for the next step and steady lag on a ramp);
  - with td="ls" the ESO's lag e1, e2 is its exact response to a unit quadratic (``eso_q``), da' is
    f x dpsi' alone, and z1 moves by (Rd - I)(F_hat - F) with F = int f_n dt and F_hat its ESO copy's
    prediction (``eso_f``, fed as y is: the exact response of a turning or accelerating base, where da l
    assumes f constant and left 23 % of a fed-back azimuth correction on a car with turns); ``eso_f`` and
    the position spans' marks move likewise; the least-squares fit's past moves by the line the correction
    would have made (its value now by dq - dq' l, its slope -psiU by d_U); p's drift fit likewise.

  Why: in the open loop (``feedback_from_s=None``, the paper) the strapdown keeps its 20'-40'
  misalignment and the small-angle model errs by second-order terms: measured on seed 001, the final
  errors are off the limits by 0.12' (levels) and 0.34' (azimuth), as large as the limits; with the
  feedback they land on the limits within 0.02'. The shifts are exact to first order (a small
  correction leaves no transient at all); the first, large one (40') leaves an azimuth transient of
  up to 1.5' that is below 0.3' 6 s later and below 0.05' 14 s later, from the second-order terms
  (the composition psi -> psi - d + (d x psi) / 2 and the psi rates' terms in psi^2), which no
  model of the estimate can give. Runs whose estimate exceeds ``feedback_limit_deg`` (15 deg; not
  settled) are not corrected: a 60-s coarse start with a 0.1 m/s, 10-Hz reference is 3.6 deg off in
  azimuth (rms, 8.6 at most over 16 runs), and the default closes on that within 1.1' (noise-free
  seed 001 IMU on the 0.1 g base, from +-4 and +-8 deg).

Without aiding: a stationary or swaying base, checked
----------------------------------------------------
aiding=None means the base is at rest: a zero velocity at every sample end. A base that moves would be read
as tilted (a constant horizontal acceleration a is a tilt of a / g to first order: the specific force
cannot tell) and the heading would come out wrong, so it is refused before the method runs by the check
every aligner applies without aiding (:func:`fusionbench.motion.check_stationary`: a velocity change no
rotation of gravity explains, or a mean specific force above gravity), one ValueError naming the method,
the figure and ``--aiding``.

The paper's configuration
-------------------------
:data:`PAPER_PARAMETERS` holds the printed values: T = h = 0.1 s (``step_s``), alpha = 1, delta = 2 h, beta11 = beta21
= 0.6, beta12 = beta22 = 0.08 (read as continuous gains, above), TD h1 = 5 h, r = 500, the ESO started
at rest (z1 = y, z2 = 0) with its fixed gains, and no attitude feedback: the paper reads eqs. 7, 9 and 12
out as the estimates (section 3, "eqs. 3-15 make up the alignment loop"); nothing in them torques the
platform, and its figures compare estimation errors. ``ESOTDAligner(**PAPER_PARAMETERS)`` is that
aligner (with this module's velocity reset, which the strapdown needs in place of the paper's platform,
and eqs. 7, 9, 12 solved together on the moving base).

The attitude is reported after every step: t (M,) the step ends, C_bn (R, M, 3, 3), and ``extra``:
``psi_hat_rad`` (R, M, 3) the estimate of the strapdown's current misalignment (removed from the
output), ``psi_feedback_rad`` (R, M, 3) the sum of the corrections fed back so far (their sum is the
estimate of the initial guess's misalignment, to first order), ``velocity_error_mps`` (R, M, 2) the
unreset level velocity error fed to the ESO.
"""

from __future__ import annotations

import numpy as np

from fusionbench import earth
from fusionbench.aligner import AlignmentResult, Site, variant
from fusionbench.claims import Supports
from fusionbench.aligner_base import AlignerBase, coarse_then_fine
from fusionbench.imu import load_spec
from fusionbench.attitude import apply_misalignment, rotvec_to_dcm
from fusionbench.coarse import InertialCoarseAligner
from fusionbench.compass import MAX_LATITUDE_DEG, check_engine
from fusionbench.strapdown import NavState, Strapdown

from .eso_td_rows import StepRows
from .ls_differentiator import LeastSquaresDifferentiator
from .moving_base_compiled import run_compiled
from .primitives import FSTTrackingDifferentiator, SecondOrderESO, fst  # noqa: F401 (re-exported)

__all__ = ["fst", "FSTTrackingDifferentiator", "SecondOrderESO", "LeastSquaresDifferentiator", "ESOTDEstimator",
           "ESOTDAligner", "PAPER_PARAMETERS", "expanding_memory_gains"]

#: Seed 001's printed configuration (section 4): T = 0.1 s (the step, ``step_s``); ESO alpha1 = alpha2 = 1,
#: delta1 = delta2 = 2 h, beta11 = beta21 = 0.6, beta12 = beta22 = 0.08 (continuous gains, see the module
#: docstring); TD h1 = 5 h, r = 500; the ESO started at rest (z1 = y, z2 = 0) with fixed gains, eq. 12's
#: derivative from the fst TD, and the estimates only read out, never fed back into the platform (eqs. 3-15
#: have no control term).
#: ``ESOTDAligner(**PAPER_PARAMETERS)`` is the paper's aligner.
PAPER_PARAMETERS = {
    "step_s": 0.1,
    "alpha1": 1.0, "alpha2": 1.0,
    "delta1": 0.2, "delta2": 0.2,        # 2 h
    "beta11": 0.6, "beta12": 0.08, "beta21": 0.6, "beta22": 0.08,
    "eso_start": "rest",
    "td": "fst", "td_h1": 0.5, "td_r": 500.0,   # h1 = 5 h
    "feedback_from_s": None,
}


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
    """The estimator of :class:`ESOTDAligner` over R runs, stepped once per ESO/TD step (the module docstring's
    names and equations).

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
        if aligner.td == "ls":  # f_n through the ESO's own filter, for s, n, fU consistent with z2 (module docstring)
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
            # eqs. 7, 9, 12 solved together (module docstring)
            den = W * cl * (1.0 + s * s) - W * sl * n + s * n * lat_rate + ds
            psiU = (W * sl * p - dq - s * (W * cl * q + lat_rate * p)) / den
        else:
            # eq. 12 integrated: Y = q - int m = a - psiU X with X = int den (module docstring); X from
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


# ---------------------------------------------------------------------------------------- aligner
class ESOTDAligner(AlignerBase):
    """ESO/TD moving-base alignment (method ``eso-td``), seed 001; :data:`PAPER_PARAMETERS` are the paper's.

    Parameters
    ----------
    step_s : float
        ESO/TD step, s (0.1, the paper's sample period T; the step h of the discrete ESO and TD). Rounded to a
        whole number of IMU samples; a faster IMU's velocities are averaged over each step, a slower one runs at
        its own interval.
    alpha1, alpha2 : float
        fal exponents of the east and north ESO (1: linear).
    delta1, delta2 : float, optional
        fal linear zones, m/s (default 2 h; no effect when alpha = 1).
    beta11, beta12, beta21, beta22 : float
        ESO gains, continuous (1/s, 1/s^2) on the east and north channels. With ``eso_start="ls"`` they
        are the floor the expanding-memory gains fall to; default 2 w0 and w0^2 with w0 = 0.05 rad/s
        (a critically damped observer; see the module docstring for the choice).
    eso_start : {"ls", "rest"}
        "ls" (default): the ESO starts as the least-squares line through the velocity errors so far
        (:func:`expanding_memory_gains`) until those gains fall to beta; "rest": z1 = y, z2 = 0 and the
        fixed gains beta (the paper).
    td : {"ls", "fst"}
        Derivative of eq. 12. "ls" (default): the least-squares slope of eq. 12 integrated
        (:class:`LeastSquaresDifferentiator`), with a memory that grows with the data; "fst": Han's fst
        TD with the fixed filter factor ``td_h1`` (eq. 15, the paper).
    td_h1 : float, optional
        fst TD filter factor, s (default 5 h); refused with td="ls", which has none.
    td_r : float
        fst TD speed factor, 1/s^2 on rad signals (500).
    td_start_s : float or "auto"
        With td="ls": time (s from the fine alignment's first row) at which the fit starts; "auto":
        when the ESO's expanding-memory gains have reached the floor beta (2.45 / w0 = 48.9 s).
    td_min_s : float
        With td="ls": the azimuth is reported (and fed back) once the fit spans this many seconds (10).
    td_memory_s : float, optional
        With td="ls": fading memory of this time constant, s; None (default): growing memory.
    force_h1 : float
        Filter factor (s) of the TD that differentiates the specific force f_n (for s' = (fE / fU)' in
        eq. 12 with td="fst", and f' in the feedback shifts): 5 s.
    feedback_from_s : float, "auto" or None
        Time of the first attitude feedback into the strapdown, s from the fine alignment's first row;
        "auto" (default): ``settle_s`` with td="fst", the ESO's floor time with td="ls" (levels first:
        the azimuth joins once it is reported); None: open loop, as the paper.
    feedback_every_s : float
        Interval of the feedback after the first, s.
    feedback_limit_deg : float
        Runs whose |psi_hat| exceeds this (deg) are not corrected at a feedback instant.
    coarse_s : float
        Without an initial attitude, the inertial-frame coarse alignment runs this long first, s (with the
        aiding valid then, if any: :class:`fusionbench.coarse.InertialCoarseAligner`).
    engine : {"numba", "numpy"}
        The step loop compiled, all runs in one call between feedbacks (:mod:`adrc.moving_base_compiled`; default),
        or the NumPy loop over steps, the reference: the same operations in the same order (equal to rounding).

    Attributes
    ----------
    settle_s : float
        When the estimates are settled, s from the start of the fine alignment: with td="fst",
        max(12 / (slowest ESO pole), 8 force_h1) + 8 h1 (64 s with the paper's parameters); with
        td="ls", ``td_start_s + td_min_s`` (the first azimuth; it keeps improving). Also ``min_duration_s``.
    """

    positive_options = ("step_s", "td_r", "force_h1", "feedback_every_s")

    name = "eso-td"
    uses_aiding = True
    # navigation-grade gyros only: with a tactical IMU its levels end 0.6-0.7 arcmin from the limit (conformance).
    # Aiding (a car with turns, navigation grade, 20'/40' start; tests/test_eso_td_aiding.py): velocity at 10 Hz
    # (1.45 x kf's azimuth rms) or 1 Hz (1.07 x), 1-Hz positions of 0.5 m (1.0 x; levels 0.1-0.2', 0.6' at 2 m),
    # a 60-s outage (2.2 x): claimed; 0.5-Hz velocity (1.9 x) and a 120-s outage (2.6 x) are not. The conformance
    # matrix (20 runs): the drives 1.5-2.7 bounds (threshold 3); an outage from 150 s on the 45-S drive 2.86 (30 s),
    # 2.96 (45 s), 3.04 (60 s): outages claimed up to 30 s
    supports = Supports(bases=("static", "sway", "moving"), max_abs_lat_deg=80.0, max_bias_ratio=0.05,
                        aiding=("velocity", "position"), min_aiding_hz=1.0, max_outage_s=30.0)
    max_latitude_deg = MAX_LATITUDE_DEG  # eq. 12 divides by the horizontal earth rate
    # a given init: 10 deg of yaw recovered, 20 deg left 52-56 arcmin of azimuth (static, 34 N, navigation, 300 s)
    init_capture_deg = 8.0
    description = ("ESO/TD alignment (seed 001): 2nd-order ESO per level velocity channel, the azimuth from "
                   "eq. 12's derivative (least-squares TD); moving base with velocity or position aiding, static or "
                   "swaying without")

    def __init__(self, step_s=0.1, alpha1=1.0, alpha2=1.0, delta1=None, delta2=None, beta11=0.1, beta12=0.0025,
                 beta21=0.1, beta22=0.0025, eso_start="ls", td="ls", td_h1=None, td_r=500.0, td_start_s="auto",
                 td_min_s=10.0, td_memory_s=None, force_h1=5.0, feedback_from_s="auto", feedback_every_s=10.0,
                 feedback_limit_deg=15.0, coarse_s=60.0, imu=None, engine="numba"):
        self.spec, self.engine = None if imu is None else load_spec(imu), check_engine(self.name, engine)
        self.step_s = float(step_s)
        if not self.step_s > 0:
            raise ValueError(f"step_s: expected a positive step in s, found {step_s}")
        self.coarse_s = float(coarse_s)
        self.alpha = (float(alpha1), float(alpha2))
        self._delta = (delta1, delta2)
        self.beta1 = (float(beta11), float(beta21))
        self.beta2 = (float(beta12), float(beta22))
        for name, b in (("beta11", beta11), ("beta12", beta12), ("beta21", beta21), ("beta22", beta22)):
            if not (np.isfinite(b) and b > 0):
                raise ValueError(f"{name}: expected a positive ESO gain, found {b}")
        if eso_start not in ("ls", "rest"):
            raise ValueError(f"eso_start: expected 'ls' or 'rest', found {eso_start!r}")
        if td not in ("ls", "fst"):
            raise ValueError(f"td: expected 'ls' or 'fst', found {td!r}")
        self.eso_start, self.td = eso_start, td
        if td == "ls" and td_h1 is not None:
            raise ValueError(f"td_h1: expected None with the least-squares TD (td='ls', the default; its memory grows "
                             f"with the data), found {td_h1}: pass td='fst' for the printed TD with a filter factor")
        self._td_h1 = td_h1
        self.td_r = float(td_r)
        self.td_min_s = float(td_min_s)
        if not self.td_min_s > 0:
            raise ValueError(f"td_min_s: expected a positive time in s, found {td_min_s}")
        self.td_memory_s = None if td_memory_s is None else float(td_memory_s)
        if self.td_memory_s is not None and not self.td_memory_s > 0:
            raise ValueError(f"td_memory_s: expected a positive time in s or None, found {td_memory_s}")
        self.force_h1 = float(force_h1)
        self.feedback_every_s = float(feedback_every_s)
        if self.feedback_every_s <= 0:
            raise ValueError(f"feedback_every_s: expected a positive interval in s, found {feedback_every_s}")
        self.feedback_limit = float(feedback_limit_deg) * np.pi / 180.0
        # the ESO's floor time: when the expanding-memory gains have fallen to beta (both of them)
        self.eso_floor_s = self._eso_floor_time(self.step_s) if eso_start == "ls" else 0.0
        if isinstance(td_start_s, str):
            if td_start_s != "auto":
                raise ValueError(f"td_start_s: expected a time in s or 'auto', found {td_start_s!r}")
            td_start_s = self.eso_floor_s
        self.td_start_s = float(td_start_s)
        if td == "fst":
            # settling: the ESO's initial error (~g psi) must fall by ~1e-5 before eq. 12 can read its
            # derivative (12 time constants of the slow pole; the specific-force TD settles meanwhile,
            # 8 force_h1), then the TD's transient (8 h1)
            slow = min(_slow_rate(b1, b2) for b1, b2 in zip(self.beta1, self.beta2))
            self.settle_s = float(np.ceil(max(12.0 / slow, 8.0 * self.force_h1) + 8.0 * self.td_h1_for(self.step_s)))
        else:
            self.settle_s = float(np.ceil(self.td_start_s + self.td_min_s))
        if isinstance(feedback_from_s, str):
            if feedback_from_s != "auto":
                raise ValueError(f"feedback_from_s: expected a time in s, 'auto' or None, found {feedback_from_s!r}")
            feedback_from_s = self.settle_s if td == "fst" else max(self.eso_floor_s, self.step_s)
        self.feedback_from_s = None if feedback_from_s is None else float(feedback_from_s)
        self.min_duration_s = self.settle_s

    def _eso_floor_time(self, h):
        k = 1
        while True:
            b1, b2 = expanding_memory_gains(k, h)
            if b1 <= min(self.beta1) and b2 <= min(self.beta2):
                return k * h
            k += 1

    def td_h1_for(self, h):
        """The fst TD filter factor used with step ``h`` (s): ``td_h1`` or 5 h."""
        return 5.0 * h if self._td_h1 is None else float(self._td_h1)

    def deltas_for(self, h):
        """The fal linear zones (east, north) used with step ``h``: ``delta1``, ``delta2`` or 2 h."""
        return tuple(2.0 * h if d is None else float(d) for d in self._delta)

    def events(self, init_given):
        """Stages for the figures (:mod:`fusionbench.figures`): the hand-over from the own inertial-frame coarse
        alignment at ``coarse_s`` (s), when no initial attitude is given."""
        return [] if init_given else [(self.coarse_s, "coarse -> fine hand-over")]

    def _align(self, imu, site: Site, aiding, init) -> AlignmentResult:
        """Align R recordings on a moving base with aiding, or on a static or swaying base
        without one; see the module docstring.

        Parameters
        ----------
        imu : IMUData
            Body RFU increments or rates.
        site : Site
            Position at the initial state.
        aiding : fusionbench.aiding.Aiding, optional
            Velocity or position rows (ENU, m/s; lat, lon, h) of a moving base, read at their times of validity
            (:mod:`adrc.eso_td_rows`); None: a stationary or swaying base (zero velocity).
        init : ndarray, shape (R, 3, 3) or (3, 3), optional
            Initial attitude C_bn within a few degrees (the small-angle model; seed 001 starts from
            20', 20', 40'). None: an inertial-frame coarse alignment over the first ``coarse_s`` seconds
            first (with the aiding when there is one).
        """
        t, dth, dvel = imu.increments()
        R = imu.runs
        if init is None:  # any heading: inertial-frame coarse alignment first (with the aiding, if any)
            coarse = InertialCoarseAligner(history_points=20, caller=self.name)
            # the fine stage after the input policy again, on the rest of the record (its own coarse start needs no
            # check of init)
            return coarse_then_fine(imu, site, aiding, coarse, self.coarse_s,
                                    lambda rest, aid, C0, t_hand: self._align(rest, site,
                                                                              *self.check(rest, site, init=C0,
                                                                                          aiding=aid)))
        dt = imu.dt
        m = max(1, int(round(self.step_s / dt)))
        h = m * dt
        steps = t.size // m

        def blocks(a):  # (steps, R, m, 3), one contiguous block per step
            return np.ascontiguousarray(a[:, :steps * m].reshape(R, steps, m, 3).swapaxes(0, 1))

        dth_b, dv_b = blocks(dth), blocks(dvel)
        try:  # the rows each step reads (None: a stationary or swaying base, at rest at every sample)
            rows = StepRows.build(aiding, t, imu.t0, m, steps, R, dt)
        except ValueError as exc:
            raise ValueError(f"{self.name}: aiding: {exc}") from None
        sd = Strapdown(NavState.broadcast(R, init, v_n=rows.v0, lat=site.lat, lon=site.lon, h=site.h), dt,
                       position_fixed=False, height_fixed=True)
        est = ESOTDEstimator(self, R, h, dt, m, rows)
        records = steps + (t.size > steps * m)  # one more for the samples after the last step (time rule)
        hist_t, hist_C = np.empty(records), np.empty((R, records, 3, 3))
        hist_t[:steps] = t[m - 1:steps * m:m]  # the ends of the steps
        hist_psi, hist_fb, hist_y = (np.empty((R, records, n)) for n in (3, 3, 2))
        if self.engine == "numba":  # the loop below, compiled
            run_compiled(est, sd, dth_b, dv_b, hist_C, hist_psi, hist_fb, hist_y)
        for j in range(steps) if self.engine == "numpy" else ():
            out = sd.run(dth_b[j], dv_b[j], record_every=1)
            st = sd.state
            psi = est.step(j, out["C_bn"], out["v_n"], dth_b[j], dv_b[j], st)
            hist_C[:, j] = apply_misalignment(st.C_bn, -psi)
            hist_y[:, j] = est.y
            est.reset_velocity(st)  # at rows (keeps eq. 1's neglected dv / R terms negligible)
            if est.feedback_due(j):
                psi = est.feedback(j, psi, st)
            hist_psi[:, j] = psi
            hist_fb[:, j] = est.psi_fb
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


#: ``eso-td-paper``: seed 001's printed parameters (ESO 0.6 / 0.08 from rest, fst TD with h1 = 5 h, open loop). On a
#: static base its fixed 0.5-s TD differentiates the earth-rate signal without averaging (5-9 x the bound); with a
#: 0.1 m/s reference on the moving base it turns the noise into thousands of arcmin (the paper001 note).
EsoTdPaper = variant(ESOTDAligner, "EsoTdPaper", "eso-td-paper",
                     "ESO/TD alignment with seed 001's printed parameters (ESO 0.6/0.08, fst TD h1 = 5 h, open loop)",
                     **PAPER_PARAMETERS)
EsoTdPaper.supports = Supports(bases=())  # the printed parameters claim no condition: they reproduce the paper
