"""The inertial-frame coarse alignment's integrals: the stationary specific force in the inertial frame i0, and on a
moving base the local ENU frame in the inertial frame i0 (the earth's rotation and the vehicle's transport over it),
the vehicle's track from its velocity, and the velocity integral of the specific force in i0 from a velocity
reference (:class:`fusionbench.methods.coarse.InertialCoarseAligner` with aiding,
:mod:`fusionbench.methods.coarse_aided`).

Frames: i0 is the ENU frame at the instant ``t_start`` frozen in inertial space; n the local ENU frame; SI units
(rad, m, s, m/s).
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import earth


def gravity_integral_inertial(t, lat, g):
    """Velocity integral of the stationary specific force in the inertial frame i0.

    i0 is the ENU frame at ``t = 0`` frozen in inertial space; the site turns about the earth axis
    ``u = [0, cos L, sin L]`` (in i0) at ``W = OMEGA_IE``, so the specific force
    ``[0, 0, g]`` of a stationary IMU is ``exp([u x] W tau) [0, 0, g]`` in i0 and its integral is::

        V(t) = t f + (1 - cos W t) / W [u x] f + (t - sin(W t) / W) [u x]^2 f

    Parameters
    ----------
    t : array_like, shape (M,)
        Times since the start, s.
    lat : float
        Latitude, rad.
    g : float
        Gravity, m/s^2.

    Returns
    -------
    ndarray, shape (M, 3)
        V(t) in i0, m/s.
    """
    W = earth.OMEGA_IE
    u = np.array([0.0, np.cos(lat), np.sin(lat)])
    K = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    f = np.array([0.0, 0.0, g])
    t = np.asarray(t, dtype=float)[:, None]
    return t * f + (1 - np.cos(W * t)) / W * (K @ f) + (t - np.sin(W * t) / W) * (K @ K @ f)


def _c_ne(lat, dlon):
    """C_n^e (..., 3, 3): the ENU axes (columns E, N, U) in an earth-fixed frame whose x axis is the
    start meridian, at latitude ``lat`` and longitude ``dlon`` from that meridian (rad)."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(dlon), np.cos(dlon)
    z = np.zeros_like(sl)
    return np.stack([np.stack([-so, -sl * co, cl * co], -1),
                     np.stack([co, -sl * so, cl * so], -1),
                     np.stack([z, cl, sl], -1)], -2)


