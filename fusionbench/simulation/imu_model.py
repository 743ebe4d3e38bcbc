"""The IMU error model (:class:`SensorErrors`, :class:`IMUSpec`), noise schedules, the velocity reference's noise
and the sensor presets; the simulator that applies them is :mod:`fusionbench.simulation.imusim`, the spec files
:mod:`fusionbench.simulation.imu`.

Error model, per sensor triad (gyro or accelerometer), body frame RFU, for sample k over ``dt``::

    y_k = (I + S + M) u_k + (b + b_gm(t_k) + b_rw(t_k)) dt + sqrt(q(t_k)) n_k

where ``u_k`` is the true increment (angle, rad, or velocity, m/s), ``S = diag(scale)``, ``M`` the
axis misalignment (off-diagonal), ``b`` a constant bias (fixed part plus a per-run draw),
``b_gm`` a first-order Gauss-Markov bias instability, ``b_rw`` a rate (or acceleration) random
walk, and ``n_k`` white noise with ``q = white^2 dt`` (``white`` the angle or velocity random
walk coefficient, rad/sqrt(s) or m/s/sqrt(s)) multiplied by any noise-schedule factor active at
``t_k``. Optional quantisation rounds the increments to counts and carries the remainder.

Randomness is seeded per run: run k of a Monte Carlo with seed s draws from
``SeedSequence(s, spawn_key=(k,))`` split into one stream per error source, so run k gives the
same numbers whether it is simulated alone or in a batch of any size, and whatever the chunk size.

Specs are SI. Customary units go through :mod:`fusionbench.simulation.units`, e.g.
``SensorErrors(bias=(0.01 * units.DEG_PER_H,) * 3)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from fusionbench.simulation import units

__all__ = ["SensorErrors", "IMUSpec", "NoiseSchedule", "VelocityReferenceSpec", "PRESETS", "BIAS_PRIOR_FLOOR"]


def _vec3(x, name):
    a = np.broadcast_to(np.asarray(x, dtype=float), (3,))
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected finite numbers, found {a.tolist()}")
    return tuple(float(v) for v in a)


@dataclass(frozen=True)
class SensorErrors:
    """Errors of one sensor triad, SI units (rad-based for gyros, m/s-based for accelerometers).

    Parameters
    ----------
    bias : (3,) float
        Fixed constant bias: rad/s (gyro) or m/s^2 (accel).
    bias_sigma : (3,) float
        Standard deviation of a per-run constant bias drawn at the start of each run, same units.
    white : (3,) float
        White-noise density: angle random walk rad/sqrt(s) (gyro) or velocity random walk
        m/s/sqrt(s) = m/s^2/sqrt(Hz) (accel).
    instability : (3,) float
        Steady-state sigma of a first-order Gauss-Markov bias, rad/s or m/s^2.
    tau : float
        Its correlation time, s.
    random_walk : (3,) float
        Rate random walk rad/s/sqrt(s) (gyro) or acceleration random walk m/s^2/sqrt(s).
    scale : (3,) float
        Fixed scale-factor error (dimensionless; 90 ppm = 90e-6).
    scale_sigma : (3,) float
        Per-run random scale-factor error sigma.
    misalignment : (3, 3) float
        Fixed axis misalignment (off-diagonal entries used), rad.
    misalignment_sigma : float
        Per-run random misalignment sigma for each off-diagonal entry, rad.
    quantum : float
        Increment quantum (rad or m/s per count); 0 for none.
    """

    bias: tuple = (0.0, 0.0, 0.0)
    bias_sigma: tuple = (0.0, 0.0, 0.0)
    white: tuple = (0.0, 0.0, 0.0)
    instability: tuple = (0.0, 0.0, 0.0)
    tau: float = 3600.0
    random_walk: tuple = (0.0, 0.0, 0.0)
    scale: tuple = (0.0, 0.0, 0.0)
    scale_sigma: tuple = (0.0, 0.0, 0.0)
    misalignment: tuple = ((0.0, 0.0, 0.0),) * 3
    misalignment_sigma: float = 0.0
    quantum: float = 0.0

    def __post_init__(self):
        for name in ("bias", "bias_sigma", "white", "instability", "random_walk", "scale", "scale_sigma"):
            object.__setattr__(self, name, _vec3(getattr(self, name), name))
        m = np.asarray(self.misalignment, dtype=float)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise ValueError(f"misalignment: expected a finite 3x3 matrix, found shape {m.shape}")
        object.__setattr__(self, "misalignment", tuple(map(tuple, m.tolist())))
        for name in ("bias_sigma", "white", "instability", "random_walk", "scale_sigma"):
            if min(getattr(self, name)) < 0:
                raise ValueError(f"{name}: expected non-negative values, found {getattr(self, name)}")
        if self.tau <= 0:
            raise ValueError(f"tau: expected a positive correlation time in s, found {self.tau}")

    def noise_free(self):
        """The same deterministic errors (fixed bias, scale, misalignment) without any random part."""
        return SensorErrors(bias=self.bias, scale=self.scale, misalignment=self.misalignment)

    def unknown_bias(self):
        """The bias an estimator does not know, per axis: ``sqrt(bias^2 + bias_sigma^2 + instability^2)`` (3,),
        rad/s (gyro) or m/s^2 (accel). The fixed bias counts as a spread: its sign is not known to the estimator."""
        return np.sqrt(np.square(self.bias) + np.square(self.bias_sigma) + np.square(self.instability))

    def bias_walk(self):
        """The bias's random walk a constant-plus-walk bias state needs, per axis: ``sqrt(random_walk^2 +
        2 instability^2 / tau)`` (3,), rad/s/sqrt(s) (gyro) or m/s^2/sqrt(s) (accel): the rate random walk plus the
        driving noise of the Gauss-Markov instability; zero for a constant bias."""
        return np.sqrt(np.square(self.random_walk) + 2.0 * np.square(self.instability) / self.tau)


@dataclass(frozen=True)
class NoiseSchedule:
    """White-noise PSD multiplied by ``factor`` for ``start <= t < end`` (s).

    ``factor = 100`` is seed 001's (Zhao 2007, ESO/TD alignment) "Q x 100": the noise standard deviation grows 10 times.
    ``sensors`` names which white noises it scales: ``"gyro"``, ``"accel"`` or both.
    """

    start: float
    end: float
    factor: float
    sensors: tuple = ("gyro", "accel")

    def __post_init__(self):
        if not (self.end > self.start and self.factor >= 0):
            raise ValueError(f"noise schedule: expected end > start and factor >= 0, found {self}")


def _psd_factor(t, schedules, sensor):
    f = np.ones_like(t)
    for s in schedules:
        if sensor in s.sensors:
            f = np.where((t >= s.start) & (t < s.end), f * s.factor, f)
    return f


#: The smallest bias-prior sigma an estimator gives a sensor (:meth:`IMUSpec.bias_prior_sigma`): 0.01 deg/h for the
#: gyros (rad/s), 10 ug for the accelerometers (m/s^2).
BIAS_PRIOR_FLOOR = {"gyro": 0.01 * units.DEG_PER_H, "accel": 10.0 * units.UG}


@dataclass(frozen=True)
class IMUSpec:
    """A complete IMU: gyro and accelerometer errors, noise schedules, a name and where it comes from."""

    gyro: SensorErrors = field(default_factory=SensorErrors)
    accel: SensorErrors = field(default_factory=SensorErrors)
    schedules: tuple = ()
    name: str = "custom"
    description: str = ""

    def noise_free(self):
        """Deterministic errors only (for tests against the theoretical limits)."""
        return replace(self, gyro=self.gyro.noise_free(), accel=self.accel.noise_free(), schedules=())

    def perfect(self):
        """An error-free IMU."""
        return IMUSpec(name=f"{self.name} (perfect)")

    def bias_prior_sigma(self):
        """Sigmas of the zero-mean bias priors an estimator gives this IMU: :meth:`SensorErrors.unknown_bias`
        floored at :data:`BIAS_PRIOR_FLOOR` (a zero datasheet figure must not freeze a bias state). Returns
        ``(gyro (3,) rad/s, accel (3,) m/s^2)``."""
        return (np.maximum(self.gyro.unknown_bias(), BIAS_PRIOR_FLOOR["gyro"]),
                np.maximum(self.accel.unknown_bias(), BIAS_PRIOR_FLOOR["accel"]))


def _spec(name, description, drift_dph, arw_dpsh, accel_bias_ug, vrw_ug_rthz, gyro_scale_ppm=0.0,
          accel_scale_ppm=0.0, drift_sigma_dph=0.0, accel_bias_sigma_ug=0.0, instab_dph=0.0,
          instab_ug=0.0, tau=3600.0):
    return IMUSpec(
        gyro=SensorErrors(bias=(drift_dph * units.DEG_PER_H,) * 3,
                          bias_sigma=(drift_sigma_dph * units.DEG_PER_H,) * 3,
                          white=(arw_dpsh * units.DEG_PER_SQRT_H,) * 3,
                          instability=(instab_dph * units.DEG_PER_H,) * 3, tau=tau,
                          scale=(gyro_scale_ppm * units.PPM,) * 3),
        accel=SensorErrors(bias=(accel_bias_ug * units.UG,) * 3,
                           bias_sigma=(accel_bias_sigma_ug * units.UG,) * 3,
                           white=(vrw_ug_rthz * units.UG_PER_SQRT_HZ,) * 3,
                           instability=(instab_ug * units.UG,) * 3, tau=tau,
                           scale=(accel_scale_ppm * units.PPM,) * 3),
        name=name, description=description)


#: Sensor presets. ``seed000``/``seed001``/``seed004`` are the papers' simulated IMUs; the grades are
#: typical catalogue figures (navigation: ring-laser class; tactical: FOG class; MEMS: consumer).
PRESETS = {
    "seed000": _spec("seed000", "Zhou 2011: drift 0.01 deg/h, ARW 0.005 deg/sqrt(h), 90 ppm; "
                     "bias 30 ug, 6 ug/sqrt(Hz), 70 ppm", 0.01, 0.005, 30.0, 6.0, 90.0, 70.0),
    "seed001": _spec("seed001", "Zhao 2007: drift 0.01 deg/h + 0.005 deg/h random; bias 100 ug + 50 ug "
                     "random", 0.01, 0.0, 100.0, 0.0, drift_sigma_dph=0.005, accel_bias_sigma_ug=50.0),
    "seed004": _spec("seed004", "Gu 2017: drift 0.01 deg/h, random walk 0.05 deg/sqrt(h); bias 50 ug, "
                     "random 50 ug*sqrt(s)", 0.01, 0.05, 50.0, 50.0),
    "navigation": _spec("navigation", "navigation grade: 0.005 deg/h, 0.002 deg/sqrt(h), 25 ug, "
                        "5 ug/sqrt(Hz)", 0.005, 0.002, 25.0, 5.0, 5.0, 20.0, instab_dph=0.002,
                        instab_ug=5.0),
    "tactical": _spec("tactical", "tactical grade: 1 deg/h, 0.1 deg/sqrt(h), 300 ug, 50 ug/sqrt(Hz)",
                      1.0, 0.1, 300.0, 50.0, 100.0, 300.0, instab_dph=0.5, instab_ug=50.0, tau=600.0),
    "mems": _spec("mems", "MEMS consumer grade: 10 deg/h, 0.3 deg/sqrt(h), 2 mg, 100 ug/sqrt(Hz)",
                  10.0, 0.3, 2000.0, 100.0, 1000.0, 1000.0, instab_dph=5.0, instab_ug=200.0, tau=300.0),
    "ideal": _spec("ideal", "no errors: the start of a spec that gives every figure itself (fusionbench identify "
                   "writes one)", 0.0, 0.0, 0.0, 0.0),
}


@dataclass(frozen=True)
class VelocityReferenceSpec:
    """Noise of the external velocity reference (zero-velocity on a static base, or a GNSS/log velocity).

    Parameters
    ----------
    sigma : (3,) float
        White-noise standard deviation of each reference sample, ENU, m/s.
    schedules : tuple of NoiseSchedule
        Variance multiplied by ``factor`` inside each window (the seed-001 "R x 100"); the
        ``sensors`` field is ignored here.
    """

    sigma: tuple = (0.0, 0.0, 0.0)
    schedules: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "sigma", _vec3(self.sigma, "vref sigma"))
