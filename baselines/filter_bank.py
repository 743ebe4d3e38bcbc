"""A bank of independent linear Kalman filters, one per Monte Carlo run, with filterpy's arithmetic.

:class:`FilterBank` holds R filters of the same layout (state dimension n, measurement dimension m) and
steps them together. Two engines do the same arithmetic as :class:`filterpy.kalman.KalmanFilter`
(``predict``: x = F x, P = F P F^T + Q; ``update``: y = z - H x, S = H P H^T + R, K = P H^T S^-1,
x = x + K y, P = (I - K H) P (I - K H)^T + K R K^T, the Joseph form):

``"numpy"`` (default)
    arrays with a leading run axis, so a step costs a few NumPy calls whatever the number of runs;
``"filterpy"``
    one filterpy ``KalmanFilter`` per run, the reference the tests compare the first with.

Arrays: ``x`` (R, n), ``P`` (R, n, n), ``R`` (R, m, m); ``F``, ``Q`` given per step as (R, n, n).
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import KalmanFilter

ENGINES = ("numpy", "filterpy")


class FilterBank:
    """R Kalman filters of one layout, stepped together.

    Parameters
    ----------
    runs : int
        Number of filters R.
    P0 : ndarray, shape (n,) or (n, n)
        Initial covariance (a diagonal as a vector), the same for every run.
    H : ndarray, shape (m, n)
        Measurement matrix, the same for every run.
    R : ndarray, shape (m, m)
        Initial measurement noise covariance, the same for every run (per-run values via :attr:`R`).
    engine : {"numpy", "filterpy"}
    """

    def __init__(self, runs, P0, H, R, engine="numpy"):
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, found {engine!r}")
        P0 = np.asarray(P0, dtype=float)
        P0 = np.diag(P0) if P0.ndim == 1 else P0
        self.engine = engine
        self.H = np.asarray(H, dtype=float)
        self.n, self.m = P0.shape[0], self.H.shape[0]
        self._I = np.eye(self.n)
        if engine == "filterpy":
            self.filters = []
            for _ in range(runs):
                kf = KalmanFilter(dim_x=self.n, dim_z=self.m)
                kf.P = P0.copy()
                kf.H = self.H.copy()
                kf.R = np.array(R, dtype=float)
                self.filters.append(kf)
        else:
            self._x = np.zeros((runs, self.n))
            self._P = np.broadcast_to(P0, (runs, self.n, self.n)).copy()
            self._R = np.broadcast_to(np.asarray(R, dtype=float), (runs, self.m, self.m)).copy()

    # the state, covariances and measurement noise as (R, ...) arrays, whatever the engine
    @property
    def x(self):
        return np.stack([kf.x[:, 0] for kf in self.filters]) if self.engine == "filterpy" else self._x

    @property
    def P(self):
        return np.stack([kf.P for kf in self.filters]) if self.engine == "filterpy" else self._P

    @property
    def R(self):
        return np.stack([kf.R for kf in self.filters]) if self.engine == "filterpy" else self._R

    @R.setter
    def R(self, value):
        value = np.asarray(value, dtype=float)
        if self.engine == "filterpy":
            for kf, v in zip(self.filters, value):
                kf.R = v.copy()
        else:
            self._R[:] = value

    def predict(self, F, Q):
        """x = F x, P = F P F^T + Q with F, Q (R, n, n)."""
        if self.engine == "filterpy":
            for kf, f, q in zip(self.filters, F, Q):
                kf.predict(F=f, Q=q)
            return
        self._x = np.einsum("rij,rj->ri", F, self._x)
        self._P = F @ self._P @ np.swapaxes(F, -1, -2) + Q

    def update(self, z):
        """Measurement update with z (R, m), Joseph form."""
        if self.engine == "filterpy":
            for kf, zr in zip(self.filters, z):
                kf.update(zr[:, None])  # a column: filterpy 2 broadcasts a 1-D z silently
            return
        H, R = self.H, self._R
        y = z - self._x @ H.T
        PHT = self._P @ H.T
        S = H @ PHT + R
        K = PHT @ np.linalg.inv(S)
        self._x = self._x + np.einsum("rij,rj->ri", K, y)
        I_KH = self._I - K @ H
        self._P = I_KH @ self._P @ np.swapaxes(I_KH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)

    def reset_x(self):
        """Set every state to zero (after its estimate was fed back); the covariances are kept."""
        if self.engine == "filterpy":
            for kf in self.filters:
                kf.x[:] = 0.0
        else:
            self._x[:] = 0.0
