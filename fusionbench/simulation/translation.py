"""Translational profiles: the base's velocity over the earth (ENU, m/s) as analytic functions of time.

One job: the translational half of a :class:`fusionbench.simulation.trajectory.Trajectory`: a :class:`Translation`
from an initial velocity through constant-acceleration segments (:class:`Segment`, ENU, m/s^2), plus an optional
band-limited :class:`VelocityDisturbance`; each gives velocity (m/s) and acceleration (m/s^2) exactly, times in s from
the start of the trajectory. Profiles are plain dataclasses, so scenarios describe them as data. The attitude profiles
and the composition into truth and IMU increments are in :mod:`fusionbench.simulation.trajectory`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Segment:
    """Constant acceleration in ENU (m/s^2) for a duration (s)."""

    accel: tuple
    duration: float


@dataclass(frozen=True)
class VelocityDisturbance:
    """Band-limited random velocity of the base: a sum of sinusoids per ENU axis.

    The base moves with ``v_d(t) = sum_i a_i sin(2 pi f_i t + p_i)`` on each axis, frequencies
    uniform in ``band`` and phases uniform, scaled so that the RMS velocity on each axis is
    ``rms`` (m/s). It is deterministic given ``seed``, smooth (so the IMU sees its exact
    acceleration), and its displacement stays bounded, as for a moored or quasi-static base.
    """

    rms: tuple = (0.0, 0.0, 0.0)
    band: tuple = (0.1, 2.0)
    components: int = 16
    seed: int = 0

    def _tables(self):
        rng = np.random.default_rng(self.seed)
        f = rng.uniform(self.band[0], self.band[1], (3, self.components))
        p = rng.uniform(0, 2 * np.pi, (3, self.components))
        a = np.sqrt(2.0 / self.components) * np.asarray(self.rms, dtype=float)[:, None] * np.ones_like(f)
        return a, 2 * np.pi * f, p

    def evaluate(self, t):
        """Velocity (N, 3) m/s, acceleration (N, 3) m/s^2 and displacement (N, 3) m, ENU."""
        t = np.asarray(t, dtype=float)
        a, w, p = self._tables()
        arg = w[None] * t[:, None, None] + p[None]
        v = np.sum(a * np.sin(arg), axis=-1)
        acc = np.sum(a * w * np.cos(arg), axis=-1)
        disp = np.sum(a / w * (np.cos(p) - np.cos(arg)), axis=-1)
        return v, acc, disp


@dataclass(frozen=True)
class Translation:
    """Velocity in ENU from rest-or-``v0`` through constant-acceleration segments, then constant.

    Parameters
    ----------
    v0 : (3,) array_like
        Initial velocity, ENU, m/s.
    segments : sequence of Segment
        Acceleration segments, applied one after the other from ``start`` (s).
    start : float
        Time the first segment begins, s.
    disturbance : VelocityDisturbance, optional
        Added band-limited velocity.
    """

    v0: tuple = (0.0, 0.0, 0.0)
    segments: tuple = ()
    start: float = 0.0
    disturbance: VelocityDisturbance | None = None

    def _knots(self):
        t = [self.start]
        v = [np.asarray(self.v0, dtype=float)]
        for s in self.segments:
            v.append(v[-1] + np.asarray(s.accel, dtype=float) * s.duration)
            t.append(t[-1] + s.duration)
        return np.array(t), np.array(v)

    def manoeuvres(self):
        """The segments as ``(t0_s, t1_s, label)``, s from the start of the trajectory (those of zero length left
        out), each labelled with its acceleration (m/s^2): the events of a figure's time axis."""
        out, t = [], self.start
        for seg in self.segments:
            if seg.duration > 0:
                a = float(np.linalg.norm(np.asarray(seg.accel, dtype=float)))
                out.append((t, t + seg.duration, f"manoeuvre, {a:.3g} m/s^2"))
            t += seg.duration
        return out

    def is_static(self):
        return not self.segments and not np.any(self.v0)

    def mean_velocity(self, t):
        """Velocity (N, 3) m/s and acceleration (N, 3) m/s^2 without the disturbance."""
        t = np.asarray(t, dtype=float)
        tk, vk = self._knots()
        v = np.empty(t.shape + (3,))
        a = np.zeros(t.shape + (3,))
        for i in range(3):
            v[..., i] = np.interp(t, tk, vk[:, i])
        for s, t0 in zip(self.segments, tk[:-1]):
            sel = (t >= t0) & (t < t0 + s.duration)
            a[sel] = s.accel
        return v, a


def accelerate_to(speed, accel, direction=(1.0, 0.0, 0.0)):
    """One :class:`Segment` accelerating at ``accel`` (m/s^2) along ENU ``direction`` until ``speed`` (m/s)."""
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    return Segment(tuple(d * accel), speed / accel)
