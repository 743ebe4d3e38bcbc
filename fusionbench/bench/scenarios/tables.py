"""The parsers of a scenario's motion and aiding tables: ``[motion]`` (acceleration segments, a disturbance, or the
legs of a drive) and ``[aiding]`` (a receiver: rate, noise, lever arm, latency, outages). Each returns the core's
object (SI inside) or raises a :class:`fusionbench.simulation.fields.FieldError` naming the file and the field; the
keys and units are docs/scenarios.md's."""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import fields, imu
from fusionbench.simulation.aidingsim import AidingSpec
from fusionbench.simulation.drive import Drive, Leg
from fusionbench.simulation.translation import Segment, Translation, VelocityDisturbance

_where, _num, _vec = fields.where, fields.number, fields.vector
#: Largest acceleration of a motion segment per ENU axis, m/s^2 (10 g: beyond any vehicle an alignment runs on).
MAX_ACCEL_MPS2 = 100.0
#: Largest velocity-noise figure (reference noise, disturbance RMS), m/s.
MAX_SPEED_MPS = 100.0
#: Largest heading rate of a leg, deg/s (a car turns at tens of deg/s at most).
MAX_TURN_DPS = 90.0
#: Keys of ``[motion]`` and ``[aiding]``.
MOTION_KEYS = {"start_s", "segments", "disturbance_rms_mps", "disturbance_band_hz", "disturbance_seed", "legs",
               "speed_mps"}
AIDING_KEYS = {"rate_hz", "velocity_sigma_mps", "position_sigma_m", "lever_arm_m", "delay_s", "outages", "schedule"}


def parse_motion(mo, src, duration, rate, heading, pitch, roll, swaying):
    """The translation of ``[motion]``: a :class:`fusionbench.simulation.translation.Translation` (segments,
    disturbance), or a :class:`fusionbench.simulation.drive.Drive` when it has ``legs`` (the vehicle's heading, pitch
    and roll from ``[attitude]``: ``heading``, ``pitch``, ``roll`` rad; a drive refuses a sway, ``swaying`` True)."""
    s = f"{src} [motion]"
    if "legs" in mo:
        return _drive(mo, src, duration, rate, heading, pitch, roll, swaying)
    if "speed_mps" in mo:
        raise fields.FieldError(f"{_where(src, 'motion.speed_mps')}: expected only with legs (a drive), found "
                                f"{mo['speed_mps']!r} without")
    segs = []
    if not isinstance(mo.get("segments", []), list):
        raise fields.FieldError(f"{_where(src, 'motion.segments')}: expected a list of tables, found {mo['segments']!r}")
    for i, it in enumerate(mo.get("segments", [])):
        if not isinstance(it, dict) or set(it) != {"accel_mps2", "duration_s"}:
            raise fields.FieldError(f"{_where(src, f'motion.segments[{i}]')}: expected accel_mps2 and duration_s, "
                                    f"found {it!r}")
        segs.append(Segment(_vec(it, "accel_mps2", s, lo=-MAX_ACCEL_MPS2, hi=MAX_ACCEL_MPS2),
                                       _num(it, "duration_s", s, lo=0.0)))
    dist = None
    if "disturbance_rms_mps" in mo:
        band = _vec(mo, "disturbance_band_hz", s, (0.1, 2.0), n=2)
        if not 0 < band[0] < band[1] <= rate / 4:
            raise fields.FieldError(f"{_where(src, 'motion.disturbance_band_hz')}: expected 0 < low < high <= "
                                    f"rate_hz/4, found {band}")
        dist = VelocityDisturbance(_vec(mo, "disturbance_rms_mps", s, lo=0.0, hi=MAX_SPEED_MPS), band,
                                              seed=int(_num(mo, "disturbance_seed", s, 0.0, 0, 2**31)))
    start = _num(mo, "start_s", s, 0.0, 0.0)
    if start >= duration and segs:
        raise fields.FieldError(f"{_where(src, 'motion.start_s')}: expected a start inside the record (< duration_s "
                                f"= {duration:g} s), found {start:g}")
    return Translation(segments=tuple(segs), start=start, disturbance=dist)


