"""Static records with known IEEE-952 terms, shared by the tests of fusionbench identify.

White noise, random walks and quantisation by :func:`fusionbench.simulation.imu.simulate` on a static base; bias
instability as true flicker noise made here, independently of the library: the rate of a continuous process of
two-sided PSD B^2 / (2 pi f) (IEEE 952, annex C) averaged over each sample, built by FFT from its exact discrete-time
spectrum (the continuous one aliased through the averaging), and checked (``tests/test_identify.py``) to have the
Allan variance (2 ln2 / pi) B^2 of the definition.
"""

import math

import numpy as np

from fusionbench.simulation import imu, imudata, trajectory as tj, units

DT = 0.1
DEG = math.pi / 180

GYRO_N = 0.3 * units.DEG_PER_SQRT_H
ACCEL_N = 50 * units.UG_PER_SQRT_HZ


def _static(duration):
    return tj.Trajectory(34 * DEG, 108 * DEG, 100.0, tj.EulerSway(mean=(1 * DEG, -2 * DEG, 30 * DEG)), duration=duration)


def _flicker_psd(f, dt, b, aliases=30):
    """Two-sided PSD at ``f`` (Hz, within Nyquist) of dt-averages of a rate with two-sided PSD b^2 / (2 pi |f|)."""
    out = np.zeros_like(f)
    for k in range(-aliases, aliases + 1):
        fk = np.abs(f + k / dt)
        out += b ** 2 / (2 * np.pi * fk) * np.sinc(fk * dt) ** 2
    return out


def _flicker(rng, n, dt, b, extra=8):
    """(n, 3) flicker rate samples, generated over ``extra`` times the record so that its lowest frequencies are
    there too."""
    m = n * extra
    f = np.fft.rfftfreq(m, dt)
    amp = np.zeros_like(f)
    amp[1:] = np.sqrt(_flicker_psd(f[1:], dt, b) / dt)  # unit white noise has two-sided PSD dt
    return np.fft.irfft(np.fft.rfft(rng.standard_normal((m, 3)), axis=0) * amp[:, None], n=m, axis=0)[:n]


def _record(n, gyro, accel, seed, gyro_b=0.0, accel_b=0.0, output="increment"):
    spec = imu.IMUSpec(gyro=imu.SensorErrors(**gyro), accel=imu.SensorErrors(**accel))
    data = imu.simulate(_static(n * DT), spec, DT, seed=seed, output=output)
    rng = np.random.default_rng(seed + 1000)
    per = DT if output == "increment" else 1.0
    g, a = data.gyro.copy(), data.accel.copy()
    if gyro_b:
        g[0] += _flicker(rng, n, DT, gyro_b) * per
    if accel_b:
        a[0] += _flicker(rng, n, DT, accel_b) * per
    return imudata.IMUData(data.t, g, a, output)
