"""The named state of the ESO/TD aligner's compiled loop: the arguments of the numba kernel
:func:`adrc.moving_base_compiled.eso_td_steps`, which :func:`adrc.moving_base_compiled.run_compiled` builds from an
:class:`adrc.eso_td_estimator.ESOTDEstimator` (the rows: :class:`adrc.eso_td_rows_compiled.RowArrays`).

Each group is a :func:`collections.namedtuple` defined here, at module level, so that numba types it by its fields
and caches the kernel (``cache=True``); the kernel reads the fields by name. The arrays are the estimator's own,
stepped in place. R runs; ENU frame, body RFU; the names and equations of ``docs/methods/eso-td.md``.
"""

from collections import namedtuple

Setup = namedtuple("Setup", "td_is_ls eso_start_is_ls td_from td_ready steps_per_row h dt td_r force_h1 q_h1 forget "
                            "gain_table")
Setup.__doc__ = """The loop's constants.

Attributes
----------
td_is_ls, eso_start_is_ls : bool
    ``td="ls"`` (the least-squares TD of eq. 12, else the fst TD), ``eso_start="ls"`` (expanding-memory gains down
    to the floors; else the floors throughout).
td_from, td_ready : int
    td="ls": the first step the fits read, the first step their slope is used (0 with td="fst").
steps_per_row : float
    ``n``, the nominal number of ESO steps from one step with rows to the next: a step with rows applies the gains
    n times over.
h, dt : float
    The ESO step and the IMU's sample interval, s.
td_r, force_h1, q_h1 : float
    The fst TDs' speed factor (1/s^2, per unit of the input) and filter factors (s) of the TD on the specific force
    and of the TD on q (``td_h1``; read with td="fst").
forget : float
    The fits' forgetting factor per step (1.0 with td="fst").
gain_table : ndarray, shape (2, N)
    The expanding-memory gains beta1 (1/s), beta2 (1/s^2) of rows 0 .. N - 1, the last one below the floors;
    empty (2, 0) with eso_start="rest".
"""

LevelESO = namedtuple("LevelESO", "z1 z2 beta1 beta2 beta1_floor beta2_floor alpha delta lin_div")
LevelESO.__doc__ = """The level channels' ESO (eq. 6), :attr:`adrc.eso_td_estimator.ESOTDEstimator.eso`.

Attributes
----------
z1, z2 : ndarray, shape (R, 2)
    The unreset velocity errors [dvE, dvN] (m/s) and their rates (m/s^2).
beta1, beta2 : ndarray, shape (2,)
    The gains per channel (1/s, 1/s^2), written at each step with rows with eso_start="ls".
beta1_floor, beta2_floor : ndarray, shape (2,)
    Their floors (1/s, 1/s^2).
alpha, delta, lin_div : ndarray, shape (2,)
    fal's exponent, its linear zone (m/s) and ``delta ** (1 - alpha)`` per channel.
"""

ForceESO = namedtuple("ForceESO", "z1 z2 beta1 beta2 beta1_floor beta2_floor")
ForceESO.__doc__ = """The copy of the ESO's filter on the specific force (td="ls"; zeros with td="fst"),
:attr:`adrc.eso_td_estimator.ESOTDEstimator.eso_f`: linear (alpha = 1), the level ESO's gains (E, N, N).

Attributes
----------
z1, z2 : ndarray, shape (R, 3)
    ``int f_n dt`` at the rows' times (m/s) and f_n as z2 sees it (m/s^2).
beta1, beta2 : ndarray, shape (3,)
    The gains (1/s, 1/s^2), written with the level ESO's.
beta1_floor, beta2_floor : ndarray, shape (3,)
    Their floors (1/s, 1/s^2).
"""

ESOCopy = namedtuple("ESOCopy", "z1 z2")
ESOCopy.__doc__ = """The states of a linear copy of the ESO's filter with the level ESO's gains (td="ls"; zeros with
td="fst"): :attr:`~adrc.eso_td_estimator.ESOTDEstimator.eso_q` on the unit quadratic ``Q = tau^2 / 2`` (z1 s^2,
z2 s; shape (2,), one per level channel) or :attr:`~adrc.eso_td_estimator.ESOTDEstimator.eso_x` on ``XX_int``
(z1 rad s, z2 the regressor's part rad; shape (R,), the north channel's gains).

Attributes
----------
z1, z2 : ndarray
    The estimate of the input and of its rate.
"""

