"""Han's active disturbance rejection control primitives, discrete forms, vectorised over a batch.

Equation numbers are those of seed 000 (Zhou, Yang, Qin, Control and Decision 26(9), 2011), which
quotes Han (2007), except for fst, the fst tracking differentiator and the second-order ESO at the
end, numbered as in seed 001 (Zhao, Zhuang, Yang, Control and Decision 22(2), 2007). Every function takes NumPy arrays (any common shape: Monte Carlo runs, channels)
and returns arrays of the broadcast shape; the classes keep their states as such arrays.

Units follow the plant: for a gyrocompass level channel the output y is a velocity error (m/s), the
control u a commanded angular rate (rad/s) and b0 = -g or +g (m/s^2 per rad).

The step ``h`` of these discrete forms is Han's symbol, kept so that the code reads as the equations: it is the
interval at which the aligner steps them, its ``step_s`` option (:class:`adrc.gyrocompass.ADRCGyrocompass`,
:class:`adrc.moving_base.ESOTDAligner`) rounded to whole IMU samples. ``h0`` and ``h1`` are not steps but
fhan's and fst's precision (filter) factors, s.
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
        origin fastest under abs(u) <= r in discrete steps h (negative when x1 is positive, at rest).
    """
    return fhan_arithmetic(np.asarray(x1, dtype=float), np.asarray(x2, dtype=float), r, h, c)


def fhan_arithmetic(x1, x2, r, h, c):
    """The arithmetic of :func:`fhan` on floats or float arrays, free of conversions so that numba compiles it
    unchanged for one value (:mod:`adrc.primitives_compiled`: a compiled loop and its NumPy oracle then share every
    operation)."""
    d = r * h * h
    a0 = h * c * x2
    y = x1 + a0
    a1 = np.sqrt(d * (d + 8.0 * np.abs(y)))
    a2 = a0 + np.sign(y) * (a1 - d) / 2.0
    sy = (np.sign(y + d) - np.sign(y - d)) / 2.0
    a = (a0 + y - a2) * sy + a2
    sa = (np.sign(a + d) - np.sign(a - d)) / 2.0
    return -r * (a / d - np.sign(a)) * sa - r * np.sign(a)


