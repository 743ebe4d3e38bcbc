"""The inertial-frame coarse alignment's relevelling (:class:`fusionbench.methods.coarse.InertialCoarseAligner`): the
level of each attitude from the specific force of the last seconds, where that is better than the fit's.

Arrays as in the aligner: ``C_bn`` (R, H, 3, 3) the history at the kept indices ``hist`` (H,) of the kept samples
``keep``; ``t`` (N,) s the increment ends and ``tk`` (K,) s the kept times since the initial state; ``C_n_i0``
(R, K, 3, 3) navigation to inertial frame, ``C_b0_i0`` (R, 3, 3) the frozen body frame to inertial; ``V_keep`` (R, K,
3) m/s the integrated specific force in the frozen body frame; ``rows`` the aiding's valid times (M,) s and the IMU's
velocity there (R, M, 3), ENU m/s (the lever velocity taken off), or None.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import earth
from fusionbench.simulation.attitude import orthonormalize, skew

#: Sub-windows of the relevelling window whose scatter tells a base's own motion (no reference given).
SUBWINDOWS = 4
#: A correction of the level that many times its noise is a real one (the fit's drift), not the base's motion.
SIGNIFICANT = 3.0
#: Fewest aiding rows in the window for their slope (and its scatter) to be read; fewer: the fit's level stays.
MIN_SLOPE_ROWS = 5


def relevel(C_bn, hist, keep, t, tk, C_n_i0, C_b0_i0, V_keep, rows, site, window_s, noise_max):
    """Level each attitude of the history on the mean specific force of the ``window_s`` seconds before it.

    The fit spreads over the second half of the record, so a gyro bias's drift of the body frame b0 over
    that half tilts the fitted attitude by about half the drift (2.5 arcmin for 1 deg/h over 300 s). The
    specific force of the last seconds, resolved in n with the attitude found, should be the base's
    (gravity, plus the reference's acceleration and Coriolis term on a moving base): a residual
    ``d = [dE, dN]`` is a tilt ``phiE = dN / g``, ``phiN = -dE / g`` (``f x phi`` with f up; with aiding, its
    acceleration is the least-squares slope of the rows valid over the window, so their noise averages out),
    removed with ``C <- (I + [phi x]) C`` (per recording, unless the rows' slope is too noisy to tell the level to
    ``noise_max`` rad, or there are fewer than :data:`MIN_SLOPE_ROWS` of them (an outage; a turn's velocity is no
    straight line either, and its scatter says so): then the fit's level stays). The azimuth is kept; on an
    accelerating base its error couples into the level by f_h / g, as it does for any method.
    """
    g = site.g

    def mean_force(j0, j):
        """Mean specific force (R, 3) m/s^2 in n between kept times j0 and j."""
        dt_w = tk[j] - tk[j0]
        f_i0 = np.einsum("rab,rb->ra", C_b0_i0, V_keep[:, j] - V_keep[:, j0]) / dt_w
        # the navigation frame turns by OMEGA_IE dt_w over the window: resolve with its mean over the window
        # (trapezoid over the kept times; exact to second order in OMEGA_IE dt_w)
        w = np.diff(tk[j0:j + 1])
        C_mean = (np.einsum("k,rkab->rab", w, C_n_i0[:, j0:j]) + np.einsum("k,rkab->rab", w, C_n_i0[:, j0 + 1:j + 1]))
        return np.einsum("rba,rb->ra", C_mean / (2 * dt_w), f_i0)

    for i, j in enumerate(hist):
        j0 = int(np.searchsorted(tk, tk[j] - window_s))
        if j0 >= j:
            continue
        f_n = mean_force(j0, j)
        expect = np.broadcast_to(-earth.gravity_n(site.lat, site.h), f_n.shape).copy()
        use = np.ones(len(f_n), bool)
        parts = np.linspace(j0, j, SUBWINDOWS + 1).round().astype(int)
        if rows is None and np.all(np.diff(parts) > 0):
            # no reference: a base that moves a little (a moored ship's heave and surge) shows as a scatter of
            # the force between sub-windows (the window's mean has it over sqrt(SUBWINDOWS) as its noise); the
            # correction is made where that noise is small or the correction stands out of it (three times:
            # a gyro bias's drift of the fit), else the fit's level stays
            f_sub = np.stack([mean_force(a, b) for a, b in zip(parts[:-1], parts[1:])])  # (S, R, 3)
            noise = np.std(f_sub[..., :2], axis=0, ddof=1).max(axis=-1) / np.sqrt(SUBWINDOWS)
            shift = np.abs(f_n[:, :2] - expect[:, :2]).max(axis=-1)
            use = (noise / g < noise_max) | (shift > SIGNIFICANT * noise)
        if rows is not None:  # the rows' acceleration: the least-squares slope of their velocities (noise averages)
            t_rows, v_rows = rows
            seg = (t_rows >= t[keep[j0]]) & (t_rows <= t[keep[j]])
            if seg.sum() < MIN_SLOPE_ROWS:
                continue
            tau = t_rows[seg] - t_rows[seg].mean()
            v = v_rows[:, seg]
            v_mean = v.mean(axis=1)
            accel = np.einsum("k,rkc->rc", tau, v - v_mean[:, None]) / np.sum(tau * tau)
            # the Coriolis term at the window's middle (sparse rows' mean time may be off it by half an interval)
            v_mid = v_mean + accel * (0.5 * (t[keep[j0]] + t[keep[j]]) - t_rows[seg].mean())
            w_cor = 2 * earth.earth_rate_n(site.lat) + earth.transport_rate_n(v_mid, site.lat, site.h)
            expect = accel + np.cross(w_cor, v_mid) - earth.gravity_n(site.lat, site.h)
            # the slope's own noise, from the rows' scatter about it: noisy or sparse rows would tilt the level
            # more than the fit does, so those recordings keep the fit's level
            scatter = v[..., :2] - v_mean[:, None, :2] - tau[None, :, None] * accel[:, None, :2]
            slope_sigma = np.sqrt(np.mean(scatter**2, axis=1) / np.sum(tau * tau))
            use = slope_sigma.max(axis=1) / g < noise_max
        d = np.where(use[:, None], f_n - expect, 0.0)
        phi = np.stack([d[:, 1] / g, -d[:, 0] / g, np.zeros(len(d))], axis=-1)
        C_bn[:, i] = (np.eye(3) + skew(phi)) @ C_bn[:, i]
    return orthonormalize(C_bn)
