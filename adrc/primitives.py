"""Han's active disturbance rejection control primitives, discrete forms, vectorised over a batch.

Equation numbers are those of seed 000 (Zhou, Yang, Qin, Control and Decision 26(9), 2011), which
quotes Han (2007). Every function takes NumPy arrays (any common shape: Monte Carlo runs, channels)
and returns arrays of the broadcast shape; the classes keep their states as such arrays.

Units follow the plant: for a gyrocompass level channel the output y is a velocity error (m/s), the
control u a commanded angular rate (rad/s) and b0 = -g or +g (m/s^2 per rad).
"""

from __future__ import annotations

import numpy as np


def fhan(x1, x2, r, h, c=1.0):
    """Han's time-optimal synthesis function fhan(x1, c x2, r, h), eq. (8).

    Parameters
    ----------
    x1, x2 : array_like
        Position-like error and its rate.
    r : float or array_like
        Acceleration bound ("speed factor"), units of x1 / s^2.
    h : float or array_like
        Filter (precision) step, s.
    c : float or array_like
        Damping factor multiplying x2.

    Returns
    -------
    ndarray
        The acceleration that brings the double integrator x1'' = u, started at (x1, x2), to the
        origin fastest under |u| <= r in discrete steps h (negative when x1 is positive, at rest).
    """
    x1 = np.asarray(x1, dtype=float)
    d = r * h * h
    a0 = h * c * np.asarray(x2, dtype=float)
    y = x1 + a0
    a1 = np.sqrt(d * (d + 8.0 * np.abs(y)))
    a2 = a0 + np.sign(y) * (a1 - d) / 2.0
    sy = (np.sign(y + d) - np.sign(y - d)) / 2.0
    a = (a0 + y - a2) * sy + a2
    sa = (np.sign(a + d) - np.sign(a - d)) / 2.0
    return -r * (a / d - np.sign(a)) * sa - r * np.sign(a)


def fal(e, alpha, delta):
    """Han's nonlinear gain fal(e, alpha, delta), eq. (10): |e|^alpha sign(e) outside [-delta, delta],
    the linear e / delta^(1 - alpha) inside (same units as e^alpha)."""
    e = np.asarray(e, dtype=float)
    lin = e / delta ** (1.0 - alpha)
    return np.where(np.abs(e) > delta, np.abs(e) ** alpha * np.sign(e), lin)


class TrackingDifferentiator:
    """Second-order tracking differentiator, eq. (7): v1 follows the reference, v2 is its derivative.

    ``v1(k+1) = v1 + h v2``; ``v2(k+1) = v2 + h fhan(v1 - vr, c0 v2, r0, h0)``.

    Parameters
    ----------
    shape : tuple
        Batch shape of the states.
    h : float
        Step, s.
    r0 : float
        Acceleration bound of the transient, reference units / s^2.
    h0 : float
        fhan precision step, s.
    c0 : float
        fhan damping factor.
    """

    def __init__(self, shape, h, r0, h0, c0=1.0):
        self.h, self.r0, self.h0, self.c0 = h, r0, h0, c0
        self.v1 = np.zeros(shape)
        self.v2 = np.zeros(shape)

    def update(self, vr):
        """One step towards the reference ``vr``; returns (v1, v2)."""
        v1 = self.v1 + self.h * self.v2
        self.v2 = self.v2 + self.h * fhan(self.v1 - vr, self.v2, self.r0, self.h0, self.c0)
        self.v1 = v1
        return self.v1, self.v2


class ExtendedStateObserver:
    """Third-order nonlinear extended state observer, eq. (9).

    For a plant ``x'' = f + b u`` with output ``y = x``: z1 estimates x, z2 its rate, z3 the
    total disturbance f (model uncertainty and external disturbance together)::

        e = z1 - y;  fe = fal(e, 0.5, delta);  fe1 = fal(e, 0.25, delta)
        z1 <- z1 + h (z2 - beta01 e)
        z2 <- z2 + h (z3 - beta02 fe + b0 u)
        z3 <- z3 - h beta03 fe1

    Parameters
    ----------
    shape : tuple
        Batch shape.
    h : float
        Step, s.
    beta01, beta02, beta03 : float
        Observer gains.
    delta : float
        Linear zone of fal.
    b0 : array_like
        Estimate of b, broadcast against ``shape``.
    """

    def __init__(self, shape, h, beta01, beta02, beta03, delta, b0):
        self.h, self.beta01, self.beta02, self.beta03, self.delta = h, beta01, beta02, beta03, delta
        self.b0 = np.asarray(b0, dtype=float)
        self.z1 = np.zeros(shape)
        self.z2 = np.zeros(shape)
        self.z3 = np.zeros(shape)

    def update(self, y, u):
        """One step with measurement ``y`` and the control ``u`` applied over the last step."""
        e = self.z1 - y
        fe = fal(e, 0.5, self.delta)
        fe1 = fal(e, 0.25, self.delta)
        h = self.h
        z1 = self.z1 + h * (self.z2 - self.beta01 * e)
        z2 = self.z2 + h * (self.z3 - self.beta02 * fe + self.b0 * u)
        self.z3 = self.z3 - h * self.beta03 * fe1
        self.z1, self.z2 = z1, z2
        return self.z1, self.z2, self.z3


def nlsef(e1, e2, z3, b0, r1, h1, c1):
    """Nonlinear state error feedback with disturbance compensation, eq. (11), sign-corrected.

    ``u0 = -fhan(e1, c1 e2, r1, h1)`` and, as printed, ``u = u0 - z3 / b0``. With the plant
    ``x'' = f + b u`` and ``b0 = b`` this gives ``x'' = (f - z3) + b u0``: for b0 < 0 (the east
    level channel, b = -g) the printed law feeds u0 back with the wrong sign. The sign of b0 must
    reach u0, so this function returns ``u = sign(b0) u0 - z3 / b0`` (identical to the printed
    form when b0 > 0); the loop then obeys ``x'' = |b| u0`` in both channels.

    Parameters
    ----------
    e1, e2 : array_like
        Tracking errors v1 - z1 and v2 - z2.
    z3 : array_like
        Disturbance estimate.
    b0 : array_like
        Estimate of b.
    r1, h1, c1 : float
        fhan bound, step and damping of the feedback.
    """
    b0 = np.asarray(b0, dtype=float)
    u0 = -fhan(e1, e2, r1, h1, c1)
    return np.sign(b0) * u0 - z3 / b0
