"""A vehicle that drives: speed and heading in legs, the velocity along the heading, as a car or a ship moves.

A :class:`Drive` is both the attitude profile and the translation of a
:class:`fusionbench.simulation.trajectory.Trajectory` (build one with :func:`drive`): the body's forward axis points
along the velocity over the ground, so a turn turns the velocity with the heading, and the centripetal acceleration of
the turn is in the specific force. In each leg the tangential acceleration and the heading rate rise from zero and
fall back to it, a raised cosine ``x(tau) = x_mean (1 - cos(2 pi tau / d))`` over the leg's length d (twice the mean
at the middle), as a driver presses a pedal or turns the wheel: speed, heading and both their rates are continuous
everywhere, so no instant of the record (an aiding row's, say) sees a rate that jumps. Frames and conventions as in
:mod:`fusionbench.simulation.trajectory`: ENU, body RFU, ``C_bn = Rz(yaw) Rx(pitch) Ry(roll)`` with yaw = -heading;
pitch and roll are the IMU's fixed mounting tilt (the velocity stays horizontal). SI inside: rad, rad/s, m/s, m/s^2, s.

The IMU simulator integrates each sample interval with Gauss-Legendre quadrature, exact for smooth motion: leg
boundaries on the sample grid (durations in whole samples) keep every interval inside one leg's formula.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusionbench.simulation import attitude
from fusionbench.simulation.trajectory import Trajectory, euler_rates_to_body


@dataclass(frozen=True)
class Leg:
    """One leg of a drive.

    Parameters
    ----------
    duration : float
        Length, s.
    accel : float
        Mean tangential acceleration (rate of change of speed) over the leg, m/s^2; negative brakes.
    turn_rate : float
        Mean heading rate over the leg, rad/s, clockwise from above positive (a right turn); the yaw rate is its
        negative.
    """

    duration: float
    accel: float = 0.0
    turn_rate: float = 0.0


@dataclass(frozen=True)
class Drive:
    """Speed and heading through :class:`Leg` s from ``start`` (s), at rest or cruising before and after.

    Parameters
    ----------
    heading : float
        Heading at the start, rad, clockwise from north.
    speed : float
        Speed at the start, m/s.
    legs : tuple of Leg
        The legs, one after the other from ``start``; after the last the vehicle keeps its speed and heading.
    start : float
        Time the first leg begins, s (before it: constant speed and heading).
    pitch, roll : float
        The IMU's fixed tilt on the vehicle, rad.
    """

    heading: float = 0.0
    speed: float = 0.0
    legs: tuple = ()
    start: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    #: The translation protocol of :class:`fusionbench.simulation.translation.Translation`: a drive has no disturbance.
    disturbance = None

    def manoeuvres(self):
        """The legs that change speed or heading as ``(t0_s, t1_s, label)``, s from the start of the trajectory,
        labelled with their mean acceleration (m/s^2) and heading rate (deg/s, clockwise positive): the events of a
        figure's time axis."""
        out, t = [], self.start
        for leg in self.legs:
            side = "right" if leg.turn_rate > 0 else "left"
            what = ([f"{side} turn {abs(np.degrees(leg.turn_rate)):.3g} deg/s"] if leg.turn_rate else []) + \
                   ([f"{'accelerate' if leg.accel > 0 else 'brake'} {abs(leg.accel):.3g} m/s^2"] if leg.accel else [])
            if what and leg.duration > 0:
                out.append((t, t + leg.duration, ", ".join(what)))
            t += leg.duration
        return out

    def _table(self):
        """Leg start times (L+1,), speeds (L+1,), headings (L+1,), accelerations (L,), heading rates (L,)."""
        t, s, h = [self.start], [self.speed], [self.heading]
        for leg in self.legs:
            t.append(t[-1] + leg.duration)
            s.append(s[-1] + leg.accel * leg.duration)
            h.append(h[-1] + leg.turn_rate * leg.duration)
        acc = np.array([leg.accel for leg in self.legs], dtype=float)
        rate = np.array([leg.turn_rate for leg in self.legs], dtype=float)
        return np.array(t), np.array(s), np.array(h), acc, rate

    def _state(self, t):
        """Speed (N,), heading (N,), tangential acceleration (N,) and heading rate (N,) at times ``t`` (s): in a leg
        of length d from its start, ``x' = x'_mean (1 - cos(2 pi tau / d))``, so ``x = x_start + x'_mean (tau -
        d sin(2 pi tau / d) / 2 pi)``."""
        t = np.asarray(t, dtype=float)
        tk, sk, hk, acc, rate = self._table()
        i = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, max(len(self.legs) - 1, 0))
        inside = (t >= tk[0]) & (t < tk[-1]) if self.legs else np.zeros(t.shape, bool)
        d = np.diff(tk)[i] if self.legs else np.ones(t.shape)
        tau = np.where(inside, t - tk[i], 0.0)
        arg = 2.0 * np.pi * tau / d
        shape, ramp = 1.0 - np.cos(arg), tau - d * np.sin(arg) / (2.0 * np.pi)
        a = np.where(inside, (acc[i] if self.legs else 0.0) * shape, 0.0)
        r = np.where(inside, (rate[i] if self.legs else 0.0) * shape, 0.0)
        s = np.where(t < tk[0], sk[0], np.where(inside, sk[i] + (acc[i] if self.legs else 0.0) * ramp, sk[-1]))
        h = np.where(t < tk[0], hk[0], np.where(inside, hk[i] + (rate[i] if self.legs else 0.0) * ramp, hk[-1]))
        return s, h, a, r

    # the attitude-profile protocol (EulerSway, RotationSequence)
    def attitude(self, t):
        """``C_bn`` (N, 3, 3) and the body rate over the navigation frame omega_nb^b (N, 3), rad/s."""
        _, h, _, r = self._state(t)
        euler = np.stack([np.full_like(h, self.pitch), np.full_like(h, self.roll), -h], axis=-1)
        rates = np.stack([np.zeros_like(r), np.zeros_like(r), -r], axis=-1)
        return attitude.euler_to_dcm(euler), euler_rates_to_body(euler, rates)

    # the translation protocol (fusionbench.simulation.translation.Translation)
    def _knots(self):
        """Leg boundaries (s) and the velocity there (ENU, m/s): where the position integration restarts."""
        tk, sk, hk, _, _ = self._table()
        return tk, np.stack([sk * np.sin(hk), sk * np.cos(hk), np.zeros_like(sk)], axis=-1)

    def is_static(self):
        """Whether the vehicle never moves."""
        return self.speed == 0.0 and not any(leg.accel for leg in self.legs)

    def mean_velocity(self, t):
        """Velocity (N, 3) m/s and acceleration (N, 3) m/s^2, ENU: along the heading, and the turn's
        centripetal part ``speed x heading rate`` across it."""
        s, h, a, r = self._state(t)
        sh, ch = np.sin(h), np.cos(h)
        v = np.stack([s * sh, s * ch, np.zeros_like(s)], axis=-1)
        acc = np.stack([a * sh + s * r * ch, a * ch - s * r * sh, np.zeros_like(s)], axis=-1)
        return v, acc


