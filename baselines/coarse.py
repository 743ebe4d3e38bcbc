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

from fusionbench.aligner import AlignmentResult, Site
from fusionbench.imudata import IMUData


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
