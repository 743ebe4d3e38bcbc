"""Does the base move? The check every aligner applies to a record given without aiding.

A stationary, swaying or moored base keeps its place: over any stretch of the record the specific force, carried
with the gyros into the body frame at the stretch's start (``V_b(t) = int C_b^b0 f^b``), equals gravity turning
with the earth (:func:`fusionbench.coarse.gravity_integral_inertial`) seen through one rotation. A vehicle that
drives adds its change of velocity, which no rotation explains. So, per window of :data:`WINDOW_S` seconds
(half-overlapping, covering the record), the rotation is fitted (Wahba's problem, with a common scale for the
accelerometers' scale and vertical bias) and the residual's **horizontal** part (heave and the vertical
accelerometer errors are along gravity) is averaged over blocks of :data:`BLOCK_S` seconds, which a sway's or
moored ship's oscillation averages out but a change of velocity does not. The worst window's RMS of those block
means, m/s, against :func:`threshold_mps`:

=====================================================  ================
record (simulated, 50 Hz, 3 runs)                      worst, m/s
=====================================================  ================
static, navigation grade, 300 s                         0.001
static and mild sway, tactical grade (1 deg/h), 600 s   0.06-0.08
seed 000's Table-1 sway, 0.05 and 0.1 m/s disturbance   0.04, 0.08
the same, tactical grade, 600 s                         0.12-0.13
heave 0.3 m/s rms at 0.05-0.3 Hz, tactical, 600 s       0.09-0.13
a car driving with turns, 300 s                         3.5
a car waiting 60 s, 270 s or 570 s (of 600) first       3.5, 2.3, 2.3
a car waiting 590 s of 600, then 10 s at 0.5 m/s^2      0.33
0.1 g from the start (the excess below catches it)      0.30
a MEMS gyro (10 deg/h), static, 300 s                   0.55-0.64
=====================================================  ================

The threshold is 0.236 m/s for a 120-s window. A gyro whose bias exceeds about 3 deg/h turns the fitted frame
enough to exceed it on a static base too, so the refusal names both causes. A constant acceleration from the first
sample to the last is, to first order, a tilt (the equivalence principle), which no fit of the record alone can
tell from one; it raises the mean specific force above gravity by ``a^2 / 2 g^2``
(:func:`fusionbench.claims.check_not_accelerating`: refused beyond :data:`MAX_GRAVITY_EXCESS`, about 0.08 g). A
base that moves at one constant velocity for the whole record is not detectable from the IMU: give its velocity.
"""

from __future__ import annotations

import numba
import numpy as np

from . import earth
from .claims import check_not_accelerating

#: Length of the windows fitted one by one, s (the whole record when shorter).
WINDOW_S = 120.0
#: Blocks over which the residual is averaged, s (a sway's or a moored ship's oscillation averages out).
BLOCK_S = 20.0
#: Spacing of the samples of the integrated specific force the fit uses, s (at least the sample interval).
SPACING_S = 0.5
#: Residual threshold: MOTION_MPS + MOTION_MPS_PER_S2 * window^2, m/s (the gyros' drift grows with the square of
#: the window), as :class:`fusionbench.coarse.InertialCoarseAligner` uses on a whole record.
MOTION_MPS, MOTION_MPS_PER_S2 = 0.15, 6e-6
#: Largest excess of the mean specific force over gravity, in g, before the base counts as accelerating.
MAX_GRAVITY_EXCESS = 3e-3


def threshold_mps(window_s) -> float:
    """Largest residual (m/s) of a stationary or swaying base over a window of ``window_s`` s."""
    return MOTION_MPS + MOTION_MPS_PER_S2 * float(window_s) ** 2


@numba.njit(cache=True)
def _integrate(dth, dv, keep, out):
    """``out[r, j]`` = the velocity increments of run r up to sample ``keep[j]``, rotated into the body frame at the
    start with the gyros (first-order rotation compensation; no coning or sculling: what the check needs)."""
    R, N = dth.shape[0], dth.shape[1]
    C = np.empty((3, 3))
    T = np.empty((3, 3))
    B = np.empty((3, 3))
    for r in range(R):
        C[:] = 0.0
        C[0, 0] = C[1, 1] = C[2, 2] = 1.0
        V0 = V1 = V2 = 0.0
        j = 0
        for k in range(N):
            a0, a1, a2 = dth[r, k, 0], dth[r, k, 1], dth[r, k, 2]
            u0 = dv[r, k, 0] + 0.5 * (a1 * dv[r, k, 2] - a2 * dv[r, k, 1])
            u1 = dv[r, k, 1] + 0.5 * (a2 * dv[r, k, 0] - a0 * dv[r, k, 2])
            u2 = dv[r, k, 2] + 0.5 * (a0 * dv[r, k, 1] - a1 * dv[r, k, 0])
            V0 += C[0, 0] * u0 + C[0, 1] * u1 + C[0, 2] * u2
            V1 += C[1, 0] * u0 + C[1, 1] * u1 + C[1, 2] * u2
            V2 += C[2, 0] * u0 + C[2, 1] * u1 + C[2, 2] * u2
            x2 = a0 * a0 + a1 * a1 + a2 * a2
            if x2 < 1e-6:
                s = 1.0 - x2 / 6.0 * (1.0 - x2 / 20.0)
                c = 0.5 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0))
            else:
                x = np.sqrt(x2)
                s = np.sin(x) / x
                c = (1.0 - np.cos(x)) / x2
            B[0, 0] = 1.0 - c * (a1 * a1 + a2 * a2)
            B[1, 1] = 1.0 - c * (a0 * a0 + a2 * a2)
            B[2, 2] = 1.0 - c * (a0 * a0 + a1 * a1)
            B[0, 1] = -s * a2 + c * a0 * a1
            B[1, 0] = s * a2 + c * a0 * a1
            B[0, 2] = s * a1 + c * a0 * a2
            B[2, 0] = -s * a1 + c * a0 * a2
            B[1, 2] = -s * a0 + c * a1 * a2
            B[2, 1] = s * a0 + c * a1 * a2
            for i in range(3):
                for m in range(3):
                    T[i, m] = C[i, 0] * B[0, m] + C[i, 1] * B[1, m] + C[i, 2] * B[2, m]
            C[:] = T
            while j < keep.shape[0] and keep[j] == k:
                out[r, j, 0], out[r, j, 1], out[r, j, 2] = V0, V1, V2
                j += 1


