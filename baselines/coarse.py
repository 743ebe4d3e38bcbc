"""Analytic coarse alignment (double-vector / TRIAD) on a stationary base.

From the mean specific force ``f^b`` (m/s^2) and mean angular rate ``w^b`` (rad/s) over the
recording, body frame RFU, build orthonormal triads in both frames::

    u = f / |f|                   (up: a stationary accelerometer measures -g^n = [0, 0, g])
    e = (w x f) / |w x f|         (east: earth rate [0, W cos L, W sin L] crossed with up)
    n = u x e                     (north)

and ``C_bn = [e_b n_b u_b]^T`` (its rows are the east, north and up axes seen in the body frame).
Up is the primary vector, so the tilt comes from the accelerometers alone and the azimuth from the
gyros' horizontal component. With accelerometer bias nabla and gyro bias eps it lands on the
theoretical limits (:func:`fusionbench.metrics.theoretical_limits`); it needs no latitude except
for its checks. On a swaying base the mean rate carries the sway's net rotation over the window
(about amplitude / duration), which can swamp the earth rate: use it on a stationary base, or as
the first stage of a fine aligner.

The result carries a history: the estimate from the data up to each of ``history_points`` times.
"""

from __future__ import annotations

import numpy as np

from scipy.spatial.transform import Rotation

from fusionbench import earth
from fusionbench.aligner import AlignmentResult, Site
from fusionbench.attitude import rotvec_to_dcm
from fusionbench.imudata import IMUData
from fusionbench.strapdown import body_increments


def triad(f_b, w_b):
    """C_bn (..., 3, 3) from mean specific force (m/s^2) and angular rate (rad/s), body frame (..., 3)."""
    f_b = np.asarray(f_b, dtype=float)
    w_b = np.asarray(w_b, dtype=float)
    u = f_b / np.linalg.norm(f_b, axis=-1, keepdims=True)
    e = np.cross(w_b, u)
    e = e / np.linalg.norm(e, axis=-1, keepdims=True)
    n = np.cross(u, e)
    return np.stack([e, n, u], axis=-2)


class CoarseAligner:
    """Analytic coarse alignment (method ``coarse``): TRIAD of the mean specific force and angular rate.

    Parameters
    ----------
    history_points : int
        Number of times at which the growing-window estimate is reported.
    """

    name = "coarse"
    description = "analytic coarse alignment (double-vector/TRIAD of mean specific force and earth rate)"
    min_duration_s = 1.0

    def __init__(self, history_points: int = 200):
        self.history_points = int(history_points)

    def align(self, imu: IMUData, site: Site, vref=None, init=None) -> AlignmentResult:
        """Align every recording of ``imu`` (stationary base); ``vref`` and ``init`` are not used.

        Returns an :class:`AlignmentResult` whose last attitude uses the whole recording.
        """
        t, dth, dv = imu.increments()
        m = min(self.history_points, t.size)
        idx = np.unique(np.linspace(0, t.size - 1, m).round().astype(int))
        span = (idx + 1)[None, :, None] * imu.dt
        w = np.cumsum(dth, axis=1)[:, idx] / span
        f = np.cumsum(dv, axis=1)[:, idx] / span
        return AlignmentResult(self.name, t[idx], triad(f, w))


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


class InertialCoarseAligner:
    """Inertial-frame coarse alignment (method ``coarse-i0``), robust to sway.

    The gyros carry the body frame from its inertially frozen start b0: ``C_b^b0(t)`` (with the
    strapdown's coning compensation); the specific force integrated in b0 gives ``V_b0(t)``
    (with rotation and sculling compensation). On a stationary or moored base the same integral in
    the inertial frame i0 is known in closed form (:func:`gravity_integral_inertial`), and
    ``V_i0(t) = C_b0^i0 V_b0(t)``. ``C_b0^i0`` is the least-squares rotation (Wahba's problem,
    :meth:`scipy.spatial.transform.Rotation.align_vectors`) over ``fit_points`` times in the second
    half of the record. Then ``C_bn(t) = C_i0^n(t) C_b0^i0 C_b^b0(t)`` with
    ``C_n^i0(t) = exp([u x] OMEGA_IE t)``. Sway enters only through bounded velocity terms, so the
    azimuth comes from how gravity turns with the earth (about OMEGA_IE t cos L rad), not from the
    mean gyro rate. Needs the latitude.
    """

    name = "coarse-i0"
    description = "inertial-frame coarse alignment (gravity turning with the earth), robust to sway"
    min_duration_s = 10.0

    def __init__(self, history_points: int = 100, fit_points: int = 50):
        self.history_points = int(history_points)
        self.fit_points = int(fit_points)

    def align(self, imu: IMUData, site: Site, vref=None, init=None) -> AlignmentResult:
        """Align every recording of ``imu`` on a stationary or swaying base; ``vref``/``init`` unused."""
        t, dth, dv = imu.increments()
        R, N, _ = dth.shape
        C_b, dv_b = body_increments(dth, dv, np.zeros((R, 3)), np.zeros((R, 3)))
        C = np.broadcast_to(np.eye(3), (R, 3, 3)).copy()
        V = np.zeros((R, 3))
        keep = np.unique(np.linspace(0, N - 1, max(self.history_points, self.fit_points) * 4).round().astype(int))
        C_keep = np.empty((R, keep.size, 3, 3))
        V_keep = np.empty((R, keep.size, 3))
        j = 0
        for k in range(N):
            V = V + (C @ dv_b[:, k, :, None])[..., 0]
            C = C @ C_b[:, k]
            if j < keep.size and keep[j] == k:
                C_keep[:, j], V_keep[:, j] = C, V
                j += 1
        tk = t[keep] - imu.t0
        V_i0 = gravity_integral_inertial(tk, site.lat, site.g)
        fit = np.unique(np.linspace(keep.size // 2, keep.size - 1, self.fit_points).round().astype(int))
        C_b0_i0 = np.empty((R, 3, 3))
        for r in range(R):
            rot, _ = Rotation.align_vectors(V_i0[fit], V_keep[r, fit])
            C_b0_i0[r] = rot.as_matrix()
        u = np.array([0.0, np.cos(site.lat), np.sin(site.lat)])
        C_n_i0 = rotvec_to_dcm(np.outer(tk, u * earth.OMEGA_IE))
        hist = np.linspace(0, keep.size - 1, self.history_points).round().astype(int)
        hist = np.unique(hist[hist >= fit[0]])
        C_bn = np.swapaxes(C_n_i0[hist], -1, -2)[None] @ C_b0_i0[:, None] @ C_keep[:, hist]
        return AlignmentResult(self.name, t[keep][hist], C_bn)
