"""Motion profiles: the true attitude, velocity and position of the IMU as analytic functions of time.

A :class:`Trajectory` combines an attitude profile (Euler-angle sway, or a turntable rotation
sequence; here) with a translational profile (constant-acceleration segments in ENU plus an optional
band-limited velocity disturbance; :mod:`fusionbench.simulation.translation`) at a site. From it come, exactly:

* the truth (``C_bn``, ``v_n``, latitude, longitude, height) at any times;
* the true angular rate ``omega_ib^b`` (rad/s) and specific force ``f^b`` (m/s^2) in the body frame;
* the true increments over each sample interval, integrated with 4-point Gauss-Legendre
  quadrature (exact to rounding for the smooth profiles here), which an error-free
  rate-integrating IMU would output.

Frames: n = ENU, b = RFU; attitude convention as in :mod:`fusionbench.simulation.attitude`. All times in s,
angles in rad, the time origin at the start of the trajectory.

Profiles are plain dataclasses, so scenarios describe them as data.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from fusionbench.simulation import attitude, earth
from fusionbench.simulation.translation import Segment, Translation, VelocityDisturbance, accelerate_to

_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)


# --------------------------------------------------------------------------- attitude profiles
@dataclass(frozen=True)
class EulerSway:
    """Sinusoidal sway of the Euler angles about a mean attitude (static when amplitudes are 0).

    ``angle_i(t) = mean_i + amplitude_i sin(2 pi frequency_i t + phase_i)`` for
    ``[pitch, roll, yaw]``.

    Parameters
    ----------
    mean : (3,) array_like
        Mean ``[pitch, roll, yaw]``, rad.
    amplitude : (3,) array_like
        Sway amplitudes, rad.
    frequency : (3,) array_like
        Sway frequencies, Hz.
    phase : (3,) array_like
        Phases, rad.
    """

    mean: tuple = (0.0, 0.0, 0.0)
    amplitude: tuple = (0.0, 0.0, 0.0)
    frequency: tuple = (0.0, 0.0, 0.0)
    phase: tuple = (0.0, 0.0, 0.0)

    def euler(self, t):
        """Euler angles ``[pitch, roll, yaw]`` (rad) and their first derivatives (rad/s), ``(N, 3)`` each."""
        t = np.asarray(t, dtype=float)[:, None]
        w = 2 * np.pi * np.asarray(self.frequency, dtype=float)
        arg = w * t + np.asarray(self.phase, dtype=float)
        amp = np.asarray(self.amplitude, dtype=float)
        return np.asarray(self.mean, dtype=float) + amp * np.sin(arg), amp * w * np.cos(arg)

    def attitude(self, t):
        """``C_bn`` (N, 3, 3) and the body rate over the navigation frame omega_nb^b (N, 3), rad/s."""
        e, de = self.euler(t)
        return attitude.euler_to_dcm(e), euler_rates_to_body(e, de)


def euler_rates_to_body(euler, euler_rate):
    """omega_nb^b (rad/s) from Euler angles ``[pitch, roll, yaw]`` and their rates.

    For ``C_bn = Rz(yaw) Rx(pitch) Ry(roll)``:
    ``omega_nb^b = [cr dp - sr cp dy, dr + sp dy, sr dp + cr cp dy]``.
    """
    p, r = euler[..., 0], euler[..., 1]
    dp, dr, dy = euler_rate[..., 0], euler_rate[..., 1], euler_rate[..., 2]
    sp, cp, sr, cr = np.sin(p), np.cos(p), np.sin(r), np.cos(r)
    return np.stack([cr * dp - sr * cp * dy, dr + sp * dy, sr * dp + cr * cp * dy], axis=-1)


@dataclass(frozen=True)
class Rotation:
    """One turntable segment: constant rate about a fixed axis for a duration.

    Parameters
    ----------
    axis : (3,) array_like
        Rotation axis (normalised here); in the body frame (``frame="body"``, an inner turntable
        axis) or the navigation frame (``frame="nav"``).
    rate : float
        Angular rate, rad/s (positive: right-handed about ``axis``).
    duration : float
        Segment length, s; use multiples of the sample interval so that no sample straddles a rate step.
    frame : {"body", "nav"}
    """

    axis: tuple
    rate: float
    duration: float
    frame: str = "body"


@dataclass(frozen=True)
class RotationSequence:
    """Turntable profile: an initial attitude, then :class:`Rotation` segments, then rest."""

    initial: tuple = (0.0, 0.0, 0.0)
    segments: tuple = ()

    def _starts(self):
        C = attitude.euler_to_dcm(np.asarray(self.initial, dtype=float))
        t0, out = 0.0, []
        for seg in self.segments:
            if seg.frame not in ("body", "nav"):
                raise ValueError(f"rotation frame: expected 'body' or 'nav', found {seg.frame!r}")
            axis = np.asarray(seg.axis, dtype=float)
            axis = axis / np.linalg.norm(axis)
            out.append((t0, C, axis, seg))
            R = attitude.rotvec_to_dcm(axis * seg.rate * seg.duration)
            C = C @ R if seg.frame == "body" else R @ C
            t0 += seg.duration
        return out, t0, C

    def attitude(self, t):
        """``C_bn`` (N, 3, 3) and omega_nb^b (N, 3), rad/s."""
        t = np.asarray(t, dtype=float)
        starts, t_end, C_end = self._starts()
        C = np.broadcast_to(C_end, t.shape + (3, 3)).copy()
        w = np.zeros(t.shape + (3,))
        for t0, C0, axis, seg in starts:
            sel = (t >= t0) & (t < t0 + seg.duration)
            if not np.any(sel):
                continue
            R = attitude.rotvec_to_dcm(np.outer(t[sel] - t0, axis * seg.rate))
            if seg.frame == "body":
                C[sel] = C0 @ R
                w[sel] = axis * seg.rate
            else:
                C[sel] = R @ C0
                w[sel] = np.einsum("nji,j->ni", C[sel], axis * seg.rate)
        if starts:
            C[t < 0] = starts[0][1]
        return C, w


# ----------------------------------------------------------------------------------- trajectory
@dataclass
class Truth:
    """True navigation state at times ``t`` (s): ``C_bn`` (N,3,3), ``v_n`` (N,3) m/s ENU,
    ``lat``, ``lon`` (N,) rad, ``h`` (N,) m."""

    t: np.ndarray
    C_bn: np.ndarray
    v_n: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray


@dataclass
class Trajectory:
    """Site, attitude profile and translation: everything the simulator needs to produce truth.

    Parameters
    ----------
    lat, lon : float
        Latitude and longitude at t = 0, rad.
    h : float
        Height at t = 0, m.
    attitude : EulerSway or RotationSequence
        Attitude profile.
    translation : Translation
        Translational profile (static by default).
    duration : float
        Length, s.
    """

    lat: float
    lon: float
    h: float
    attitude: object = field(default_factory=EulerSway)
    translation: Translation = field(default_factory=Translation)
    duration: float = 600.0

    def __post_init__(self):
        earth.check_latitude(self.lat, "trajectory latitude")
        for name, value, lo, hi in (("lon", self.lon, -4 * np.pi, 4 * np.pi), ("h", self.h, -1e4, 1e5)):
            if not (np.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"Trajectory {name}: expected a finite number in [{lo:g}, {hi:g}], found {value!r}")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"Trajectory duration: expected a positive length in s, found {self.duration!r}")
        self._pos = None

    # position: lat' = vN / (RM + h), lon' = vE / ((RN + h) cos lat), h' = vU, for the mean motion;
    # the disturbance displacement is added to first order (it stays at the millimetre level).
    def _position_solution(self):
        if self._pos is None:
            tr = self.translation
            tk, _ = tr._knots()
            edges = np.unique(np.clip(np.concatenate([[0.0], tk, [self.duration]]), 0.0, self.duration))
            pieces = []
            y = np.array([self.lat, self.lon, self.h])

            def rhs(t, y):
                v, _ = tr.mean_velocity(np.array([t]))
                rm, rn = earth.radii(y[0])
                return [v[0, 1] / (rm + y[2]), v[0, 0] / ((rn + y[2]) * np.cos(y[0])), v[0, 2]]

            for a, b in zip(edges[:-1], edges[1:]):
                sol = solve_ivp(rhs, (a, b), y, method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True)
                pieces.append((a, b, sol.sol))
                y = sol.y[:, -1]
            self._pos = (pieces, y)
        return self._pos

    def position(self, t):
        """Latitude, longitude (rad) and height (m) at times ``t`` (s), each shape (N,)."""
        t = np.asarray(t, dtype=float)
        if self.translation.is_static():
            out = np.broadcast_to(np.array([self.lat, self.lon, self.h]), t.shape + (3,)).copy()
        else:
            pieces, y_end = self._position_solution()
            out = np.broadcast_to(y_end, t.shape + (3,)).copy()
            for a, b, sol in pieces:
                sel = (t >= a) & (t <= b)
                if np.any(sel):
                    out[sel] = sol(t[sel]).T
            out[t < 0] = [self.lat, self.lon, self.h]
        if self.translation.disturbance is not None:
            _, _, d = self.translation.disturbance.evaluate(t)
            rm, rn = earth.radii(out[:, 0])
            out[:, 0] += d[:, 1] / (rm + out[:, 2])
            out[:, 1] += d[:, 0] / ((rn + out[:, 2]) * np.cos(out[:, 0]))
            out[:, 2] += d[:, 2]
        return out[:, 0], out[:, 1], out[:, 2]

    def velocity(self, t):
        """Velocity ``v_n`` (N, 3) m/s and its time derivative (N, 3) m/s^2, ENU."""
        v, a = self.translation.mean_velocity(t)
        if self.translation.disturbance is not None:
            dv, da, _ = self.translation.disturbance.evaluate(t)
            v, a = v + dv, a + da
        return v, a

    def truth(self, t):
        """The true state at times ``t`` (s) as a :class:`Truth`."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        C, _ = self.attitude.attitude(t)
        v, _ = self.velocity(t)
        lat, lon, h = self.position(t)
        return Truth(t, C, v, lat, lon, h)

    def kinematics(self, t):
        """True angular rate omega_ib^b (N, 3) rad/s and specific force f^b (N, 3) m/s^2 at ``t``.

        ``omega_ib^b = omega_nb^b + C_bn^T (omega_ie^n + omega_en^n)`` and
        ``f^b = C_bn^T (dv_n/dt + (2 omega_ie^n + omega_en^n) x v_n - g^n)``.
        """
        t = np.asarray(t, dtype=float)
        C, w_nb = self.attitude.attitude(t)
        v, a = self.velocity(t)
        lat, _, h = self.position(t)
        w_ie = earth.earth_rate_n(lat)
        w_en = earth.transport_rate_n(v, lat, h)
        f_n = a + np.cross(2 * w_ie + w_en, v) - earth.gravity_n(lat, h)
        Ct = np.swapaxes(C, -1, -2)
        w_ib = w_nb + np.einsum("nij,nj->ni", Ct, w_ie + w_en)
        f_b = np.einsum("nij,nj->ni", Ct, f_n)
        return w_ib, f_b

    def increments(self, t_start, dt, n):
        """Exact angle (rad) and velocity (m/s) increments of ``n`` samples, body frame.

        Sample k covers ``(t_start + k dt, t_start + (k + 1) dt]``.

        Returns
        -------
        t : ndarray, shape (n,)
            End time of each sample interval, s.
        dtheta, dvel : ndarray, shape (n, 3)
            Integrals of omega_ib^b and f^b over each interval.
        """
        k = np.arange(n)
        mid = t_start + (k + 0.5) * dt
        tq = (mid[:, None] + 0.5 * dt * _GL_X[None, :]).ravel()
        w, f = self.kinematics(tq)
        wts = 0.5 * dt * _GL_W
        dtheta = np.einsum("nqi,q->ni", w.reshape(n, 4, 3), wts)
        dvel = np.einsum("nqi,q->ni", f.reshape(n, 4, 3), wts)
        return t_start + (k + 1) * dt, dtheta, dvel