def _wahba(a, b):
    """Rotations (R, 3, 3) with ``a ~ C b`` in the least-squares sense, for point sets a, b (R, n, 3) (Kabsch)."""
    H = np.einsum("rni,rnj->rij", a, b)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    return U @ D @ Vt


def window_residual(imu, site, window_s=WINDOW_S, block_s=BLOCK_S):
    """The worst window's horizontal fit residual, block-averaged (module docstring), per recording.

    Parameters
    ----------
    imu : fusionbench.imudata.IMUData
        R recordings, body RFU.
    site : fusionbench.aligner.Site
        Latitude (rad) and height (m): gravity and how it turns with the earth.

    Returns
    -------
    residual : ndarray, shape (R,)
        m/s.
    start : ndarray, shape (R,)
        Where the worst window starts, s after the initial state.
    window : float
        The window's length, s.
    gravity_excess : ndarray, shape (R,)
        The specific force's excess over gravity, in g: ``1 / s - 1`` with s the fits' common scale, averaged over
        the windows (a sway turns the body-frame mean, not this; a constant horizontal acceleration a raises it by
        about a^2 / 2 g^2).
    """
    from .coarse import gravity_integral_inertial

    t, dth, dv = imu.increments()
    R, N, _ = dth.shape
    step = max(1, int(round(SPACING_S / imu.dt)))
    keep = np.unique(np.r_[np.arange(step - 1, N, step), N - 1])
    V = np.zeros((R, keep.size + 1, 3))
    _integrate(np.ascontiguousarray(dth), np.ascontiguousarray(dv), keep, V[:, 1:])
    tk = np.r_[0.0, t[keep] - imu.t0]
    T = tk[-1]
    W = min(float(window_s), T)
    starts = np.arange(0.0, max(T - W, 0.0) + 1e-9, W / 2)
    if starts[-1] < T - W - 1e-9:
        starts = np.r_[starts, T - W]
    g = float(earth.gravity(site.lat, site.h))
    worst, where, excess = np.zeros(R), np.zeros(R), np.zeros(R)
    for s0 in starts:
        sel = np.flatnonzero((tk >= s0 - 1e-9) & (tk <= s0 + W + 1e-9))
        tw = tk[sel] - tk[sel[0]]
        Vi = gravity_integral_inertial(tw, site.lat, g)                   # (n, 3), in the window's start frame
        Vb = V[:, sel] - V[:, sel[:1]]                                     # (R, n, 3)
        C = _wahba(np.broadcast_to(Vi, Vb.shape), Vb)
        a = np.einsum("rij,rnj->rni", C, Vb)
        s = np.sum(a * Vi, axis=(1, 2)) / np.sum(a * a, axis=(1, 2))      # the accelerometers' common scale
        excess += (1.0 / s - 1.0) / starts.size
        res = Vi - s[:, None, None] * a
        up = np.gradient(Vi, tw, axis=0) if tw.size > 2 else np.broadcast_to(Vi[-1], Vi.shape)
        up = up / np.linalg.norm(up, axis=-1, keepdims=True)
        res = res - np.sum(res * up, axis=-1, keepdims=True) * up          # horizontal part
        nb = max(1, int(round(tw[-1] / block_s)))
        blk = np.minimum((tw / (tw[-1] + 1e-12) * nb).astype(int), nb - 1)
        counts = np.bincount(blk, minlength=nb).astype(float)
        means = np.stack([np.stack([np.bincount(blk, res[r, :, i], nb) for i in range(3)], -1)
                          for r in range(R)]) / np.maximum(counts, 1.0)[None, :, None]
        rms = np.sqrt(np.sum(means**2, axis=-1)[:, counts > 0].mean(axis=1))
        worse = rms > worst
        worst[worse], where[worse] = rms[worse], s0
    return worst, where, W, excess


def check_stationary(imu, site, name):
    """Raise ValueError (one line naming ``name``, the recording and the figure, and ``--aiding``) when the record
    shows a base that moves (module docstring); a stationary, swaying or moored base passes."""
    res, start, W, excess = window_residual(imu, site)
    r = int(np.argmax(res))
    thr = threshold_mps(W)
    if res[r] > thr:
        raise ValueError(f"{name}: the base moves (recording {r}: between {start[r]:.0f} and {start[r] + W:.0f} s the "
                         f"specific force departs from gravity's by {res[r]:.2f} m/s of horizontal velocity, a "
                         f"stationary or swaying base by less than {thr:.2f}; or the gyros drift by more than about 3 "
                         f"deg/h): a moving base needs its velocity or position as aiding (--aiding FILE)")
    check_not_accelerating(excess, MAX_GRAVITY_EXCESS, name)
