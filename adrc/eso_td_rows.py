"""The aiding as eso-td's ESO reads it: what each ESO step measures, from the rows valid within it.

:class:`adrc.moving_base.ESOTDAligner` steps its ESO every ``h`` seconds (``m`` IMU samples; step j covers the
samples ``j m .. j m + m - 1``, i.e. valid times in ``(t_end[j m - 1], t_end[j m + m - 1]]``). Its measurement of a
step is the mean, over the rows valid in the step (:attr:`fusionbench.simulation.aiding.Aiding.t_valid`), of the
antenna's horizontal velocity error (east, north, m/s):

* **a velocity row**: the strapdown's velocity at the row's time, linear between the two sample ends that bracket
  it (:func:`fusionbench.simulation.aiding_geometry.bracket`), plus the antenna's velocity relative to the IMU
  ``C_bn (omega_nb^b x l)`` (:func:`fusionbench.simulation.aiding_geometry.lever_velocity`; the strapdown's attitude
  at the end of the bracketing sample, the gyros' rate over it less ``C_bn^T omega_in^n``), less the row;
* **a row at rest**: the strapdown's velocity there less the row's velocity (its zero, or a receiver's noisy zero;
  0 where it has none), no lever arm: the IMU itself is at rest;
* **positions only** (no velocity row in the whole aiding): positions differenced over :data:`POSITION_SPAN_S`
  (:func:`fusionbench.simulation.aiding_geometry.enu_offset`; a new span ends at every position row) give the
  antenna's mean velocity over the span, against the strapdown's mean velocity over it (the difference of its integral
  at the two ends, plus the change of the lever-arm offset ``C_bn l``,
  :func:`fusionbench.simulation.aiding_geometry.lever_offset`), counted at the step in which the span's last position
  is valid: no row is read before its time of validity. A mean velocity against a mean velocity has no error from the
  vehicle's jerk (a point velocity at the middle would be off by ``v'' T^2 / 24``: 0.12 m/s over 1 s in which the
  acceleration steps by 1 m/s^2). Why 10 s rather than consecutive rows
  (:meth:`fusionbench.simulation.aiding.Aiding.velocities_from_positions`): the ESO's second-order roll-off passes a
  difference's white noise to the level angles up to the rows' Nyquist rate; on a car with turns, 1-Hz positions of
  0.5 m (2 m) left 0.5' (2') of level error differenced row to row, 0.15' (0.6') over 10 s and 0.1' (0.3') over 20 s,
  the azimuth within 20 %. The price: after an attitude feedback the spans that straddle it are made consistent
  (:meth:`StepRows.turn_marks`) to first order, but 0.4 % of a fed-back azimuth correction remains with 10-s spans
  (1.2 % with 20 s, 0.015 % row to row; measured, not explained).

The velocity errors enter the ESO *unreset* (the velocity resets so far added back, so the series stays continuous
through the resets), and the last row of a step gives the reset (the strapdown's level velocity less that row's
error): resets happen at rows, not at every step. The same rows time the specific force's copy of the ESO: its
input is the integral of ``f_n`` at the rows' times (or its mean over a position interval), as the velocity is.

Steps without rows: every copy of the ESO predicts (``z1 <- z1 + h z2``) and takes no correction, and the
least-squares fits take no sample (a prediction holds no new information). A step with rows corrects with the
gains of the ESO's law times ``n``, the nominal number of steps between rows (:attr:`StepRows.steps_per_row`: 1 at
10 Hz with the default 0.1-s step, 10 at 1 Hz): the same continuous bandwidth whatever the rate (beta1, beta2 are
per second). The expanding-memory gains count rows, not steps, and with ``n`` steps between rows they are the
least-squares line through the rows (:func:`adrc.eso_td_estimator.expanding_memory_gains`). After an outage the
correction is the nominal one: the ESO pulls the prediction's error in over its own time constants. The
estimator's clock (the fit's start, the first feedback) starts at the first step with rows.

Times: a row's time in samples from the record's start is ``u = K + w`` (K its bracketing sample, w the fraction;
``t = t0 + u dt``); :attr:`StepRows.offset` is the mean of a step's rows' u less the step's mean sample end (0 for
the rows at every sample end of the per-increment reference), :attr:`StepRows.tau2` the mean square of their
spread, s^2 (a position interval adds ``T^2 / 12``): the ESO's copy on a unit quadratic is fed exactly that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusionbench.simulation.aiding_geometry import bracket, enu_offset

#: Kinds of measurement: a velocity (or at-rest) row at one time; the mean over a position interval.
POINT, INTERVAL = 0, 1
#: Positions are differenced over this span, s (the nearest whole number of rows, at least one; module docstring).
POSITION_SPAN_S = 10.0


@dataclass
class StepRows:
    """The measurements of each ESO step, built from an :class:`~fusionbench.simulation.aiding.Aiding` (:meth:`build`).

    Measurements are sorted by the step they belong to: those of step j are ``start[j]:start[j + 1]``. Arrays of
    int are int64 (the compiled kernel reads them as they are: :func:`adrc.eso_td_rows_compiled.measure` makes a
    step's measurement from them; its NumPy oracle is ``measure`` in ``tests/oracles/eso_td.py``).

    Attributes
    ----------
    start : ndarray of int, shape (steps + 1,)
    kind : ndarray of int, shape (n,)
        :data:`POINT` or :data:`INTERVAL`.
    k : ndarray of int, shape (n,)
        The sample (0 .. m - 1 within the step) whose interval holds the time (the interval's end for a position
        interval).
    w : ndarray, shape (n,)
        Fraction of that sample's interval at the time, (0, 1].
    lever : ndarray of int, shape (n,)
        1: the point row is the antenna's velocity (add the lever-arm velocity); 0: at rest, or no lever arm.
    value : ndarray, shape (R, n, 2)
        The row's velocity, or the interval's differenced mean velocity, east and north, m/s.
    mark0, mark1 : ndarray of int, shape (n,)
        A position interval's first and last mark (index into the marks), -1 for a point.
    inv_T : ndarray, shape (n,)
        1 / the interval's length, 1/s (0 for a point).
    age : ndarray, shape (n,)
        From a position interval's mean time to its step's end, s (0 for a point): the reset after such a step is
        its error carried to the step's end with the ESO's rate.
    mark_start, mark_k, mark_w, mark_u : ndarray
        The marks (the position rows' times): those of step j are ``mark_start[j]:mark_start[j + 1]``, at sample
        ``mark_k`` (within the step), fraction ``mark_w``; ``mark_u`` their times in samples from the start.
    offset : ndarray, shape (steps,)
        Mean time of each step's rows less the step's mean sample end, in samples (module docstring).
    tau2 : ndarray, shape (steps,)
        Mean square spread of each step's rows' times about their mean, s^2.
    steps_per_row, first_step : int
        The nominal number of ESO steps from one step with rows to the next (their median, at least 1); the first
        step with rows (where the estimator's clock starts: its fit and feedback times count from there).
    v0 : ndarray, shape (R, 3)
        The strapdown's initial velocity: the first two measurements extrapolated back to the record's start (the
        first one alone when there is one), ENU, vertical 0, m/s.
    lever_arm : ndarray, shape (3,)
        IMU to antenna, body RFU, m.
    dt : float
        The IMU's sample interval, s.
    """

    start: np.ndarray
    kind: np.ndarray
    k: np.ndarray
    w: np.ndarray
    lever: np.ndarray
    value: np.ndarray
    mark0: np.ndarray
    mark1: np.ndarray
    inv_T: np.ndarray
    age: np.ndarray
    mark_start: np.ndarray
    mark_k: np.ndarray
    mark_w: np.ndarray
    mark_u: np.ndarray
    offset: np.ndarray
    tau2: np.ndarray
    steps_per_row: int
    first_step: int
    v0: np.ndarray
    lever_arm: np.ndarray
    dt: float

    @classmethod
    def build(cls, aiding, t_end, t0, m, steps, runs, dt):
        """The measurements of ``steps`` ESO steps of ``m`` samples each.

        Parameters
        ----------
        aiding : fusionbench.simulation.aiding.Aiding or None
            Rows for ``runs`` recordings (``Aiding.for_runs``), valid inside the record; None: a stationary or
            swaying base, i.e. rows at rest (zero velocity) at every sample end.
        t_end : ndarray, shape (M,)
            The IMU's increment ends, s.
        t0 : float
            The record's initial state, s.
        m, steps, runs : int
            Samples per step, steps, recordings.
        dt : float
            Sample interval, s.
        """
        R = runs
        if aiding is None:
            t_v, val, lev = t_end[:steps * m], np.zeros((R, steps * m, 2)), np.zeros(steps * m, bool)
            lever_arm, iv = np.zeros(3), None
        else:
            lever_arm = np.asarray(aiding.lever_arm, dtype=float)
            rest = np.zeros(aiding.t.size, bool) if aiding.at_rest is None else aiding.at_rest
            pts = aiding.velocity_rows()
            val = (np.zeros((R, aiding.t.size, 2)) if aiding.velocity is None
                   else np.nan_to_num(aiding.velocity[..., :2], nan=0.0))[:, pts]
            t_v, lev = aiding.t_valid[pts], ~rest[pts] & bool(np.any(lever_arm))
            iv = _position_spans(aiding, R) if not (pts & ~rest).any() and aiding.has_position else None
        K, w = bracket(t_end, t0, t_v)
        keep = K < steps * m  # rows in the samples after the last whole step are not read
        u = (K + w)[keep]
        cols = dict(kind=np.full(u.size, POINT), K=K[keep], w=w[keep], lever=lev[keep], value=val[:, keep],
                    mark0=np.full(u.size, -1), mark1=np.full(u.size, -1), inv_T=np.zeros(u.size), u=u,
                    var=np.zeros(u.size))
        marks = (np.zeros(0, np.int64), np.zeros(0))
        if iv is not None:
            tp, i0, i1, d = iv
            mk, mw = bracket(t_end, t0, tp)
            marks = (mk, mw)
            u0, u1 = mk[i0] + mw[i0], mk[i1] + mw[i1]
            ok = mk[i1] < steps * m
            i0, i1 = i0[ok], i1[ok]
            cols = {name: np.concatenate([col, new], axis=-1 if name != "value" else 1) for (name, col), new in zip(
                cols.items(), (np.full(i1.size, INTERVAL), mk[i1], mw[i1], np.ones(i1.size, bool), d[:, ok], i0, i1,
                               1.0 / (tp[i1] - tp[i0]), ((u0 + u1) / 2)[ok], ((u1 - u0) ** 2 / 12.0)[ok]))}
        order = np.argsort(cols["K"] + cols["w"], kind="stable")
        cols = {name: (col[:, order] if name == "value" else col[order]) for name, col in cols.items()}
        step = cols["K"] // m
        age = np.where(cols["kind"] == INTERVAL, ((step + 1) * m - cols["u"]) * dt, 0.0)
        start = np.searchsorted(step, np.arange(steps + 1), side="left").astype(np.int64)
        if start[-1] == 0:
            raise ValueError(f"expected a row valid within the ESO's steps (up to {steps * m * dt:g} s after the "
                             f"start; positions: two {POSITION_SPAN_S:g} s apart), found none")
        mark_start = np.searchsorted(marks[0] // m, np.arange(steps + 1), side="left").astype(np.int64)
        offset, tau2 = _timing(start, cols["u"], cols["var"], m, dt)
        with_rows = np.flatnonzero(np.diff(start) > 0)
        n = max(1, int(round(float(np.median(np.diff(with_rows)))))) if with_rows.size > 1 else 1
        return cls(start, cols["kind"].astype(np.int64), (cols["K"] - step * m).astype(np.int64), cols["w"],
                   cols["lever"].astype(np.int64), np.ascontiguousarray(cols["value"]),
                   cols["mark0"].astype(np.int64), cols["mark1"].astype(np.int64), cols["inv_T"], age, mark_start,
                   (marks[0] % m).astype(np.int64), marks[1].astype(float), (marks[0] + marks[1]).astype(float),
                   offset, tau2, n, int(with_rows[0]),
                   _initial_velocity(cols["value"], cols["u"]), lever_arm, float(dt))

    def turn_marks(self, j, m, Rd, ramp, P, marks, F_int):
        """At an attitude feedback after step ``j`` (of ``m`` samples): the marks written so far as if the strapdown
        had always carried the corrected attitude (``Rd`` (R, 3, 3)), as the ESO is shifted. The velocity and
        ``int f_n dt`` at each time t since a mark gain ``(Rd - I) (F - F_now) + ramp (t - now)^2 / 2`` (F = int f_n
        dt, ``F_int`` (R, 3) now, m/s; ``ramp`` (R, 3) the change of their rates' slope, m/s^3), whose integrals move
        the mark's (``marks`` (R, n_marks, 8) in place, from ``P`` (R, 5) now); its lever-arm offset turns by ``Rd``."""
        n = self.mark_start[j + 1]
        if n == 0:
            return
        span = ((j + 1) * m - self.mark_u[:n]) * self.dt  # from each mark to now, s
        dF = (P[:, None, 2:5] - marks[:, :n, 2:5]) - F_int[:, None] * span[None, :, None]
        dF = np.einsum("rij,rnj->rni", Rd, dF) - dF + ramp[:, None] * (span**3 / 6.0)[None, :, None]
        marks[:, :n, :2] -= dF[..., :2]
        marks[:, :n, 2:5] -= dF
        marks[:, :n, 5:] = np.einsum("rij,rnj->rni", Rd, marks[:, :n, 5:])


def _position_spans(aiding, runs):
    """Position rows differenced over :data:`POSITION_SPAN_S` (module docstring): the rows' valid times ``tp`` (P,),
    the first and last row of each span (n,), and the antenna's mean velocity over it (runs, n, 2), ENU m/s. Spans
    longer than 1.5 times their nominal length (an outage inside) are left out."""
    rows = np.flatnonzero(aiding.position_rows())
    tp = aiding.t_valid[rows]
    if rows.size < 2:
        return tp, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((runs, 0, 2))
    step = float(np.median(np.diff(tp)))
    n = max(1, int(round(POSITION_SPAN_S / step)))
    i1 = np.arange(n, rows.size)
    i1 = i1[tp[i1] - tp[i1 - n] <= 1.5 * n * step]
    p = aiding.for_runs(runs).position[:, rows]
    d = enu_offset(p[:, i1], p[:, i1 - n])[..., :2] / (tp[i1] - tp[i1 - n])[:, None]
    return tp, i1 - n, i1, d


def _timing(start, u, var, m, dt):
    """Each step's rows' mean time less its mean sample end (samples) and their mean square spread (s^2); steps
    without rows 0. Computed once per pattern of rows within a step."""
    steps = start.size - 1
    offset, tau2, seen = np.zeros(steps), np.zeros(steps), {}
    for j in np.flatnonzero(np.diff(start) > 0):
        uj, vj = u[start[j]:start[j + 1]] - j * m, var[start[j]:start[j + 1]]
        key = (uj.tobytes(), vj.tobytes())
        if key not in seen:
            mean = np.mean(uj)
            seen[key] = (mean - (m + 1) / 2.0, np.mean(((uj - mean) * dt) ** 2 + vj * dt * dt))
        offset[j], tau2[j] = seen[key]
    return offset, tau2


def _initial_velocity(value, u):
    """The first two measurements (R, n, 2) at times ``u`` (samples from the start) extrapolated to u = 0 (the first
    alone when there is one), ENU (R, 3), vertical 0, m/s."""
    v0 = np.zeros(value.shape[:1] + (3,))
    if u.size == 1:
        v0[:, :2] = value[:, 0]
    elif u.size > 1:
        v0[:, :2] = value[:, 0] - (value[:, 1] - value[:, 0]) * (u[0] / (u[1] - u[0]))
    return v0
