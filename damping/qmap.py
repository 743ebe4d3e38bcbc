"""The acceleration -> q map of seed 004 (Gu 2017, adaptive Schuler damping) (Fig. 6, eqs. 11-12), as a scikit-learn RBF
regressor.

Training data come from the network itself (:mod:`damping.network`): the peak attitude error of the
north loop for a step of acceleration ``a`` is linear in ``a`` (eq. 2 is linear), so with
``e1(q)`` the peak for 1 m/s^2 (simulated with the actual H(s), :func:`damping.network.simulated_peak_error`)
the largest q that keeps the error at or under ``max_error`` (0.03 deg in the paper) solves
``a e1(q) = max_error``; e1 grows with q (more damping, more acceleration error), so q*(a) falls
with a. Targets are clipped to [1, 8], the network's range.

The model is a Pipeline of a standard scaler and kernel ridge regression with an RBF kernel on
log10(a) (accelerations span decades), its alpha and gamma chosen by cross-validation; its output
is clipped to [1, 7] (eq. 12). Input accelerations are validated: finite, non-negative, at most
``MAX_ACCEL`` (m/s^2); below ``MIN_ACCEL`` the map returns its value at ``MIN_ACCEL``.
"""

from __future__ import annotations

import io as _io
from functools import lru_cache

import joblib
import numpy as np
from sklearn.kernel_ridge import KernelRidge
from sklearn.model_selection import GridSearchCV, train_test_split
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from fusionbench.files.imufiles import atomic_open
from fusionbench.simulation.units import DEG

from .network import simulated_peak_error

#: Accepted accelerations, m/s^2.
MIN_ACCEL, MAX_ACCEL = 1e-4, 10.0
#: Output clip of eq. 12.
Q_MIN, Q_MAX = 1.0, 7.0


def unit_peak_error(q_grid):
    """Peak attitude error (rad) for a 1 m/s^2 step of acceleration at each q of ``q_grid``."""
    return np.array(_unit_peak_error(tuple(float(q) for q in q_grid)))


@lru_cache(maxsize=8)
def _unit_peak_error(q_grid):  # one lsim of 3 h per q: cached, the map and its figure share it
    return tuple(simulated_peak_error(1.0, q) for q in q_grid)


def training_data(accels, max_error=0.03 * DEG, q_grid=None):
    """(accels, q*) with q* the largest q in [1, 8] keeping the peak error at or under ``max_error`` (rad),
    clipped to eq. 12's [1, 7] (the map is only ever used clipped)."""
    q_grid = np.linspace(1.0, 8.0, 57) if q_grid is None else np.asarray(q_grid, dtype=float)
    e1 = unit_peak_error(q_grid)  # increasing in q
    target = max_error / np.asarray(accels, dtype=float)  # the e1 each acceleration allows
    q = np.interp(target, e1, q_grid, left=1.0, right=8.0)
    return np.asarray(accels, dtype=float), np.clip(q, Q_MIN, Q_MAX)


def check_accel(a, name="acceleration"):
    """Validated accelerations (m/s^2) as an array; ValueError naming ``name`` otherwise."""
    a = np.asarray(a, dtype=float)
    bad = ~np.isfinite(a) | (a < 0) | (a > MAX_ACCEL)
    if np.any(bad):
        raise ValueError(f"{name}: expected finite accelerations between 0 and {MAX_ACCEL:g} m/s^2, "
                         f"found {a[bad].ravel()[:3].tolist()}")
    return np.maximum(a, MIN_ACCEL)


def default_accels(n=240):
    """The training grid: ``n`` accelerations log-spaced over [1e-3, 0.3] m/s^2 (Fig. 6's range and beyond)."""
    return np.logspace(-3.0, np.log10(0.3), n)


class QMap:
    """Acceleration (m/s^2) -> network coefficient q, an RBF kernel regressor fitted to :func:`training_data`."""

    def __init__(self, model=None, accel_range=(MIN_ACCEL, MAX_ACCEL)):
        self.model = model
        self.mse_ = None
        self.range_ = tuple(accel_range)

    def fit(self, accels, q, test_size=0.25, seed=0):
        """Fit with cross-validated alpha and gamma; the held-out MSE (q units^2) is ``mse_``."""
        accels = check_accel(accels)
        self.range_ = (float(accels.min()), float(accels.max()))
        x = np.log10(accels)[:, None]
        x_tr, x_te, y_tr, y_te = train_test_split(x, q, test_size=test_size, random_state=seed)
        pipe = Pipeline([("scale", StandardScaler()), ("krr", KernelRidge(kernel="rbf"))])
        grid = {"krr__alpha": [1e-10, 1e-8, 1e-6, 1e-4], "krr__gamma": [3.0, 10.0, 30.0, 100.0, 300.0]}
        search = GridSearchCV(pipe, grid, cv=5, scoring="neg_mean_squared_error").fit(x_tr, y_tr)
        self.model = search.best_estimator_
        self.mse_ = float(np.mean((self.model.predict(x_te) - y_te) ** 2))
        return self

    def q_net(self, a):
        """The regressor's raw output for accelerations ``a`` (m/s^2), held constant outside the training
        range (an RBF model relaxes to its mean away from its data, which would be wrong there)."""
        a = np.clip(check_accel(a), *self.range_)
        return self.model.predict(np.log10(a).reshape(-1, 1)).reshape(np.shape(a))

    def __call__(self, a):
        """q for accelerations ``a`` (m/s^2), clipped to [1, 7] (eq. 12)."""
        return np.clip(self.q_net(a), Q_MIN, Q_MAX)

    def save(self, path):
        """Write the map with joblib, atomically."""
        buf = _io.BytesIO()
        joblib.dump({"model": self.model, "mse": self.mse_, "range": self.range_}, buf)
        with atomic_open(path, binary=True) as fh:
            fh.write(buf.getvalue())

    @classmethod
    def load(cls, path):
        """Read a map written by :meth:`save`."""
        d = joblib.load(path)
        out = cls(d["model"], d["range"])
        out.mse_ = d["mse"]
        return out
