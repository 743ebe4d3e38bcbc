"""The inertial-frame coarse alignment on position rows: the fit in its position (double-integral) form.

Differenced positions (:mod:`fusionbench.methods.coarse_aided`'s velocity form) turn a receiver's position noise sigma
into a velocity noise of sigma sqrt(2) / dt per row (0.7 m/s for 0.5 m at 1 Hz), which the fit's blocks average only
down to sigma sqrt(2) / block (0.24 m/s over 3-s blocks: 14 arcmin of azimuth on a car). Integrated once more, the
identity ``V_i0(t) = C_b0^i0 (V_b0(t) - V_b0(tau_0))`` becomes one between displacements, where the positions enter
with their own noise::

    D(t) = int_t0^t V_i0 = C_b0^i0 P_b0(t) + u t + w

with ``P_b0 = int V_b0`` (the pass over the samples integrates it), ``u`` the unknown velocity at the start (no
position row gives it) and ``w`` an unknown constant: both are projected out of the two sides over the position
rows (a constant and a straight line in time), and ``C_b0^i0`` is Wahba's rotation between what remains.
``D`` at the position rows is the rows' displacement resolved in i0 (``int C_n^i0 v = C_n^i0 dp`` over each pair,
exact to the frame's turn over the pair times the velocity's departure from the mean, taken from the rows' and the
IMU bridges' velocities) plus the double integral of ``C_n^i0 (w_ie x v - g)``. Frames and units as in
:mod:`fusionbench.methods.coarse_aided`.
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.coarse_inertial import cumulative_trapezoid
from fusionbench.simulation.aiding_geometry import enu_offset, lever_offset


def displacements(pos, C_bn=None, lever_arm=None):
    """The IMU's displacement between consecutive position rows (R, Kp - 1, 3), ENU m at each pair's start: the
    antenna's (``pos`` (R, Kp, 3): latitude, longitude rad, height m; a height not measured: none) less the lever
    arm's turn ``C_bn l`` (``C_bn`` (R, Kp, 3, 3) at the rows; None: not taken off)."""
    dp = enu_offset(pos[:, 1:], pos[:, :-1])
    dp[..., 2] = np.nan_to_num(dp[..., 2])
    if C_bn is not None:
        off = lever_offset(C_bn, lever_arm)
        dp = dp - (off[:, 1:] - off[:, :-1])
    return dp


def displacement_integral(T, vm, V_i0, C_n, at_pos, dp):
    """``D = int V_i0`` (R, Kp, 3), m in i0, at the position rows from the first, on the grid ``T`` (M,) s.

    Parameters
    ----------
    T : ndarray, shape (M,)
        The grid's times, s: the rows', the bridges' and the position rows'.
    vm : ndarray, shape (R, M, 3)
        Velocity over the earth on the grid, ENU m/s.
    V_i0, C_n : ndarray, shapes (R, M, 3) and (R, M, 3, 3)
        :func:`fusionbench.methods.coarse_inertial.velocity_integral_inertial` of ``vm`` on the grid.
    at_pos : ndarray of int, shape (Kp,)
        Where the position rows are on the grid.
    dp : ndarray, shape (R, Kp - 1, 3)
        The IMU's displacement over each pair of position rows (:func:`displacements`), ENU m.
    """
    Cv = np.einsum("rkij,rkj->rki", C_n, vm)
    H = cumulative_trapezoid(V_i0 - Cv + Cv[:, :1], T)  # int of int C_n^i0 (w_ie x v - g)
    J, K = cumulative_trapezoid(Cv, T), cumulative_trapezoid(vm, T)
    a, b = at_pos[:-1], at_pos[1:]
    m = np.clip(np.searchsorted(T, 0.5 * (T[a] + T[b])), a, b)  # the grid point at (or after) each pair's middle
    # int C_n^i0 v over a pair: the grid's, with its displacement replaced by the rows' (at the pair's middle frame)
    step = J[:, b] - J[:, a] + np.einsum("rkij,rkj->rki", C_n[:, m], dp - (K[:, b] - K[:, a]))
    D = np.concatenate([np.zeros_like(step[:, :1]), np.cumsum(step, axis=1)], axis=1)
    return D + H[:, at_pos] - H[:, at_pos[:1]]


def project_line(X, t):
    """``X`` (R, Kp, 3) less its least-squares constant and straight line in ``t`` (Kp,) s, per run and axis."""
    B, _ = np.linalg.qr(np.column_stack([np.ones_like(t), t - t.mean()]))
    return X - np.einsum("kb,jb,rjc->rkc", B, B, X)