TD = namedtuple("TD", "x1 x2")
TD.__doc__ = """The states of an fst tracking differentiator (eqs. 14-15):
:attr:`~adrc.eso_td_estimator.ESOTDEstimator.td_f` on the specific force (R, 3; x1 m/s^2, x2 m/s^3) or
:attr:`~adrc.eso_td_estimator.ESOTDEstimator.td_q` on q (R,; x1 rad, x2 rad/s; td="fst", zeros with td="ls").

Attributes
----------
x1, x2 : ndarray
    The tracked input and its rate.
"""

Observers = namedtuple("Observers", "eso eso_f eso_q eso_x td_f td_q")
Observers.__doc__ = """The observers, named as the estimator's attributes.

Attributes
----------
eso : LevelESO
eso_f : ForceESO
eso_q, eso_x : ESOCopy
td_f, td_q : TD
"""

LSFits = namedtuple("LSFits", "S_ls origin_ls S_p origin_p X_int Xb_int M_int XX_int s_jumps X den_a_prev den_b_prev "
                              "m_prev")
LSFits.__doc__ = """td="ls": the least-squares fits and eq. 12 integrated (``docs/methods/eso-td.md``); zeros with
td="fst". The arrays of one column per run are the estimator's attributes of the same names.

Attributes
----------
S_ls, origin_ls : ndarray, shapes (5, R), (2, R)
    The fit of eq. 12 (Y = q - M_int against X; slope -psiU): its weighted sums [1, x, x^2, y, x y] of
    x = X - X0, y = Y - Y0 and its origin (X0, Y0) (rad), set at its first sample
    (:class:`adrc.ls_differentiator.LeastSquaresDifferentiator`, ``td_ls``).
S_p, origin_p : ndarray, shapes (5, R), (2, R)
    The same of the fit of p against the quadratic's time ``eso_q.z2[0]`` (s; slope psiN's drift, rad/s; ``td_p``).
X_int, Xb_int, M_int : ndarray, shape (R,)
    The integrals (trapezoidal, rad) of den0's parts ``W cos L`` and ``den0 - W cos L`` and of the known part of
    eq. 12's right side, ``m = W sin L p - s (W cos L q + L' p)`` (each rad/s).
XX_int : ndarray, shape (R,)
    ``int X_int dt``, rad s: eso_x's input.
s_jumps : ndarray, shape (R,)
    The jumps of s = fE / fU at the feedbacks (X stays continuous).
X : ndarray, shape (R,)
    The fit's regressor, written at each step from the first rows: ``eso_x.z2 + Xb_int + s - s_jumps``.
den_a_prev, den_b_prev, m_prev : ndarray, shape (R,)
    The previous step's integrands of X_int, Xb_int, M_int (rad/s).
"""

EstimatorArrays = namedtuple("EstimatorArrays", "clock times reset_sum psi_fb v_prev F_int P marks now")
EstimatorArrays.__doc__ = """The estimator's running arrays (:class:`adrc.eso_td_estimator.ESOTDEstimator`'s, by
their names there but ``now``).

Attributes
----------
clock : ndarray of int, shape (3,)
    Steps with rows so far, the first step with rows, the last.
times : ndarray, shape (3,)
    The row time offsets of those first and last steps (samples) and the last one's spread (s^2).
reset_sum : ndarray, shape (R, 2)
    The velocity resets so far, m/s.
psi_fb : ndarray, shape (R, 3)
    The attitude corrections fed back so far, rad.
v_prev : ndarray, shape (R, 2)
    The strapdown's level velocity at the step's start, m/s.
F_int : ndarray, shape (R, 3)
    ``int f_n dt`` up to the step's start, m/s.
P, marks : ndarray, shapes (R, 5), (R, n_marks, 8)
    With position intervals: the integrals of the unreset velocity (m) and of ``int f_n dt`` (m) up to the step's
    start; each mark's integrals and lever-arm offset ``C_bn l`` (m).
now : ndarray, shape (R, 12)
    Written at each step, what the feedback reads (``ESOTDEstimator._now``): f_n (3, m/s^2), f_n' (3, m/s^3),
    W (rad/s), sin L, cos L, L' (rad/s), the Coriolis coefficient (rad/s), s = fE / fU.
"""

Histories = namedtuple("Histories", "C_sd psi psi_fb y")
Histories.__doc__ = """What the loop records at each step j (``[r, j]``).

Attributes
----------
C_sd : ndarray, shape (R, steps, 3, 3)
    The strapdown's attitude (body to ENU) at the step's end.
psi : ndarray, shape (R, steps, 3)
    The estimate psi (E, N, U) before any feedback, rad.
psi_fb : ndarray, shape (R, >= steps, 3)
    The corrections fed back so far, rad.
y : ndarray, shape (R, >= steps, 2)
    The unreset level velocity error measured, m/s (NaN without rows).
"""