def c_n_i0(tau, lat0, lat, dlon):
    """The local ENU frame in i0, ``C_n^i0`` (R, K, 3, 3).

    Parameters
    ----------
    tau : ndarray, shape (K,)
        Time since the instant of i0, s.
    lat0 : float
        Latitude of i0's ENU frame, rad.
    lat, dlon : ndarray, shape (R, K)
        Latitude and longitude from i0's meridian of the local frame, rad.
    """
    wt = earth.OMEGA_IE * np.asarray(tau, dtype=float)
    c, s = np.cos(wt), np.sin(wt)
    Rz = np.zeros((wt.size, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    C0T = np.swapaxes(_c_ne(np.asarray(lat0, dtype=float), np.asarray(0.0)), -1, -2)
    return C0T @ Rz[None] @ _c_ne(lat, dlon)


def integrate_track(t, t_start, v, lat, h):
    """Position at times ``t`` (N,) s from (``lat`` rad, longitude 0, ``h`` m) at ``t_start``, the velocity ``v``
    (R, N, 3), ENU m/s, integrated by the trapezoid rule (before ``t[0]`` at ``v[:, 0]``).

    Returns
    -------
    lat, dlon, h : ndarray, shape (R, N)
        Latitude (rad), longitude from the start (rad), height (m).
    """
    R, N, _ = v.shape
    dtau = np.diff(np.concatenate([[0.0], np.asarray(t, dtype=float) - t_start]))
    v_prev = np.concatenate([v[:, :1], v[:, :-1]], axis=1)
    v_mid = 0.5 * (v + v_prev)
    h_k = float(h) + np.cumsum(v_mid[..., 2] * dtau, axis=1)
    lat_k = np.full((R, N), float(lat))
    for _ in range(2):  # the radii depend weakly on the latitude: two passes are exact to 1e-12
        rm, rn = earth.radii(lat_k)
        lat_k = lat + np.cumsum(v_mid[..., 1] / (rm + h_k) * dtau, axis=1)
    rm, rn = earth.radii(lat_k)
    dlon = np.cumsum(v_mid[..., 0] / ((rn + h_k) * np.cos(lat_k)) * dtau, axis=1)
    return lat_k, dlon, h_k


def velocity_integral_inertial(t, t_start, vref, lat, h, track=None, chunk=20000):
    """Velocity integral of the specific force in the inertial frame i0 from a velocity reference.

    i0 is the ENU frame at ``t_start`` frozen in inertial space. With ``C_n^i0(t)`` the attitude of the
    local ENU frame at the vehicle's position (the earth's rotation and the vehicle's transport over the
    earth), the velocity equation ``v' = C_bn f^b - (2 w_ie + w_en) x v + g^n`` gives, since
    ``d/dt (C_n^i0 v) = C_n^i0 (v' + w_in x v)`` with ``w_in = w_ie + w_en`` (the transport rate cancels with its
    share of the Coriolis term)::

        V_i0(t) = int_t0^t C_n^i0 C_bn f^b = C_n^i0(t) v(t) - C_n^i0(t0) v(t0) + int_t0^t C_n^i0 (w_ie x v - g^n)

    from the first time ``t0 = t[0]`` on. The integral is the trapezoid rule on the samples (the reference
    interpolated linearly between them).

    Neglected: the trapezoid rule's error on ``C_n^i0 (w_ie x v - g^n)`` (dt^2 / 12 times its second
    derivative, g W^2 dt^2 t / 12 for the turning gravity: below 1e-6 m/s over an hour at 100 Hz, 1e-4 at 1 Hz;
    for the Coriolis term W times the error of the interpolated velocity's integral, a few centimetres per
    second-long interval in a turn); the deflection of the vertical and gravity anomalies (the normal gravity of
    :func:`fusionbench.simulation.earth.gravity`), as on a stationary base. The reference's errors pass as they are:
    its noise at ``t`` and ``t0`` directly (the aligner averages both sides of the fit over blocks), its integrated
    noise in the Coriolis term as W sigma sqrt(t dt) (1e-5 m/s for 0.1 m/s over 300 s at 10 Hz) and in the position as
    sigma sqrt(t dt) (0.5 m: 1e-7 rad of frame transport).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times of the reference, s, increasing.
    t_start : float
        The instant of i0, s.
    vref : ndarray, shape (R, N, 3)
        Reference velocity over the earth, ENU, m/s, at ``t``.
    lat, h : float
        Latitude (rad) and height (m) at ``t_start``.
    track : tuple of ndarray, optional
        Latitude (rad), longitude from a fixed meridian (rad) and height (m), each (R, N), at ``t``, when already
        computed; None: :func:`integrate_track` of ``vref``.

    Returns
    -------
    V : ndarray, shape (R, N, 3)
        ``V_i0(t[k]) - V_i0(t[0])`` in i0, m/s.
    C_n_i0 : ndarray, shape (R, N, 3, 3)
        The local ENU frame at each ``t[k]`` in i0.
    """
    R, N, _ = vref.shape
    lat_k, dlon, h_k = integrate_track(t, t_start, vref, lat, h) if track is None else track
    tau = np.asarray(t, dtype=float) - t_start
    C_n_i0 = np.empty((R, N, 3, 3))
    F = np.empty((R, N, 3))
    for a in range(0, N, chunk):
        b = min(N, a + chunk)
        C = c_n_i0(tau[a:b], lat, lat_k[:, a:b], dlon[:, a:b])
        C_n_i0[:, a:b] = C
        f = np.cross(earth.earth_rate_n(lat_k[:, a:b]), vref[:, a:b]) - earth.gravity_n(lat_k[:, a:b], h_k[:, a:b])
        F[:, a:b] = np.einsum("rkij,rkj->rki", C, f)
    Cv = np.einsum("rkij,rkj->rki", C_n_i0, vref)
    return Cv - Cv[:, :1] + cumulative_trapezoid(F, t), C_n_i0


def cumulative_trapezoid(X, t):
    """The integral of ``X`` (R, N, ...) over times ``t`` (N,) s from ``t[0]`` by the trapezoid rule, (R, N, ...)."""
    dt = np.diff(np.asarray(t, dtype=float)).reshape((1, -1) + (1,) * (X.ndim - 2))
    return np.concatenate([np.zeros_like(X[:, :1]), np.cumsum(0.5 * (X[:, 1:] + X[:, :-1]) * dt, axis=1)], axis=1)
