"""A bank of independent linear Kalman filters, one per Monte Carlo run, with filterpy's arithmetic.

:class:`FilterBank` holds R filters of the same layout (state dimension n, measurement dimension m) and
steps them together. Two engines do the same arithmetic as :class:`filterpy.kalman.KalmanFilter`
(``predict``: x = F x, P = F P F^T + Q; ``update``: y = z - H x, S = H P H^T + R, K = P H^T S^-1,
x = x + K y, P = (I - K H) P (I - K H)^T + K R K^T, the Joseph form):

``"numpy"`` (default)
    arrays with a leading run axis, so a step costs a few NumPy calls whatever the number of runs;
``"filterpy"``
    one filterpy ``KalmanFilter`` per run, the reference the tests compare the first with.

Arrays: ``x`` (R, n), ``P`` (R, n, n), ``R`` (R, m, m); ``F``, ``Q`` given per step as (R, n, n). An update may bring
its own ``H`` (q, n) or (R, q, n) and ``R`` (q, q) or (R, q, q), of any dimension q: measurements whose number
and model change from step to step (aiding rows at their own epochs), as filterpy's ``update(z, R, H)`` takes them.
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
    H : ndarray, shape (m, n), optional
        Measurement matrix, the same for every run (None: every update brings its own).
    R : ndarray, shape (m, m), optional
        Initial measurement noise covariance, the same for every run (per-run values via :attr:`R`; None: every
        update brings its own).
    engine : {"numpy", "filterpy"}
    """

    def __init__(self, runs, P0, H=None, R=None, engine="numpy"):
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, found {engine!r}")
        P0 = np.asarray(P0, dtype=float)
        P0 = np.diag(P0) if P0.ndim == 1 else P0
        self.engine = engine
        self.n = P0.shape[0]
        self.H = np.zeros((0, self.n)) if H is None else np.asarray(H, dtype=float)
        self.m = self.H.shape[0]
        R = np.zeros((self.m, self.m)) if R is None else np.asarray(R, dtype=float)
        self._I = np.eye(self.n)
        if engine == "filterpy":
            self.filters = []
            for _ in range(runs):
                kf = KalmanFilter(dim_x=self.n, dim_z=max(self.m, 1))
                kf.P = P0.copy()
                kf.H = self.H.copy()
                kf.R = R.copy()
                self.filters.append(kf)
        else:
            self._x = np.zeros((runs, self.n))
            self._P = np.broadcast_to(P0, (runs, self.n, self.n)).copy()
            self._R = np.broadcast_to(R, (runs, self.m, self.m)).copy()

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

    def update(self, z, H=None, R=None):
        """Measurement update with z (R, q), Joseph form; ``H`` (q, n) or (R, q, n) and ``R`` (q, q) or (R, q, q)
        for this update only (None: the bank's :attr:`H` and :attr:`R`)."""
        runs = z.shape[0]
        H = self.H if H is None else np.asarray(H, dtype=float)
        Hr = np.broadcast_to(H, (runs,) + H.shape[-2:])
        if self.engine == "filterpy":
            Rr = [None] * runs if R is None else np.broadcast_to(R, (runs,) + np.shape(R)[-2:])
            for kf, zr, h, r in zip(self.filters, z, Hr, Rr):
                kf.update(zr[:, None], R=r, H=h)  # a column: filterpy 2 broadcasts a 1-D z silently
            return
        R = self._R if R is None else np.broadcast_to(np.asarray(R, dtype=float), (runs,) + np.shape(R)[-2:])
        HT = np.swapaxes(Hr, -1, -2)
        y = z - np.einsum("rqn,rn->rq", Hr, self._x)
        PHT = self._P @ HT
        S = Hr @ PHT + R
        K = PHT @ np.linalg.inv(S)
        self._x = self._x + np.einsum("rij,rj->ri", K, y)
        I_KH = self._I - K @ Hr
        self._P = I_KH @ self._P @ np.swapaxes(I_KH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)

    def reset_x(self):
        """Set every state to zero (after its estimate was fed back); the covariances are kept."""
        if self.engine == "filterpy":
            for kf in self.filters:
                kf.x[:] = 0.0
        else:
            self._x[:] = 0.0
