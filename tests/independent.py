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