# ------------------------------------------------------------------------- the papers' profiles
def moored(lat, lon=0.0, h=0.0, mean=(0.0, 0.0, 0.0), amplitude=(5 * np.pi / 180, 7 * np.pi / 180, 9 * np.pi / 180),
           frequency=(0.5, 0.3, 0.2), disturbance_rms=0.05, duration=600.0, seed=0):
    """Moored/swaying base (seed 000 (Zhou 2011, ADRC gyrocompass), Table 1 by default): sway on ``[pitch, roll, yaw]``
    (rad, Hz) about ``mean`` plus a band-limited linear velocity disturbance of ``disturbance_rms`` m/s per axis."""
    dist = VelocityDisturbance((disturbance_rms,) * 3, seed=seed) if disturbance_rms else None
    return Trajectory(lat, lon, h, EulerSway(tuple(mean), tuple(amplitude), tuple(frequency)),
                      Translation(disturbance=dist), duration)


def accelerating(lat, lon=0.0, h=0.0, mean=(0.0, 0.0, 0.0), accel=0.1 * 9.80665, accel_duration=None,
                 start=0.0, direction=(1.0, 0.0, 0.0), duration=400.0):
    """Moving base (seed 001 (Zhao 2007, ESO/TD alignment) by default: 0.1 g east from t = start until the end, or for
    accel_duration s)."""
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    seg = Segment(tuple(d * accel), (duration - start) if accel_duration is None else accel_duration)
    return Trajectory(lat, lon, h, EulerSway(tuple(mean)), Translation(segments=(seg,), start=start), duration)


def ship(lat, lon=0.0, h=0.0, heading=0.0, accel=0.02, cruise_speed=20.0, static_s=12 * 3600.0,
         duration=20 * 3600.0, direction=(1.0, 0.0, 0.0)):
    """Ship at sea (seed 004 (Gu 2017, adaptive Schuler damping)): sea sway pitch 1.2 deg sin(2 pi t/7), roll 1.2 deg
    sin(2 pi t/8), yaw 0.8 deg sin(2 pi t/11) about ``heading`` (rad, clockwise from north); at rest for
    ``static_s`` s, then accelerating at ``accel`` m/s^2 along ENU ``direction`` up to ``cruise_speed``
    m/s, then cruising, for ``duration`` s in all (20 h by default)."""
    deg = np.pi / 180
    sway = EulerSway((0.0, 0.0, -heading), (1.2 * deg, 1.2 * deg, 0.8 * deg), (1 / 7, 1 / 8, 1 / 11))
    return Trajectory(lat, lon, h, sway,
                      Translation(segments=(accelerate_to(cruise_speed, accel, direction),), start=static_s), duration)
