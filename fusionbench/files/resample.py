"""Jittered IMU time stamps: which steps are jitter and which are defects, and the resampling onto a uniform grid.

Loggers stamp samples with the time they read them (USB transfers, OS scheduling) or with a receiver's clock, so the
steps between stamps vary; KF-GINS and PSINS files carry the actual times for that reason. Every method takes an
:class:`~fusionbench.simulation.imudata.IMUData`, one uniform grid: the readers of :mod:`fusionbench.files.imufiles` and
:mod:`fusionbench.files.layouts` check the times with :func:`timing_defect` and call :func:`uniform_imu`, which reads
the samples at their actual times and puts them on a uniform grid.

Steps
-----
The nominal step ``D`` is the mean of the steps between 0.5 and 1.75 times the median step (stamps quantised to a
large part of the step, e.g. 2 and 3 ms at 400 Hz, average to their step; gaps do not count). A step ``s`` (the
time of row k minus that of row k - 1) is

* a duplicate time (``s = 0``) or a reversal (``s < 0``): refused;
* a gap (``s >= GAP_STEPS D``, 1.5): a sample or more missing (one missing sample makes about ``2 D``): refused;
* too short (``s <= SHORT_STEPS D``, 0.5): an extra sample or a misplaced stamp: refused;
* jitter otherwise. Stamps that scatter by up to a quarter of the step about a steady clock give such steps; a
  clock whose rate wanders slowly does too, whatever its offset from the grid grows to.

Times uniform to :data:`~fusionbench.simulation.imudata.STEP_TOLERANCE` (1e-3 of the step) are kept as they are;
others are resampled.

Scheme
------
Rates (instantaneous at their time ``tau_k``) are integrated over the actual intervals by the trapezoid rule;
increments are kept over their actual intervals ``(tau_{k-1}, tau_k]``, the first starting at ``t_start`` (a
PSINS header's t0; otherwise one mean step before the first time). The cumulative angle ``Theta(t)`` and velocity
``V(t)`` (body frame, summed componentwise) are so known at the actual times; they are interpolated linearly at
the uniform times ``u_j = t_start + j dt``, ``dt = (tau_last - t_start) / M``, and differenced into ``M``
increments over ``(u_{j-1}, u_j]`` (``M = N`` for increments, ``N - 1`` for rates), kind "increment". The grid
starts at ``t_start`` (the first time for rates) and ends on the last time, so the increments sum to the record's
total and the record keeps its span. Each
new increment is the actual intervals' mean rates weighted by their overlaps with its interval: nothing
overshoots, noise is not amplified, and the container's range limits still hold. White noise loses a little of its
variance at the shortest spans (measured: 10 % over one step and 1.5 % over ten at 10 % jitter, 1 % over one step at
1 %), so an Allan deviation of a resampled file reads that much low at its first taus. (Keeping an increment file's
increments and only moving their times onto the grid would compose the same rotations, but leave each sample's
velocity off by ``f (tau_k - u_k)``, 1 cm/s for 1 ms of jitter under gravity, and its attitude by ``w (tau_k - u_k)``;
resampling keeps both at the second-order ``c |df/dt|`` and ``c |dw/dt|`` below.)

Error
-----
For ``u`` in ``[tau_k, tau_{k+1}]`` linear interpolation misses, per component (Taylor, mean value),

    ``Theta_lin(u) - Theta(u) = 1/2 (u - tau_k) (tau_{k+1} - u) dw/dt(xi)``,

so the cumulative angle and velocity are off by at most ``c max|dw/dt|`` and ``c max|df/dt|`` with

    ``c = max_j 1/2 (u_j - tau_k) (tau_{k+1} - u_j) <= 1/2 J (dt + J)``  (and ``<= h^2 / 8`` always),

``J = max_j |tau_j - u_j|`` the jitter of the stamps about the grid (``tau_j`` the j-th interval's actual end, or the
j-th rate sample), ``h`` the longest step: second order in time
(the jitter times the step) and zero without jitter. These errors do not accumulate: each is that of the cumulative
quantity at one grid time, zero at the first and the last; an increment's error ``e_j - e_{j-1}`` telescopes.

Non-commutativity. The angle is resampled componentwise, as if rotations commuted. Moving ``e_j`` of angle between
neighbouring intervals turns the composed attitude (body frame) by ``sum_j e_j x a_j`` to first order (``a_j`` the
increments), and ``e_j = c_j dw/dt`` with ``0 <= c_j <= c``, so the attitude at time ``T`` is off by

    ``dphi(T) = sum_j c_j (dw/dt x w) dt``,  ``|dphi(T)| <= c max|dw/dt| + c int_0^T |w x dw/dt| dt``

to leading order (the first term is the cumulative angle's, zero at the last sample). The second accumulates
(``c_j`` never changes sign). It vanishes when the rotation axis is fixed and is largest for coning: a cone of
half-angle ``alpha`` at ``W`` rad/s has ``|w x dw/dt| = alpha^2 W^3``, a drift of at most ``c alpha^2 W^3`` (a third
to a half of it for random jitter, whose mean ``c_j`` is that part of ``c``). Componentwise resampling stops being
exact enough when that drift nears the gyro bias the alignment resolves. At 100 Hz with ``J`` = 1 ms (10 % of the
step) ``c = 5.5e-6 s^2``: 0.01 deg/h allows ``|w x dw/dt| < 8.8e-3 rad^2/s^3``, i.e. coning of 1 deg up to 0.5 Hz or
0.1 deg up to 2.3 Hz; 0.1 deg of engine vibration at 10 Hz drifts 0.9 deg/h. With ``J`` = 0.1 ms (1 %) ``c`` is 11
times smaller (those frequencies 2.2 times higher). A rate file pays the same drift for its trapezoid rule with
``c = dt^2 / 12`` (8.3e-6 s^2 at 100 Hz), jitter or not, so jitter up to about 15 % of the step adds less than the
rate file's own integration. A higher-order interpolant would cut the coning term only by about ``(W dt)^2``: little
where it matters (fast coning), and nothing is needed where it would gain (slow motion).

The velocity is resampled the same way. Its cross terms with the rotation are of the same form, to leading order at
most ``c int (|w x df/dt| + |dw/dt x f|) dt`` beyond what the attitude error above does to it (zero on a static
base; a sway's ``dw/dt`` changes sign, so its share averages out).
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation.imudata import STEP_TOLERANCE, IMUData, time_defect

__all__ = ["GAP_STEPS", "SHORT_STEPS", "nominal_step", "timing_defect", "intervals", "to_uniform", "uniform_imu"]

#: A step of at least this many nominal steps is a gap (a missing sample makes about 2).
GAP_STEPS = 1.5
#: A step of at most this many nominal steps is too short (an extra sample or a misplaced stamp).
SHORT_STEPS = 0.5


def nominal_step(steps):
    """The nominal step (s) of positive ``steps`` (s): the mean of those between 0.5 and 1.75 times the median."""
    steps = np.asarray(steps, dtype=float)
    med = float(np.median(steps))
    near = steps[(steps >= 0.5 * med) & (steps <= 1.75 * med)]
    return float(near.mean()) if near.size else med


def timing_defect(t, t_start=None):
    """The first defect of the time column ``t`` (N,) s, or None when its steps are all uniform or jitter.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s (the rows' times).
    t_start : float, optional
        Start of the first sample's interval, s, for an increment file that says it; its step is checked too.

    Returns
    -------
    tuple or None
        ``(k, what, detail)``: the row k, the defect (a non-finite value; time not strictly increasing: a duplicate
        or a reversal; a gap in time; a time step too short) and, in ``detail``, what was found and what was
        expected.
    """
    t = np.asarray(t, dtype=float)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        return int(bad[0]), f"non-finite value {t[bad[0]]}", ""
    if t_start is None:  # step i ends at row i + 1
        prev, step, first = t[:-1], np.diff(t), 1
    else:  # step i ends at row i; the first begins at t_start
        prev = np.r_[float(t_start), t[:-1]]
        step, first = t - prev, 0
    if step.size == 0:
        return None

    def after(i):
        return f"after {prev[i]:.10g} s" + (" (the start of the first interval)" if i + first == 0 else "")

    bad = np.flatnonzero(step <= 0)
    if bad.size:
        i = int(bad[0])
        found = "a duplicate time" if step[i] == 0 else "a reversal"
        return i + first, "time not strictly increasing", f"{found}, t={t[i + first]:.10g} s {after(i)}"
    nom = nominal_step(step)
    bad = np.flatnonzero((step >= GAP_STEPS * nom) | (step <= SHORT_STEPS * nom))
    if not bad.size:
        return None
    i = int(bad[0])
    ratio = step[i] / nom
    if ratio >= GAP_STEPS:
        what, hint = "gap in time", f"about {max(round(ratio) - 1, 1)} sample(s) missing"
    else:
        what, hint = "time step too short", "an extra sample or a misplaced time stamp"
    return i + first, what, (f"step {step[i]:.6g} s {after(i)}, {ratio:.3g} times the nominal step {nom:.6g} s: "
                             f"{hint} (expected steps between {SHORT_STEPS:g} and {GAP_STEPS:g} nominal steps, "
                             f"jitter read at the actual times)")


def intervals(t, t_start=None):
    """Each row's interval (s, shape (N,)) where the times are finite and strictly increasing, else their mean step.

    The first row's interval begins at ``t_start``, or one mean step before ``t[0]``. An increment divided by its
    interval is the mean rate the range limits of :mod:`fusionbench.simulation.imudata` apply to.
    """
    t = np.asarray(t, dtype=float)
    mean = (t[-1] - t[0]) / (t.size - 1) if t.size > 1 else np.nan
    mean = mean if np.isfinite(mean) and mean > 0 else 1.0
    step = np.diff(t, prepend=t[0] - mean if t_start is None else t_start) if t.size else t
    return step if step.size and np.all(np.isfinite(step)) and np.all(step > 0) else mean


def to_uniform(t_end, dtheta, dvel, t_start):
    """Increments over actual intervals onto the uniform grid of the same span (scheme and error: module docstring).

    Parameters
    ----------
    t_end : ndarray, shape (M,)
        End of each actual interval, s, strictly increasing; interval k is ``(t_end[k-1], t_end[k]]``.
    dtheta, dvel : ndarray, shape (M, 3)
        Angle (rad) and velocity (m/s) increments over those intervals, body frame.
    t_start : float
        Start of the first interval, s (``< t_end[0]``).

    Returns
    -------
    t : ndarray, shape (M,)
        Uniform interval ends ``t_start + (j + 1) dt``, ``dt = (t_end[-1] - t_start) / M``, s; ``t[-1] = t_end[-1]``.
    dtheta, dvel : ndarray, shape (M, 3)
        Increments over ``(t[j] - dt, t[j]]``, rad and m/s, body frame.
    info : dict
        ``jitter_s`` (J: the largest distance of an actual time from its grid time, s) and ``resampling_c_s2`` (c: the
        largest ``(u - tau_k) (tau_{k+1} - u) / 2``, s^2; the cumulative angle's resampling error is at most
        ``c max|dw/dt|``, its velocity's ``c max|df/dt|``).
    """
    m = t_end.size
    knots = np.r_[0.0, np.asarray(t_end, dtype=float) - t_start]  # relative times keep the precision of the steps
    grid = np.linspace(0.0, knots[-1], m + 1)
    out = []
    for inc in (dtheta, dvel):
        cum = np.vstack([np.zeros((1, 3)), np.cumsum(inc, axis=0)])
        at = np.column_stack([np.interp(grid, knots, cum[:, i]) for i in range(3)])
        out.append(np.diff(at, axis=0))
    k = np.clip(np.searchsorted(knots, grid, side="right") - 1, 0, m - 1)
    c = 0.5 * (grid - knots[k]) * (knots[k + 1] - grid)
    t = t_start + grid[1:]
    t[-1] = t_end[-1]
    info = {"jitter_s": float(np.abs(knots - grid).max()), "resampling_c_s2": float(max(c.max(), 0.0))}
    return t, out[0], out[1], info


def uniform_imu(t, gyro, accel, kind, t_start=None):
    """One recording on a uniform grid: as it is when its times are uniform, else resampled at its actual times.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Actual sample times, s, without defects (:func:`timing_defect` returns None).
    gyro, accel : ndarray, shape (N, 3)
        Body frame: angular rate (rad/s) and specific force (m/s^2) at ``t`` (``kind="rate"``), or angle (rad) and
        velocity (m/s) increments over ``(t[k-1], t[k]]`` (``kind="increment"``).
    kind : {"rate", "increment"}
    t_start : float, optional
        Increments: start of the first interval, s; default one mean step before ``t[0]``.

    Returns
    -------
    imu : IMUData
        One run. Uniform times (to :data:`~fusionbench.simulation.imudata.STEP_TOLERANCE`, ``t_start`` included when
        given): the samples as they are, of their kind. Otherwise kind "increment" on the uniform grid of the same span
        (:func:`to_uniform`): N increments, or N - 1 from rates (the initial state still at ``t[0]``).
    info : dict
        ``resampled`` (bool), ``jitter_s`` (s) and ``resampling_c_s2`` (s^2, 0 when not resampled): the figures of
        the error bound (module docstring).
    """
    t = np.asarray(t, dtype=float)
    n = t.size
    if kind == "increment" and t_start is None:
        t_start = t[0] - (t[-1] - t[0]) / (n - 1)
    uniform = time_defect(t) is None
    if kind == "increment":
        step = (t[-1] - t_start) / n
        uniform = uniform and abs((t[0] - t_start) - step) <= STEP_TOLERANCE * step
    if uniform:
        jitter = float(np.abs(t - np.linspace(t[0], t[-1], n)).max())
        return IMUData(t, gyro[None], accel[None], kind), {"resampled": False, "jitter_s": jitter,
                                                             "resampling_c_s2": 0.0}
    if kind == "rate":
        h = np.diff(t)[:, None]
        t_end, dtheta, dvel = t[1:], 0.5 * h * (gyro[1:] + gyro[:-1]), 0.5 * h * (accel[1:] + accel[:-1])
        t_start = t[0]
    else:
        t_end, dtheta, dvel = t, gyro, accel
    t_out, dtheta, dvel, info = to_uniform(t_end, dtheta, dvel, t_start)
    return IMUData(t_out, dtheta[None], dvel[None], "increment"), {"resampled": True, **info}
