"""Is a given initial attitude within what a fine aligner recovers from? Checked against a coarse solution of the
record's own before the method runs.

A fine aligner linearised about its start (a Kalman filter's small-angle error model, the ESO/TD loop's small
feedback) converges from an initial attitude within its capture range and lands elsewhere, without a word, from
one beyond it: handed the truth turned 180 deg in yaw (static base, 34 N, navigation grade, 300 s), ``kf`` ended
8-11 deg off, ``akf`` and ``eso-td`` 178-180 deg. Such a method declares ``init_capture_deg``; with an ``init``,
:func:`check_capture` carries it over the first ``span_s`` seconds with the gyros (the strapdown, position held) and
compares it with the inertial-frame coarse alignment of the same seconds (``coarse-i0``, with the aiding there on
a moving base). The rotation angle between the two may be up to the capture range plus the coarse solution's own
error (:func:`coarse_error_deg`); beyond it the method refuses in one line naming ``init``. An ``init`` it accepts
is off by at most the capture range plus twice that error.
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.claims import azimuth_bias_ratio
from fusionbench.methods.coarse_i0 import inertial_coarse
from fusionbench.methods.motion import check_stationary
from fusionbench.simulation import earth
from fusionbench.simulation.imudata import IMUData

__all__ = ["COARSE_NOISE_DEG", "NOISE_SIGMAS", "coarse_error_deg", "init_offset_deg", "check_capture"]

#: The coarse solution's error allowed beside what the IMU model accounts for, deg (a sway's share, a receiver's
#: rows at 1 Hz: measured up to 0.9 deg from a correct init on fixed, swaying and moving bases, navigation grade).
COARSE_NOISE_DEG = 1.5
#: How many of the gyro noise's standard deviations the coarse solution's azimuth may be off.
NOISE_SIGMAS = 4.0


def coarse_error_deg(spec, lat, span_s) -> float:
    """How far the coarse solution over ``span_s`` s may be from the truth, deg: the azimuth the gyro bias of
    ``spec`` turns north by at latitude ``lat`` (rad), ``asin(bias / horizontal earth rate)``
    (:func:`~fusionbench.methods.claims.azimuth_bias_ratio`), plus :data:`NOISE_SIGMAS` times the azimuth its white gyro
    noise leaves after ``span_s``, ``white / (horizontal earth rate sqrt(span_s))``, plus :data:`COARSE_NOISE_DEG`.
    ``spec`` None: the ``navigation`` preset. Measured over 60 s from a correct init (8 runs each): navigation grade
    0.09-0.45 deg mean, 1.2 max (80 N); tactical 4.8-8.7 deg mean at 34-60 N, 16.4 max."""
    from fusionbench.simulation.imu import PRESETS

    spec = PRESETS["navigation"] if spec is None else spec
    w_h = earth.OMEGA_IE * abs(np.cos(lat))
    bias = np.arcsin(min(float(azimuth_bias_ratio(spec, lat)), 1.0))
    noise = float(np.max(spec.gyro.white)) / (w_h * np.sqrt(span_s)) if w_h > 0 else np.pi
    return float(np.degrees(min(bias + NOISE_SIGMAS * noise, np.pi))) + COARSE_NOISE_DEG


def init_offset_deg(imu: IMUData, site, aiding, init, span_s: float, caller: str) -> np.ndarray:
    """Rotation angle (R,), deg, between ``init`` (R, 3, 3) carried over the first ``span_s`` s of ``imu`` and the
    inertial-frame coarse alignment of those seconds (with the rows of ``aiding`` valid there)."""
    from fusionbench.simulation.strapdown import NavState, Strapdown

    t, dth, dv = imu.increments()
    k = min(max(int(round(span_s / imu.dt)), 2), t.size)
    part = IMUData(t[:k], dth[:, :k], dv[:, :k], "increment")
    rows = None if aiding is None else aiding.window(-np.inf, float(t[k - 1]))
    who = f"{caller} (coarse-i0 start)"
    if rows is None or rows.is_at_rest():  # as coarse-i0's input policy: a stretch that moves needs rows of its motion
        check_stationary(part, site, who)
    coarse = inertial_coarse(part, site, rows, history_points=2, who=who)
    nav = NavState.broadcast(imu.runs, init, lat=site.lat, lon=site.lon, h=site.h)
    carried = Strapdown(nav, imu.dt, position_fixed=True).run(dth[:, :k], dv[:, :k], record_every=k)["C_bn"][:, -1]
    cos = (np.einsum("rij,rij->r", carried, coarse.C_bn_final) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def check_capture(method, imu: IMUData, site, aiding, init, span_s: float = 60.0):
    """Refuse an ``init`` beyond what ``method`` recovers from (module docstring): a one-line ``ValueError`` naming
    the method, ``init``, the angle found, the largest allowed and the way out.

    Parameters
    ----------
    method : fusionbench.methods.aligner_base.AlignerBase
        Declares ``init_capture_deg`` (deg); its ``spec`` (the IMU model, or None) sets the coarse solution's error.
    imu : IMUData
        Body RFU, R recordings.
    site : fusionbench.methods.aligner.Site
    aiding : fusionbench.simulation.aiding.Aiding or None
    init : ndarray, shape (R, 3, 3)
        The given initial attitude C_bn at the record's start.
    span_s : float
        Seconds of the record the coarse solution uses (the method's own coarse stage); the whole record when the
        aiding there is too sparse for one (and no check when it is for the whole record too: the method's own
        checks then refuse the aiding).

    Returns
    -------
    ndarray, shape (R,), or None
        The angles found, deg (None: not checked).
    """
    span_s = min(float(span_s), imu.duration)
    try:
        found = init_offset_deg(imu, site, aiding, init, span_s, method.name)
    except ValueError:  # too few aiding rows there for a coarse solution: the whole record's, or nothing to check
        span_s = imu.duration
        try:
            found = init_offset_deg(imu, site, aiding, init, span_s, method.name)
        except ValueError:  # the method's own checks speak about such aiding
            return None
    allowed = float(method.init_capture_deg) + coarse_error_deg(getattr(method, "spec", None), site.lat, span_s)
    worst = int(np.argmax(found))
    if found[worst] > allowed:
        run = f" (run {worst})" if found.size > 1 else ""
        raise ValueError(f"{method.name}: init: expected an initial attitude within {allowed:.3g} deg of the record's "
                         f"own coarse alignment over its first {span_s:g} s ({method.init_capture_deg:g} deg the "
                         f"method recovers from, plus the coarse solution's error), found {found[worst]:.3g} deg"
                         f"{run}: give a correct init, or none (the method then aligns from its own coarse stage)")
    return found