def drive(lat, lon=0.0, h=0.0, legs=(), heading=0.0, speed=0.0, start=0.0, pitch=0.0, roll=0.0, duration=300.0):
    """A :class:`fusionbench.simulation.trajectory.Trajectory` of a vehicle driving the ``legs`` (:class:`Drive`;
    angles rad, rates rad/s, speeds m/s, times s) from (``lat``, ``lon`` rad, ``h`` m)."""
    d = Drive(float(heading), float(speed), tuple(legs), float(start), float(pitch), float(roll))
    return Trajectory(lat, lon, h, attitude=d, translation=d, duration=duration)


def car_legs(duration):
    """The legs of a car's drive with turns lasting at least ``duration`` s (:func:`car_drive`): from rest it
    accelerates (0.5 m/s^2 on average) to 10 m/s, then alternates straight stretches and 40-deg turns right and left
    (over 8 s: 5 deg/s on average, 10 at the apex), slowing to 6 m/s for each turn and back to 10 m/s after it.
    Every leg is a whole number of 0.1 s."""
    deg = np.pi / 180.0
    legs = [Leg(20.0, 0.5)]
    sign = 1.0
    while sum(leg.duration for leg in legs) < duration:
        legs += [Leg(10.0), Leg(4.0, -1.0), Leg(8.0, 0.0, sign * 5.0 * deg), Leg(4.0, 1.0), Leg(6.0)]
        sign = -sign
    return legs


def car_drive(lat, lon=0.0, h=0.0, heading=0.0, wait=0.0, duration=300.0, pitch=0.0, roll=0.0):
    """A car's drive with turns (the conformance matrix's and the tests'): at rest for ``wait`` s, then the legs of
    :func:`car_legs` until ``duration`` s; the site (rad, m) and heading, pitch, roll (rad) as :func:`drive`."""
    return drive(lat, lon, h, car_legs(duration - wait), heading, 0.0, wait, pitch, roll, duration)
