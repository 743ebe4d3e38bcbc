"""The measurement of an ESO step from its rows (:mod:`adrc.eso_td_rows`), compiled, for one run, for
:func:`adrc.moving_base_compiled.eso_td_steps`. Its NumPy oracle is ``measure`` in ``tests/oracles/eso_td.py``, over
the runs, operation for operation (the sums of three products in the lever-arm terms excepted: NumPy's einsum orders
them its own way). Frames and units as there: ENU, body RFU, m/s."""

from __future__ import annotations

from collections import namedtuple

import numba
import numpy as np

#: The kinds of measurement (:data:`adrc.eso_td_rows.POINT`, ``INTERVAL``).
_POINT = 0


RowArrays = namedtuple("RowArrays", "start kind k w lever value mark0 mark1 inv_T mark_start mark_k mark_w lever_arm "
                                    "age offset tau2")
RowArrays.__doc__ = """The arrays of an :class:`adrc.eso_td_rows.StepRows` that the compiled loop reads, by their
names there (:func:`row_arrays`). n rows, ``steps`` ESO steps; int arrays are int64.

Attributes
----------
start : ndarray of int, shape (steps + 1,)
    The rows of step j are ``start[j]:start[j + 1]``.
kind : ndarray of int, shape (n,)
    :data:`adrc.eso_td_rows.POINT` (a velocity at a time) or ``INTERVAL`` (a position span's mean velocity).
k, w : ndarray, shape (n,)
    The sample within the step (int, 0 .. m - 1) whose interval holds the row's time, and the fraction of that
    interval there, (0, 1].
lever : ndarray of int, shape (n,)
    1: a point row is the antenna's velocity (the lever-arm velocity is added); 0: at rest, or no lever arm.
value : ndarray, shape (R, n, 2)
    The row's velocity, east and north, m/s.
mark0, mark1 : ndarray of int, shape (n,)
    A position interval's first and last mark, -1 for a point.
inv_T : ndarray, shape (n,)
    1 / the interval's length, 1/s (0 for a point).
mark_start, mark_k, mark_w : ndarray, shapes (steps + 1,), (n_marks,), (n_marks,)
    The marks of step j are ``mark_start[j]:mark_start[j + 1]``, at sample ``mark_k`` (int) within the step,
    fraction ``mark_w``.
lever_arm : ndarray, shape (3,)
    IMU to antenna, body RFU, m.
age : ndarray, shape (n,)
    From a position interval's mean time to its step's end, s (0 for a point).
offset, tau2 : ndarray, shape (steps,)
    Mean time of each step's rows less the step's mean sample end (samples); mean square spread of their times
    about their mean (s^2).
"""


def row_arrays(rows):
    """The arrays of a :class:`adrc.eso_td_rows.StepRows` that the compiled loop reads, as a :class:`RowArrays`."""
    return RowArrays(rows.start, rows.kind, rows.k, rows.w, rows.lever, rows.value, rows.mark0, rows.mark1, rows.inv_T,
                     rows.mark_start, rows.mark_k, rows.mark_w, rows.lever_arm, rows.age, rows.offset, rows.tau2)


@numba.njit(cache=True)
def _lever_velocity(C, w_ib, w_in, lever_arm, out):
    """``C (omega_nb^b x l)`` (:func:`fusionbench.simulation.aiding_geometry.lever_velocity`) into ``out`` (3,), m/s,
    with ``omega_nb^b = w_ib - C^T w_in`` (rad/s; ``C`` (3, 3) body to ENU, ``w_in`` ENU)."""
    w0 = w_ib[0] - (C[0, 0] * w_in[0] + C[1, 0] * w_in[1] + C[2, 0] * w_in[2])
    w1 = w_ib[1] - (C[0, 1] * w_in[0] + C[1, 1] * w_in[1] + C[2, 1] * w_in[2])
    w2 = w_ib[2] - (C[0, 2] * w_in[0] + C[1, 2] * w_in[1] + C[2, 2] * w_in[2])
    c0 = w1 * lever_arm[2] - w2 * lever_arm[1]
    c1 = w2 * lever_arm[0] - w0 * lever_arm[2]
    c2 = w0 * lever_arm[1] - w1 * lever_arm[0]
    for i in range(3):
        out[i] = C[i, 0] * c0 + C[i, 1] * c1 + C[i, 2] * c2


@numba.njit(cache=True)
def _rate_at(dth, r, k, w, dt, out):
    """:func:`fusionbench.simulation.aiding_geometry.rate_at` for one row of run r: the gyros' rate (rad/s) at the
    fraction w of increment k of ``dth`` (R, m, 3), on the line through the two nearest increments' middles."""
    m = dth.shape[1]
    if m == 1:
        for c in range(3):
            out[c] = dth[r, k, c] / dt
        return
    j0 = k if w >= 0.5 else k - 1
    j0 = min(max(j0, 0), m - 2)
    f = k + w - 0.5 - j0
    for c in range(3):
        out[c] = ((1.0 - f) * dth[r, j0, c] + f * dth[r, j0 + 1, c]) / dt