def _drive(mo, src, duration, rate, heading, pitch, roll, swaying):
    """A :class:`fusionbench.simulation.drive.Drive` from ``[motion]``'s ``legs`` (module docstring)."""
    s = f"{src} [motion]"
    for key in ("segments", "disturbance_rms_mps"):
        if key in mo:
            raise fields.FieldError(f"{_where(src, 'motion.' + key)}: expected legs or {key}, found both")
    if swaying:
        raise fields.FieldError(f"{_where(src, 'motion.legs')}: expected a level vehicle (no sway amplitude in "
                                f"[attitude]), found both a drive and a sway")
    legs = mo["legs"]
    if not isinstance(legs, list) or not legs:
        raise fields.FieldError(f"{_where(src, 'motion.legs')}: expected a list of tables, found {legs!r}")
    out = []
    for i, it in enumerate(legs):
        label = f"motion.legs[{i}]"
        if not isinstance(it, dict) or not set(it) <= {"duration_s", "accel_mps2", "turn_rate_dps"} \
                or "duration_s" not in it:
            raise fields.FieldError(f"{_where(src, label)}: expected duration_s [, accel_mps2, turn_rate_dps], found "
                                    f"{it!r}")
        d = _num(it, "duration_s", s, lo=0.0, label=f"{label}.duration_s")
        if abs(d * rate - round(d * rate)) > 1e-6:
            raise fields.FieldError(f"{_where(src, label + '.duration_s')}: expected whole samples of 1/rate_hz = "
                                    f"{1 / rate:g} s (a leg's end inside a sample would blur its exact increments), "
                                    f"found {d:g}")
        out.append(Leg(d, _num(it, "accel_mps2", s, 0.0, -MAX_ACCEL_MPS2, MAX_ACCEL_MPS2, f"{label}.accel_mps2"),
                       np.radians(_num(it, "turn_rate_dps", s, 0.0, -MAX_TURN_DPS, MAX_TURN_DPS,
                                       f"{label}.turn_rate_dps"))))
    speed = _num(mo, "speed_mps", s, 0.0, 0.0, MAX_SPEED_MPS * 10)
    start = _num(mo, "start_s", s, 0.0, 0.0)
    if start >= duration:
        raise fields.FieldError(f"{_where(src, 'motion.start_s')}: expected a start inside the record (< duration_s "
                                f"= {duration:g} s), found {start:g}")
    v = speed
    for i, leg in enumerate(out):
        v += leg.accel * leg.duration
        if v < -1e-9:
            raise fields.FieldError(f"{_where(src, f'motion.legs[{i}].accel_mps2')}: expected a speed that stays "
                                    f"positive (a vehicle drives forward), found {v:.3g} m/s at the leg's end")
    return Drive(heading, speed, tuple(out), start, pitch, roll)


def parse_aiding(ai, src, duration):
    """The receiver of an ``[aiding]`` table as an :class:`fusionbench.simulation.aidingsim.AidingSpec` (module
    docstring)."""
    s = f"{src} [aiding]"
    rate = _num(ai, "rate_hz", s, lo=1e-3, hi=1e4, label="aiding.rate_hz")
    vel = _vec(ai, "velocity_sigma_mps", s, lo=0.0, hi=MAX_SPEED_MPS, label="aiding.velocity_sigma_mps") \
        if "velocity_sigma_mps" in ai else None
    pos = _vec(ai, "position_sigma_m", s, lo=0.0, hi=1e4, label="aiding.position_sigma_m") \
        if "position_sigma_m" in ai else None
    if vel is None and pos is None:
        raise fields.FieldError(f"{_where(src, 'aiding')}: expected velocity_sigma_mps, position_sigma_m or both (what "
                                f"the receiver measures), found neither")
    outages = []
    items = ai.get("outages", [])
    if not isinstance(items, list):
        raise fields.FieldError(f"{_where(src, 'aiding.outages')}: expected a list of tables, found {items!r}")
    for i, it in enumerate(items):
        label = f"aiding.outages[{i}]"
        if not isinstance(it, dict) or set(it) != {"start_s", "end_s"}:
            raise fields.FieldError(f"{_where(src, label)}: expected start_s and end_s, found {it!r}")
        a = _num(it, "start_s", s, lo=0.0, hi=duration, label=f"{label}.start_s")
        b = _num(it, "end_s", s, lo=a, label=f"{label}.end_s")
        if b <= a:
            raise fields.FieldError(f"{_where(src, label + '.end_s')}: expected an end after start_s = {a:g} s, found "
                                    f"{b:g}")
        outages.append((a, b))
    scheds = imu.schedules_from_list(ai.get("schedule", []), src, "aiding.schedule")
    try:
        return AidingSpec(rate, vel, pos, _vec(ai, "lever_arm_m", s, lo=-200.0, hi=200.0, label="aiding.lever_arm_m"),
                          _num(ai, "delay_s", s, 0.0, -10.0, 10.0, "aiding.delay_s"), tuple(outages), scheds)
    except ValueError as exc:
        raise fields.FieldError(f"{_where(src, 'aiding')}: {exc}") from None
