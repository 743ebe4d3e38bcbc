"""Prior standard deviations of the 45 states: the filter's starting covariance (:mod:`baselines.rolling.ekf`)
and the scaling of the information matrices (:mod:`baselines.rolling.observability`), so that one unit of a scaled
state is one prior standard deviation in both."""

from __future__ import annotations

import numpy as np

from . import model

#: Prior standard deviation of each coefficient group in its customary unit (filter starts at zero),
#: and of the attitude angles (deg): wide enough for seed 002's (Ding, rolling-platform self-calibration) Table 1
#: spreads and a coarse start.
PRIOR_SIGMA = {"D0": 2.0, "D1": 2.0, "D2": 0.5, "GYRO_MOUNT": 300.0, "K0": 1000.0, "K1": 1000.0, "K2": 50.0,
               "ACCEL_MOUNT": 300.0, "KT": 1000.0}
ANGLE_SIGMA_DEG = 5.0


def prior_sigma(angle_sigma_deg=ANGLE_SIGMA_DEG, groups=None):
    """Prior standard deviations of the 45 states, SI (from :data:`PRIOR_SIGMA` in customary units).

    Parameters
    ----------
    angle_sigma_deg : float
        Of the attitude angles phi, theta, psi, deg.
    groups : dict, optional
        Overrides of :data:`PRIOR_SIGMA` by group name (customary units).

    Returns
    -------
    ndarray, shape (45,)
        The 42 coefficients in their SI units (:data:`baselines.rolling.model.COEFF_UNITS`), then the angles in rad.
    """
    groups = {**PRIOR_SIGMA, **(groups or {})}
    sig = np.empty(model.N_STATES)
    for name, val in groups.items():
        sl = getattr(model, name)
        sig[sl] = val * model.COEFF_SCALE[sl]
    sig[model.ANGLES] = np.radians(angle_sigma_deg)
    return sig