def fal(e, alpha, delta):
    """Han's nonlinear gain fal(e, alpha, delta), eq. (10): ``|e|^alpha sign(e)`` outside [-delta, delta],
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


# ------------------------------------------------------- seed 001: fst tracking differentiator, 2nd-order ESO
def _filled(value, like):
    """A new float array of ``like``'s shape holding ``value`` (broadcast): a state's start."""
    return np.array(np.broadcast_to(value, like.shape), dtype=float)


def fst(x1, x2, v, r, h1):
    """Han's fst (seed 001, eq. 15 text): the TD's acceleration towards ``v``, bounded by ``r``.

    ::

        d = h1 r,  d0 = h1 d,  e = x1 - v,  y = e + h1 x2
        g = x2 - sign(y) (d - sqrt(8 r abs(y) + d^2)) / 2    if abs(y) >= d0
        g = x2 + y / h1                                   if abs(y) <  d0
        fst = -r sat(g, d),  sat(g, d) = sign(g) if abs(g) >= d else g / d

    (the printed formula lost the square root). Inside the linear zone (abs(y) < h1^2 r, abs(g) < h1 r)
    fst = -(x1 - v) / h1^2 - 2 x2 / h1.

    Parameters
    ----------
    x1, x2 : array_like
        Tracking signal and its derivative (units of v, and v per second).
    v : array_like
        Input signal.
    r : float
        Speed factor: acceleration bound, units of v per s^2.
    h1 : float
        Filter factor, s.
    """
    x1 = np.asarray(x1, dtype=float)
    x2 = np.asarray(x2, dtype=float)
    d = h1 * r
    d0 = h1 * d
    y = x1 - v + h1 * x2
    ay = np.abs(y)
    g = np.where(ay >= d0, x2 - np.sign(y) * (d - np.sqrt(8.0 * r * ay + d * d)) / 2.0, x2 + y / h1)
    return -r * np.where(np.abs(g) >= d, np.sign(g), g / d)


class FSTTrackingDifferentiator:
    """Tracking differentiator with fst, eq. (15), batched: x1 follows v, x2 is its derivative.

    ``x1(k+1) = x1 + h x2``; ``x2(k+1) = x2 + h fst(x1, x2, v, r, h1)`` (eqs. 14-15).

    Parameters
    ----------
    shape : tuple
        Batch shape.
    h : float
        Step, s.
    r : float
        Speed factor (units of v / s^2).
    h1 : float
        Filter factor, s (h1 > h filters noise; linear zone double pole at -1/h1).
    """

    def __init__(self, shape, h, r, h1):
        self.h, self.r, self.h1 = float(h), float(r), float(h1)
        self.x1 = np.zeros(shape)
        self.x2 = np.zeros(shape)

    def reset(self, v, dv=0.0):
        """Start at rest on ``v`` (or moving at ``dv``)."""
        self.x1, self.x2 = _filled(v, self.x1), _filled(dv, self.x2)

    def update(self, v):
        """One step with input ``v``; returns (x1, x2) after the step."""
        x1 = self.x1 + self.h * self.x2
        self.x2 = self.x2 + self.h * fst(self.x1, self.x2, v, self.r, self.h1)
        self.x1 = x1
        return self.x1, self.x2


class SecondOrderESO:
    """Second-order ESO, eq. (6), batched: z1 tracks y, z2 the total rate of change of y.

    ::

        e = z1 - y
        z1 <- z1 + h (z2 - beta1 e)
        z2 <- z2 - h beta2 fal(e, alpha, delta)

    With alpha = 1 it is linear: z2 = G(s) y', G = beta2 / (s^2 + beta1 s + beta2).

    Parameters
    ----------
    shape : tuple
        Batch shape (e.g. (runs, channels)).
    h : float
        Step, s.
    beta1, beta2 : float or array_like
        Continuous gains (1/s, 1/s^2 for alpha = 1), broadcast against ``shape``.
    alpha, delta : float or array_like
        fal exponent and linear zone (units of y).
    """

    def __init__(self, shape, h, beta1, beta2, alpha=1.0, delta=0.2):
        self.h = float(h)
        self.beta1 = np.asarray(beta1, dtype=float)
        self.beta2 = np.asarray(beta2, dtype=float)
        self.alpha = np.asarray(alpha, dtype=float)
        self.delta = np.asarray(delta, dtype=float)
        self.z1 = np.zeros(shape)
        self.z2 = np.zeros(shape)

    def reset(self, y, rate=0.0):
        """Start with z1 = y, z2 = rate."""
        self.z1, self.z2 = _filled(y, self.z1), _filled(rate, self.z2)

    def steady_lag(self, rate):
        """Steady-state errors of the discrete observer when y' is a ramp of slope ``rate`` (y'' = rate).

        Between updates z1, z2 are the predictions for the next sample k+1; then
        ``z1 - y_{k+1} = e1 = -rate delta^(1-alpha) / beta2`` (fal in its linear zone; exact for
        alpha = 1) and ``z2 - y'(t_{k+1}) = e2 = rate h / 2 + beta1 e1`` (a lag of beta1 / beta2 - h / 2).
        Returns (e1, e2)."""
        rate = np.asarray(rate, dtype=float)
        e1 = -rate * self.delta ** (1.0 - self.alpha) / self.beta2
        return e1, rate * self.h / 2.0 + self.beta1 * e1

    def shift(self, d_rate, d_slope=0.0, lead=None):
        """Account for a known change of the observed signal's dynamics from now on: y' jumps by
        ``d_rate`` and its slope y'' by ``d_slope``; returns the changes (dz1, dz2).

        After :meth:`update`, z1 and z2 are already the predictions for the next measurement, made
        with the old dynamics, ``lead`` seconds ahead (h for point samples, (h + dt) / 2 for the mean
        of the next step's samples at interval dt): the change dy(t) = d_rate t + d_slope t^2 / 2 is
        added as if it had always been there, z1 += dy(lead) + e1, z2 += dy'(lead) + e2, with the
        steady ramp lag (e1, e2) of :meth:`steady_lag`.
        """
        lead = self.h if lead is None else float(lead)
        d_slope = np.asarray(d_slope, dtype=float)
        e1, e2 = self.steady_lag(d_slope)
        dz1 = d_rate * lead + d_slope * lead**2 / 2.0 + e1
        dz2 = d_rate + d_slope * lead + e2
        self.z1 = self.z1 + dz1
        self.z2 = self.z2 + dz2
        return dz1, dz2

    def update(self, y):
        """One step with measurement ``y``; returns (z1, z2) after the step."""
        e = self.z1 - y
        z1 = self.z1 + self.h * (self.z2 - self.beta1 * e)
        self.z2 = self.z2 - self.h * self.beta2 * fal(e, self.alpha, self.delta)
        self.z1 = z1
        return self.z1, self.z2
