"""The least-squares tracking differentiator of eso-td's default configuration (:mod:`adrc.moving_base`, ``td="ls"``):
a straight line fitted through all the samples so far, its slope the derivative, with a memory that grows with the
data instead of a fixed filter factor (or fades, ``forget`` < 1). Units are the caller's (Y per X)."""

from __future__ import annotations

import numpy as np


class LeastSquaresDifferentiator:
    """Least-squares line Y = a + b X through all the samples so far (or with a fading memory), batched.

    The tracking differentiator of the default configuration: x1 = a + b X (the fitted value at the
    latest X) tracks Y, and b = dY/dX is its derivative, with a memory that grows with the data instead
    of a fixed filter factor (see the module docstring). ``forget`` < 1 weighs a sample k steps old by
    forget^k (a fading memory of h / (1 - forget) seconds).

    Parameters
    ----------
    shape : tuple
        Batch shape.
    forget : float
        Forgetting factor per sample, in (0, 1] (1: growing memory).
    """

    def __init__(self, shape, forget=1.0):
        self.forget = float(forget)
        self.S = np.zeros((5,) + tuple(shape))  # sums of 1, x, x^2, y, x y (x, y relative to the first sample)
        self.origin = None

    @property
    def count(self):
        """Weighted number of samples."""
        return self.S[0]

    def add(self, X, Y):
        """Add the sample (X, Y)."""
        X, Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
        if self.origin is None:
            self.origin = (X.copy(), Y.copy())
        x, y = X - self.origin[0], Y - self.origin[1]
        self.S = self.forget * self.S + np.stack([np.ones_like(x), x, x * x, y, x * y])

    def fit(self, X):
        """(value at X, slope b) of the least-squares line (NaN with fewer than two distinct X)."""
        S0, S1, S2, Sy, Sxy = self.S
        det = S0 * S2 - S1 * S1
        with np.errstate(invalid="ignore", divide="ignore"):
            b = np.where(det > 0, (S0 * Sxy - S1 * Sy) / det, 0.0)
            a = np.where(S0 > 0, (Sy - b * S1) / S0, 0.0)
        return a + b * (np.asarray(X) - self.origin[0]) + self.origin[1], b

    def shift(self, d_value, d_slope, X):
        """Move every stored Y by the line that changes the value at X by ``d_value`` and the slope by
        ``d_slope`` (exact: the fit moves by that line)."""
        alpha = d_value - d_slope * (np.asarray(X) - self.origin[0])
        S0, S1, S2 = self.S[0], self.S[1], self.S[2]
        self.S[3] = self.S[3] + alpha * S0 + d_slope * S1
        self.S[4] = self.S[4] + alpha * S1 + d_slope * S2