@numba.njit(cache=True)
def measure(r, j, rw, out_C, out_v, dth, cs, v_prev, reset_sum, F_int, P, marks, w_in, dt, y, Fbar, e_last):
    """Step ``j``'s measurement for run ``r``; False without rows in the step.

    Parameters
    ----------
    rw : RowArrays
        The rows (:func:`row_arrays`).
    out_C, out_v : ndarray, shapes (R, m, 3, 3), (R, m, 3)
        The strapdown's attitude and velocity after each of the step's samples.
    dth : ndarray, shape (R, m, 3)
        The step's angle increments, body, rad.
    cs : ndarray, shape (m + 1, 3)
        ``int f_n dt`` from the step's start to each sample end (``cs[0]`` = 0), run ``r``, m/s.
    v_prev : ndarray, shape (R, 2)
        The strapdown's level velocity at the step's start (after the last reset), m/s.
    reset_sum, F_int : ndarray, shapes (R, 2), (R, 3)
        The velocity resets so far (m/s) and ``int f_n dt`` up to the step's start (m/s).
    P, marks : ndarray, shapes (R, 5), (R, n_marks, 8)
        With position intervals: the integrals of the unreset velocity (m) and of ``int f_n dt`` (m) up to the
        step's start, advanced to its end here (run ``r``); each mark's integrals and lever-arm offset ``C_bn l``
        (m), written here when it falls in the step.
    w_in : ndarray, shape (3,)
        omega_in^n of run ``r``, rad/s (earth rate and transport rate, ENU).
    y, Fbar, e_last : ndarray, shapes (2,), (3,), (2,)
        Written: the unreset level velocity error, ``int f_n dt`` at the rows' times, the last row's error.
    """
    start, kind, kk, ww, lever, value = rw.start, rw.kind, rw.k, rw.w, rw.lever, rw.value
    mark0, mark1, inv_T, lever_arm = rw.mark0, rw.mark1, rw.inv_T, rw.lever_arm
    mark_start, mark_k, mark_w = rw.mark_start, rw.mark_k, rw.mark_w
    m = out_v.shape[1]
    I0, I1, cum, lv, e, F = np.empty(5), np.empty(5), np.zeros(5), np.empty(3), np.empty(2), np.empty(3)
    rt = np.empty(3)
    if mark_k.shape[0] > 0:  # the integrals of the unreset velocity and of int f_n dt, at the marks and the end
        ia, b = mark_start[j], mark_start[j + 1]
        for k in range(m):
            for c in range(2):
                I0[c] = (v_prev[r, c] if k == 0 else out_v[r, k - 1, c]) + reset_sum[r, c]
                I1[c] = out_v[r, k, c] + reset_sum[r, c]
            for i in range(3):
                I0[2 + i], I1[2 + i] = cs[k, i] + F_int[r, i], cs[k + 1, i] + F_int[r, i]
            while ia < b and mark_k[ia] == k:
                w = mark_w[ia]
                for c in range(5):
                    marks[r, ia, c] = (P[r, c] + cum[c]) + w * dt * ((1.0 - w / 2.0) * I0[c] + w / 2.0 * I1[c])
                for i in range(3):
                    marks[r, ia, 5 + i] = (out_C[r, k, i, 0] * lever_arm[0] + out_C[r, k, i, 1] * lever_arm[1]
                                           + out_C[r, k, i, 2] * lever_arm[2])
                ia += 1
            for c in range(5):
                cum[c] += 0.5 * dt * (I0[c] + I1[c])
        for c in range(5):
            P[r, c] = P[r, c] + cum[c]
    i0, i1 = start[j], start[j + 1]
    if i1 == i0:
        return False
    sy, sF = np.zeros(2), np.zeros(3)
    for i in range(i0, i1):
        if kind[i] == _POINT:
            k, w = kk[i], ww[i]
            for c in range(2):
                e[c] = (1.0 - w) * (v_prev[r, c] if k == 0 else out_v[r, k - 1, c]) + w * out_v[r, k, c]
            if lever[i] == 1:
                _rate_at(dth, r, k, w, dt, rt)
                _lever_velocity(out_C[r, k], rt, w_in, lever_arm, lv)
                for c in range(2):
                    e[c] = e[c] + lv[c]
            for c in range(2):
                e[c] = e[c] - value[r, i, c]
            for c in range(3):
                F[c] = (1.0 - w) * cs[k, c] + w * cs[k + 1, c]
        else:  # the mean over a position interval: the integrals' difference over its length
            a, b = mark0[i], mark1[i]
            for c in range(2):
                e[c] = (((marks[r, b, c] - marks[r, a, c]) * inv_T[i] + (marks[r, b, 5 + c] - marks[r, a, 5 + c])
                         * inv_T[i]) - value[r, i, c]) - reset_sum[r, c]
            for c in range(3):
                F[c] = (marks[r, b, 2 + c] - marks[r, a, 2 + c]) * inv_T[i] - F_int[r, c]
        for c in range(2):
            sy[c] = e[c] if i == i0 else sy[c] + e[c]
        for c in range(3):
            sF[c] = F[c] if i == i0 else sF[c] + F[c]
    for c in range(2):
        y[c], e_last[c] = sy[c] / (i1 - i0) + reset_sum[r, c], e[c]
    for c in range(3):
        Fbar[c] = F_int[r, c] + sF[c] / (i1 - i0)
    return True
