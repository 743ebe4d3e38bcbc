"""Geometry of aiding rows in space and time: where a receiver's antenna sits and moves relative to the IMU (the lever
arm, ENU m and m/s), offsets between geodetic positions (ENU, m), and where a row's valid time falls on the IMU
record (the bracketing increment, the gyros' rate there).

Pure functions of arrays, used by :class:`fusionbench.simulation.aiding.Aiding` and by the methods that process its
rows.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import earth


def lever_velocity(C_bn, w_nb_b, lever_arm):
    """Velocity of the antenna relative to the IMU, ``C_bn (omega_nb^b x l)``, ENU m/s.

    Parameters
    ----------
    C_bn : ndarray, shape (..., 3, 3)
        Attitude, body RFU to ENU.
    w_nb_b : ndarray, shape (..., 3)
        Body rate over the navigation frame, body frame, rad/s (``omega_ib^b - C_bn^T omega_in^n``).
    lever_arm : (3,) array_like
        IMU to antenna, body frame, m.
    """
    return np.einsum("...ij,...j->...i", C_bn, np.cross(w_nb_b, np.asarray(lever_arm, dtype=float)))


def lever_offset(C_bn, lever_arm):
    """Position of the antenna relative to the IMU, ``C_bn l``, ENU m (``C_bn`` (..., 3, 3), ``lever_arm`` (3,) m)."""
    return np.einsum("...ij,j->...i", C_bn, np.asarray(lever_arm, dtype=float))


def enu_offset(position, origin):
    """The curvilinear ENU offset (..., 3), m, of ``position`` from ``origin`` (each (..., 3): latitude rad, longitude
    rad, height m): ``(R_N + h0) cos(L_mid) dlon``, ``(R_M + h0) dL``, ``dh`` with the radii at the origin.

    For differences of metres (a filter's position error, a lever arm) it is the local tangent plane's to the square
    of the distance over the earth's radius; kilometres away it is a coordinate on the ellipsoid, which differs from
    the tangent plane at second order (a point 1.6 km due east on the parallel lies d^2 tan L / 2R = 0.2 m north of
    the tangent plane at 45 deg). NaN heights leave the horizontal offset and make the up offset NaN."""
    position, origin = np.asarray(position, dtype=float), np.asarray(origin, dtype=float)
    lat0, h0 = origin[..., 0], origin[..., 2]
    rm, rn = earth.radii(lat0)
    dlon = np.angle(np.exp(1j * (position[..., 1] - origin[..., 1])))  # across the antimeridian too
    lat_mid = 0.5 * (position[..., 0] + lat0)
    r_h = np.nan_to_num(h0)  # a height not measured: the horizontal offset still is (the up offset is NaN)
    return np.stack([dlon * (rn + r_h) * np.cos(lat_mid), (position[..., 0] - lat0) * (rm + r_h),
                     position[..., 2] - h0], axis=-1)


def displace(position, d):
    """``position`` (..., 3) (latitude, longitude rad, height m) moved by the ENU offset ``d`` (..., 3) m: the inverse
    of :func:`enu_offset` to first order in ``d`` over the earth's radius (the radii at ``position``; a NaN height, not
    measured, stays NaN and counts as 0 m in the radii)."""
    position, d = np.asarray(position, dtype=float), np.asarray(d, dtype=float)
    rm, rn = earth.radii(position[..., 0])
    h = np.nan_to_num(position[..., 2])
    return np.stack([position[..., 0] + d[..., 1] / (rm + h),
                     position[..., 1] + d[..., 0] / ((rn + h) * np.cos(position[..., 0])),
                     position[..., 2] + d[..., 2]], axis=-1)


def rate_at(dth, dt, k, w):
    """The gyros' rate (R, n, 3), rad/s, body frame, at the fraction ``w`` (n,) of the increments ``k`` (n,) of
    ``dth`` (R, N, 3) (angle increments, rad, over intervals of ``dt`` s; :func:`bracket` gives ``k``, ``w``): each
    increment's mean rate belongs to its interval's middle, and the rate at a row's time lies on the line through the
    two nearest middles (interpolated, extrapolated by at most half an interval at the array's ends): exact for a rate
    that changes linearly, where the increment's own mean would be half an interval late or early (a turn rate
    changing by 4 deg/s a second puts a 1.5-m lever arm's velocity 0.5 mm/s off at 100 Hz)."""
    N = dth.shape[1]
    k, w = np.asarray(k), np.asarray(w, dtype=float)
    if N == 1:
        return dth[:, k] / dt
    j0 = np.clip(np.where(w >= 0.5, k, k - 1), 0, N - 2)
    f = (k + w - 0.5 - j0)[None, :, None]
    return ((1.0 - f) * dth[:, j0] + f * dth[:, j0 + 1]) / dt


def bracket(t_end, t0, tau):
    """Where times ``tau`` (n,) s fall on an IMU record: the index k (n,) of the first increment ending at or after
    each (0 .. M-1) and the fraction w (n,) of that increment, ``(tau - start) / (end - start)``, with the increment
    k covering ``(t_end[k-1], t_end[k]]`` (the first from ``t0``). A value x[k] known at the increment ends (and
    ``x_start`` at ``t0``) is at ``tau`` about ``(1 - w) x[k-1] + w x[k]``."""
    t_end = np.asarray(t_end, dtype=float)
    tau = np.asarray(tau, dtype=float)
    k = np.clip(np.searchsorted(t_end, tau - 1e-9 * (t_end[-1] - t0) / t_end.size, side="left"), 0, t_end.size - 1)
    start = np.where(k > 0, t_end[np.maximum(k - 1, 0)], t0)
    w = np.clip((tau - start) / (t_end[k] - start), 0.0, 1.0)
    return k, w
