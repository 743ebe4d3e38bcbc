"""The factor graph's figures (:mod:`baselines.factor_graph`): the IMU noise densities, bias priors and bias walk
from an IMU model, their floors, and the sigmas of the priors on what no row fixes.

Units: gyro rad/s (noise rad/sqrt(s)), accelerometer m/s^2 (noise m/s/sqrt(s)), velocities m/s, positions m.
The reasons for each figure: ``docs/methods/gtsam.md`` ("The IMU model").
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import units
from fusionbench.simulation.imu import IMUSpec

#: Smallest reference noise used, m/s: an exact reference still gives well-conditioned velocity factors.
VREF_SIGMA_FLOOR = 1e-3
#: Sigma of a prior on an axis that rows fix, m or m/s: no information.
UNFIXED_SIGMA = 1e6
#: Sigma of the prior on the first velocity on an axis that no row measures (a vertical), m/s: a road's climb.
UNMEASURED_VELOCITY_SIGMA = 1.0

#: Defaults without an IMU model (``imu=None``): white noise of the seed000 preset ("Zhou 2011"),
#: bias-prior sigmas ten times (gyro) and three times (accelerometer) seed000's biases.
GYRO_NOISE = 0.005 * units.DEG_PER_SQRT_H       # rad/sqrt(s)
ACCEL_NOISE = 6.0 * units.UG_PER_SQRT_HZ        # m/s/sqrt(s)
GYRO_BIAS_SIGMA = 0.1 * units.DEG_PER_H         # rad/s, 10 x seed000's 0.01 deg/h
ACCEL_BIAS_SIGMA = 100.0 * units.UG             # m/s^2, above seed000's 30 ug
#: Floors of the white-noise densities taken from an IMUSpec: a zero datasheet figure would make the preintegrated
#: covariance singular. (The bias priors' floors are the IMU model's:
#: :meth:`fusionbench.simulation.imu.IMUSpec.bias_prior_sigma`.)
GYRO_NOISE_FLOOR = 1e-5 * units.DEG_PER_SQRT_H
ACCEL_NOISE_FLOOR = 0.1 * units.UG_PER_SQRT_HZ


def noise_model(spec):
    """The graph's IMU noise figures from an IMU model (``docs/methods/gtsam.md``, "The IMU model").

    Parameters
    ----------
    spec : IMUSpec or None
        The sensor model; None gives the defaults (seed000's white noise, bias priors 0.1 deg/h and
        100 ug, constant bias).

    Returns
    -------
    dict
        ``gyro_noise`` (3,) rad/sqrt(s), ``accel_noise`` (3,) m/s/sqrt(s) (white-noise densities,
        floored); ``gyro_bias_sigma`` (3,) rad/s and ``accel_bias_sigma`` (3,) m/s^2: the zero-mean
        bias priors, ``sqrt(bias^2 + bias_sigma^2 + instability^2)`` per axis (the fixed bias is a
        figure whose sign the estimator does not know, so it counts as a spread), floored
        (:meth:`fusionbench.simulation.imu.IMUSpec.bias_prior_sigma`);
        ``gyro_bias_walk`` (3,) rad/s/sqrt(s) and ``accel_bias_walk`` (3,) m/s^2/sqrt(s): the
        bias's random walk, ``sqrt(random_walk^2 + 2 instability^2 / tau)`` (the Kalman aligner's
        process noise; zero for a constant bias); ``name``, the model's name.
    """
    if spec is None:
        return {"gyro_noise": np.full(3, GYRO_NOISE), "accel_noise": np.full(3, ACCEL_NOISE),
                "gyro_bias_sigma": np.full(3, GYRO_BIAS_SIGMA), "accel_bias_sigma": np.full(3, ACCEL_BIAS_SIGMA),
                "gyro_bias_walk": np.zeros(3), "accel_bias_walk": np.zeros(3), "name": "default"}
    if not isinstance(spec, IMUSpec):
        raise ValueError(f"imu: expected a fusionbench.simulation.imu.IMUSpec or None, found {type(spec).__name__}")
    out = {"name": spec.name}
    for sensor, e, noise_floor in (("gyro", spec.gyro, GYRO_NOISE_FLOOR), ("accel", spec.accel, ACCEL_NOISE_FLOOR)):
        out[f"{sensor}_noise"] = np.maximum(np.asarray(e.white), noise_floor)
        out[f"{sensor}_bias_walk"] = e.bias_walk()
    out["gyro_bias_sigma"], out["accel_bias_sigma"] = spec.bias_prior_sigma()
    return out


def _scalar_or_axes(x):
    """A float when the three axes agree, else the (3,) array."""
    x = np.asarray(x, dtype=float)
    return float(x[0]) if np.all(x == x[0]) else x.copy()


#: Walk of a bias the model holds constant beside others that walk, per sqrt(s), as a fraction of its prior: 1e-3 of
#: the prior over an hour.
STILL_WALK = 1e-3 / np.sqrt(3600.0)
