"""Recordings from an independent simulator, pyins (PyPI ``python-ins``), made at test time.

pyins works in NED with FRD body axes and roll-pitch-heading angles; fusionbench in ENU with RFU body
axes. The same matrix P = [[0, 1, 0], [1, 0, 0], [0, 0, -1]] swaps the first two axes and flips the third
in both frames, so ``C_bn (RFU -> ENU) = P C_nb_pyins (FRD -> NED) P`` and body vectors map as ``v_RFU = P v_FRD``.
pyins interpolates the attitude with a rotation spline through the given angles, so its truth is the
attitude at the sample times; its rate output is the spline's derivative there, its increment output the
spline's integral over each interval (its first row repeats the second: dropped here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass
class Recording:
    """One pyins recording in fusionbench's frames: sample times t (N,) s, rates (N, 3) rad/s and m/s^2 at t,
    increments (N - 1, 3) rad and m/s over (t[k-1], t[k]], and the true C_bn (N, 3, 3) at t; the site in deg/m."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    dtheta: np.ndarray
    dvel: np.ndarray
    C_bn: np.ndarray
    lat_deg: float
    lon_deg: float
    height_m: float

    def truth_at(self, times):
        """True C_bn at sample times (s), (M, 3, 3); each time must be one of ``t``."""
        dt = self.t[1] - self.t[0]
        k = np.rint((np.asarray(times) - self.t[0]) / dt).astype(int)
        if np.any(np.abs(self.t[k] - times) > 1e-6 * dt):
            raise ValueError("truth_at: times off the sample grid")
        return self.C_bn[k]


def sway(lat_deg=34.0, lon_deg=108.0, height_m=450.0, heading_deg=30.0, rate_hz=100.0, duration_s=150.0,
         amplitude_deg=(5.0, 7.0, 9.0), frequency_hz=(0.5, 0.3, 0.2), pitch_deg=0.0, roll_deg=0.0):
    """A perfect IMU on a swaying base simulated by pyins.

    ``amplitude_deg`` and ``frequency_hz`` are the sway of [pitch, roll, heading] (seed 000's Table 1 by
    default: 5/7/9 deg at 0.5/0.3/0.2 Hz); heading is clockwise from north.
    """
    from pyins import sim, transform

    n = int(round(duration_s * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    amp = np.asarray(amplitude_deg, dtype=float)
    arg = 2 * np.pi * np.outer(t, frequency_hz)
    # pyins angles: roll, pitch, heading (deg)
    rph = np.column_stack([roll_deg + amp[1] * np.sin(arg[:, 1]), pitch_deg + amp[0] * np.sin(arg[:, 0]),
                           heading_deg + amp[2] * np.sin(arg[:, 2])])
    lla = np.tile([lat_deg, lon_deg, height_m], (n, 1))
    vel = np.zeros((n, 3))
    _, rate = sim.generate_imu(t, lla, rph, vel, sensor_type="rate")
    _, inc = sim.generate_imu(t, lla, rph, vel, sensor_type="increment")
    cols_g, cols_a = ["gyro_x", "gyro_y", "gyro_z"], ["accel_x", "accel_y", "accel_z"]
    C_bn = P @ transform.mat_from_rph(rph) @ P
    return Recording(t, rate[cols_g].to_numpy() @ P, rate[cols_a].to_numpy() @ P,
                     inc[cols_g].to_numpy()[1:] @ P, inc[cols_a].to_numpy()[1:] @ P, C_bn,
                     lat_deg, lon_deg, height_m)


@dataclass
class Drive(Recording):
    """A pyins drive: a :class:`Recording` plus the true position (``lla`` (N, 3): deg, deg, m) and velocity
    (``v_enu`` (N, 3) m/s) at the sample times, and pyins's own trajectory (NED, FRD, for :meth:`antenna`)."""

    lla: np.ndarray = None
    v_enu: np.ndarray = None
    trajectory: object = None
    heading_rate: np.ndarray = None

    def antenna(self, lever_rfu):
        """The antenna's position (N, 3) (deg, deg, m) and velocity (N, 3) ENU m/s at the sample times, for a lever
        arm ``lever_rfu`` (m, body right-front-up), translated by pyins (``transform.translate_trajectory``: the
        position by ``C_nb l``, the velocity by ``C_nb (omega_nb^b x l)``)."""
        from pyins import transform

        traj = self.trajectory.copy()
        rate_ned = np.column_stack([np.zeros_like(self.heading_rate), np.zeros_like(self.heading_rate),
                                    self.heading_rate])  # the body turns about the local down axis only
        C_nb = transform.mat_from_rph(traj[["roll", "pitch", "heading"]].to_numpy())
        traj[["rate_x", "rate_y", "rate_z"]] = np.einsum("nji,nj->ni", C_nb, rate_ned)
        moved = transform.translate_trajectory(traj, P @ np.asarray(lever_rfu, dtype=float))
        return moved[["lat", "lon", "alt"]].to_numpy(), moved[["VN", "VE", "VD"]].to_numpy() @ P


def drive(lat_deg=45.0, lon_deg=12.0, height_m=100.0, heading_deg=30.0, rate_hz=100.0, duration_s=300.0,
          pitch_deg=1.0, roll_deg=-2.0):
    """A car's drive with turns simulated by pyins: from rest, smoothly up to 10 m/s over 20 s, then a 40-deg turn
    (right, then left, ...) every 30 s at up to 8 deg/s, each a raised-cosine heading rate over 10 s; the IMU tilted
    by ``pitch_deg`` and ``roll_deg`` on the car, its forward axis along the velocity. A perfect IMU (rates at the
    sample times and increments), the truth at the samples. Defined here, independently of
    fusionbench.simulation.drive."""
    from pyins import sim, transform

    n = int(round(duration_s * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    x = np.clip(t / 20.0, 0.0, 1.0)
    speed = 10.0 * x**3 * (10 - 15 * x + 6 * x**2)  # a smooth start: zero velocity, acceleration and jerk at 0
    rate = np.zeros(n)  # heading rate, deg/s
    for k, t0 in enumerate(np.arange(30.0, duration_s - 10.0, 30.0)):
        inside = (t >= t0) & (t < t0 + 10.0)
        rate[inside] += (-1) ** k * 4.0 * (1 - np.cos(2 * np.pi * (t[inside] - t0) / 10.0))  # 40 deg per turn
    heading = heading_deg + np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) / rate_hz)])
    h = np.radians(heading)
    vel_ned = np.column_stack([speed * np.cos(h), speed * np.sin(h), np.zeros(n)])
    rph = np.column_stack([np.full(n, roll_deg), np.full(n, pitch_deg), heading])
    traj, rate_out = sim.generate_imu(t, [lat_deg, lon_deg, height_m], rph, vel_ned, sensor_type="rate")
    _, inc = sim.generate_imu(t, [lat_deg, lon_deg, height_m], rph, vel_ned, sensor_type="increment")
    cols_g, cols_a = ["gyro_x", "gyro_y", "gyro_z"], ["accel_x", "accel_y", "accel_z"]
    C_bn = P @ transform.mat_from_rph(rph) @ P
    return Drive(t, rate_out[cols_g].to_numpy() @ P, rate_out[cols_a].to_numpy() @ P,
                 inc[cols_g].to_numpy()[1:] @ P, inc[cols_a].to_numpy()[1:] @ P, C_bn, lat_deg, lon_deg, height_m,
                 lla=traj[["lat", "lon", "alt"]].to_numpy(), v_enu=traj[["VN", "VE", "VD"]].to_numpy() @ P,
                 trajectory=traj, heading_rate=np.radians(rate))
