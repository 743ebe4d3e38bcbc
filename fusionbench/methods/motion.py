"""Does the base move? The check every aligner applies to a record given without aiding.

A stationary, swaying or moored base keeps its place: over any stretch of the record the specific force, carried
with the gyros into the body frame at the stretch's start (``V_b(t) = int C_b^b0 f^b``), equals gravity turning
with the earth (:func:`fusionbench.methods.coarse_inertial.gravity_integral_inertial`) seen through one rotation. A
vehicle that drives adds its change of velocity, which no rotation explains. So, per window (half-overlapping,
covering the record), the rotation is fitted (Wahba's problem, with a common scale for the accelerometers' scale and
vertical bias) and the residual's **horizontal** part (heave and the vertical accelerometer errors are along gravity) is
averaged over blocks of a sixth of the window, which a sway's or moored ship's oscillation averages out but a
change of velocity does not. The worst window's RMS of those block means, m/s, is held to
:func:`threshold_mps` (0.15 m/s plus the gyros' drift, which grows with the square of the window), on three
scales (:func:`scales`): 60-s windows see a brief change of velocity, 120-s windows and the whole record a steady
acceleration, which a short window takes for a tilt. Worst residual over its threshold, per scale (seed 000: Zhou
2011, the ADRC gyrocompass, whose Table 1 gives the sway):

==================================================  ======  ======  ============
record (simulated, 50 Hz, 3 runs)                   60 s    120 s   whole record
==================================================  ======  ======  ============
static, navigation grade, 300 s                     0.00    0.00    0.00
static or mild sway, tactical grade, 600 s          0.15    0.35    0.46
seed 000's Table-1 sway, 0.05 m/s disturbance       0.27    0.18    0.04
the same, 0.1 m/s, tactical grade, 600 s            0.63    0.58    0.47
heave 0.3 m/s rms at 0.05-0.3 Hz, tactical, 600 s   0.64    0.54    0.47
a car driving with turns, 300 s                     23      15      3.6
a car waiting 60 s of 300, 570 s of 600             23, 15  15, 11  2.5, 0.21
a car waiting 590 s of 600, then driving 10 s       2.7     0.85    0.02
0.1 g from the start, 300 s                         0.50    1.28    1.63
a MEMS gyro (10 deg/h), static, 300 s               1.01    2.74    4.47
==================================================  ======  ======  ============

A gyro whose bias exceeds about 3 deg/h turns the fitted frame enough to exceed the threshold on a static base
too, so the refusal names both causes. A constant acceleration over a short record is, to first order, a tilt
(the equivalence principle), which no fit of the record alone tells from one; it raises the specific force above
gravity by ``a^2 / 2 g^2``, less the Eotvos effect of the speed it builds (the whole record's fitted scale:
:func:`fusionbench.methods.claims.check_not_accelerating` refuses beyond :data:`MAX_GRAVITY_EXCESS`; 0.1 g over 60 s:
4.8 mg). A base that moves at one constant velocity for the whole record is not detectable from the IMU: give its
velocity.
"""

from __future__ import annotations

import numba
import numpy as np

from fusionbench.methods.claims import check_not_accelerating
from fusionbench.methods.coarse_inertial import gravity_integral_inertial
from fusionbench.simulation import earth
from fusionbench.simulation.strapdown_compiled import _rodrigues3

#: Lengths of the windows fitted one by one, s, beside the whole record: the short ones see a brief change of
#: velocity, the long ones a steady acceleration (which a short window takes for a tilt).
WINDOWS_S = (60.0, 120.0)
#: Each window's residual is averaged over blocks of a sixth of it (a sway's or a moored ship's oscillation averages
#: out, a change of velocity does not).
BLOCKS_PER_WINDOW = 6
#: The default window and block of :func:`window_residual`, s.
WINDOW_S, BLOCK_S = 60.0, 10.0
#: Spacing of the samples of the integrated specific force the fit uses, s (at least the sample interval).
SPACING_S = 0.5
#: Residual threshold: MOTION_MPS + MOTION_MPS_PER_S2 * window^2, m/s (the gyros' drift grows with the square of
#: the window), as :class:`fusionbench.methods.coarse.InertialCoarseAligner` uses on a whole record.
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
            _rodrigues3(a0, a1, a2, B)
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
    """The worst window's horizontal fit residual, block-averaged (module docstring), per recording, for windows of
    ``window_s`` s (the whole record when shorter) and blocks of ``block_s`` s.

    Parameters
    ----------
    imu : fusionbench.simulation.imudata.IMUData
        R recordings, body RFU.
    site : fusionbench.methods.aligner.Site
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
    tk, V = _integrated(imu)
    return _windows(tk, V, site, min(float(window_s), tk[-1]), float(block_s))


def _integrated(imu):
    """Times (K+1,) s from the initial state and the integrated specific force (R, K+1, 3) m/s in the body frame at
    the start (:func:`_integrate`), every :data:`SPACING_S`."""
    t, dth, dv = imu.increments()
    R, N, _ = dth.shape
    step = max(1, int(round(SPACING_S / imu.dt)))
    keep = np.unique(np.r_[np.arange(step - 1, N, step), N - 1])
    V = np.zeros((R, keep.size + 1, 3))
    _integrate(np.ascontiguousarray(dth), np.ascontiguousarray(dv), keep, V[:, 1:])
    return np.r_[0.0, t[keep] - imu.t0], V


def _windows(tk, V, site, W, block_s):
    """:func:`window_residual` on the integrated specific force ``V`` at times ``tk``, windows of ``W`` s."""

    R, T = V.shape[0], tk[-1]
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


def scales(duration):
    """The window lengths (s) the check fits on a record of ``duration`` s: :data:`WINDOWS_S` shorter than it, and
    the whole record."""
    return sorted({min(w, float(duration)) for w in WINDOWS_S} | {float(duration)})


def check_stationary(imu, site, name):
    """Raise ValueError (one line naming ``name``, the recording and the figure, and ``--aiding``) when the record
    shows a base that moves (module docstring): on any of the :func:`scales`, a window whose residual exceeds
    :func:`threshold_mps`, or a mean specific force above gravity; a stationary, swaying or moored base passes."""
    tk, V = _integrated(imu)
    excess = None
    for W in scales(tk[-1]):
        res, start, W, ex = _windows(tk, V, site, W, W / BLOCKS_PER_WINDOW)
        excess = ex if excess is None or W == tk[-1] else excess
        r = int(np.argmax(res))
        thr = threshold_mps(W)
        if res[r] > thr:
            raise ValueError(f"{name}: the base moves (recording {r}: between {start[r]:.0f} and {start[r] + W:.0f} s "
                             f"the specific force departs from gravity's by {res[r]:.2f} m/s of horizontal velocity, a "
                             f"stationary or swaying base by less than {thr:.2f}; or the gyros drift by more than about "
                             f"3 deg/h): a moving base needs its velocity or position as aiding (--aiding FILE)")
    check_not_accelerating(excess, MAX_GRAVITY_EXCESS, name)
