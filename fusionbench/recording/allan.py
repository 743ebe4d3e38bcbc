"""Overlapping Allan deviation of each gyro and accelerometer axis of one IMU record, with confidence intervals.

The deviation is :func:`allantools.oadev` of the *phase* data, here the cumulative angle (rad) or velocity (m/s)
increments: for an ``"increment"`` record that is exact (the increments are the integrals of the rate), for a
``"rate"`` record each sample is taken as the mean over the interval that ends at it (``rate * dt``), so a rate
record and the increment record it was made from give the same deviation. The mean rate (earth rate, gravity,
biases) is removed first: a linear phase trend has no Allan variance, and keeping it costs precision.

Averaging times are octaves of the sample interval, ``tau = m dt`` with ``m = 1, 2, 4, ...`` up to a quarter of
the record (:data:`STOP_RATIO`, as Stable32 and NIST SP 1065 do for the overlapping deviation; longer ones rest
on fewer than ~3 degrees of freedom). The confidence interval of each point is a chi-square interval
(:func:`allantools.confidence_interval`) with Greenhall's equivalent degrees of freedom
(:func:`allantools.edf_greenhall`), which depend on the power-law noise type at that tau: :func:`allan` takes it
from the local log-log slope of the curve (:func:`noise_types_from_slope`); the fit of
:mod:`fusionbench.recording.allanfit` replaces it with the type of the term that dominates its model there
(:func:`with_noise_types`).

Units are SI: gyro deviations rad/s, accelerometer m/s^2, tau s; axes are the body frame (x right, y forward,
z up).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import allantools
import numpy as np

from fusionbench.simulation.imudata import IMUData

__all__ = ["AllanCurve", "AllanSet", "STOP_RATIO", "ALPHA_NAMES", "octave_factors", "allan_curve",
           "noise_types_from_slope", "with_noise_types", "edf", "phases", "allan"]

#: The longest averaging factor is the number of phase points divided by this (Stable32's stop ratio for oadev).
STOP_RATIO = 4
#: Power-law noise types by their rate-PSD exponent alpha (S(f) ~ f^alpha), as allantools numbers them.
ALPHA_NAMES = {2: "white phase (quantisation)", 0: "white rate (random walk)", -1: "flicker rate (bias instability)",
               -2: "random-walk rate"}


@dataclass(frozen=True)
class AllanCurve:
    """The overlapping Allan deviation of one axis.

    Attributes
    ----------
    tau : ndarray, shape (M,)
        Averaging times, s (octaves of the sample interval).
    m : ndarray of int, shape (M,)
        Averaging factors, ``tau = m dt``.
    adev : ndarray, shape (M,)
        Overlapping Allan deviation, rad/s (gyro) or m/s^2 (accelerometer).
    lo, hi : ndarray, shape (M,)
        The 68.3 % (1-sigma) confidence interval of ``adev``, same unit.
    edf : ndarray, shape (M,)
        Equivalent degrees of freedom of each estimate (Greenhall).
    alpha : ndarray of int, shape (M,)
        Noise type assumed for ``edf`` (:data:`ALPHA_NAMES`).
    n_phase : int
        Number of phase points (samples + 1).
    """

    tau: np.ndarray
    m: np.ndarray
    adev: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray
    n_phase: int

    @property
    def avar(self):
        """Allan variance, (rad/s)^2 or (m/s^2)^2."""
        return self.adev ** 2

    @property
    def avar_sd(self):
        """Standard deviation of the Allan variance estimate of a chi-square with ``edf`` degrees of freedom,
        relative to the variance: ``sqrt(2 / edf)``."""
        return np.sqrt(2.0 / self.edf)


@dataclass(frozen=True)
class AllanSet:
    """The Allan deviation of every axis of one record.

    Attributes
    ----------
    gyro, accel : tuple of 3 AllanCurve
        Body axes x, y, z; rad/s and m/s^2.
    dt : float
        Sample interval, s.
    samples : int
        Number of samples (intervals) of the record.
    kind : {"increment", "rate"}
        The record's kind.
    """

    gyro: tuple
    accel: tuple
    dt: float
    samples: int
    kind: str

    @property
    def duration(self):
        """Length of the record, s."""
        return self.samples * self.dt


def octave_factors(n_phase):
    """Averaging factors ``1, 2, 4, ...`` up to ``(n_phase - 1) / STOP_RATIO`` (int array, possibly empty)."""
    top = (n_phase - 1) // STOP_RATIO
    return 2 ** np.arange(int(np.floor(np.log2(top))) + 1) if top >= 1 else np.zeros(0, dtype=int)


@lru_cache(maxsize=4096)
def _edf(alpha, m, n_phase):
    return float(allantools.edf_greenhall(alpha, 2, m, n_phase, overlapping=True))


def edf(m, n_phase, alpha):
    """Greenhall's equivalent degrees of freedom (M,) of the overlapping Allan variance at factors ``m`` (M,) of a
    record of ``n_phase`` phase points, for noise types ``alpha`` (M,) (:data:`ALPHA_NAMES`)."""
    return np.array([_edf(int(a), int(k), int(n_phase)) for a, k in zip(alpha, m)])


def _edf_ci(adev, m, n_phase, alpha):
    e = edf(m, n_phase, alpha)
    lo, hi = np.transpose([allantools.confidence_interval(d, v) for d, v in zip(adev, e)])
    return e, lo, hi


def noise_types_from_slope(tau, adev):
    """Power-law noise type at each tau from the local slope of log Allan variance against log tau (a straight-line
    fit over the point and its neighbours): slope -2 is white phase (alpha 2), -1 white rate (0), 0 flicker rate
    (-1), +1 or more random-walk rate (-2; steeper ramps are counted as random walk, the steepest type
    Greenhall's degrees of freedom cover)."""
    tau, adev = np.asarray(tau, float), np.asarray(adev, float)
    lt, lv = np.log(tau), 2.0 * np.log(np.maximum(adev, np.finfo(float).tiny))
    out = np.zeros(tau.size, dtype=int)
    for i in range(tau.size):
        j = slice(max(0, i - 1), min(tau.size, i + 2))
        slope = np.polyfit(lt[j], lv[j], 1)[0] if lt[j].size > 1 else -1.0
        out[i] = 2 if slope < -1.5 else int(np.clip(np.round(-slope - 1.0), -2, 0))
    return out


def with_noise_types(curve, alpha):
    """``curve`` with its degrees of freedom and confidence interval recomputed for noise types ``alpha`` (M,)."""
    alpha = np.asarray(alpha, dtype=int)
    edf, lo, hi = _edf_ci(curve.adev, curve.m, curve.n_phase, alpha)
    return replace(curve, edf=edf, lo=lo, hi=hi, alpha=alpha)


def allan_curve(phase, dt):
    """Overlapping Allan deviation of one axis at octave taus.

    Parameters
    ----------
    phase : ndarray, shape (N + 1,)
        Cumulative increments, rad or m/s (the integral of the rate, any offset).
    dt : float
        Sample interval, s.

    Returns
    -------
    AllanCurve
        Deviation in rad/s or m/s^2, confidence from the slope-based noise types.
    """
    phase = np.asarray(phase, dtype=float)
    m = octave_factors(phase.size)
    tau, adev, _, _ = allantools.oadev(phase, rate=1.0 / dt, data_type="phase", taus=m * dt)
    m = np.round(np.asarray(tau) / dt).astype(int)
    adev = np.asarray(adev, dtype=float)
    curve = AllanCurve(np.asarray(tau, float), m, adev, adev, adev, np.zeros(m.size), np.zeros(m.size, int), phase.size)
    return with_noise_types(curve, noise_types_from_slope(curve.tau, adev))


def phases(imu: IMUData, run=0):
    """Cumulative gyro (rad) and accelerometer (m/s) increments of run ``run``, mean rate removed, each (N + 1, 3)
    starting at 0."""
    g, a = imu.rates()
    dt = imu.dt
    out = []
    for r in (g[run], a[run]):
        inc = (r - r.mean(axis=0)) * dt
        out.append(np.vstack([np.zeros((1, 3)), np.cumsum(inc, axis=0)]))
    return out[0], out[1]


def allan(imu: IMUData, run=0):
    """Overlapping Allan deviation of each gyro and accelerometer axis of run ``run`` of ``imu``.

    Returns
    -------
    AllanSet
        Gyro deviations rad/s, accelerometer m/s^2, per body axis x, y, z.
    """
    gp, ap = phases(imu, run)
    dt = imu.dt
    return AllanSet(tuple(allan_curve(gp[:, j], dt) for j in range(3)),
                    tuple(allan_curve(ap[:, j], dt) for j in range(3)), dt, imu.samples, imu.kind)
