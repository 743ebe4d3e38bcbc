"""The primitives of :mod:`adrc.primitives` for one value, compiled with numba for the compiled control loops.

Each function here does the operations of its NumPy namesake on one element, in the same order, so a compiled
loop reproduces the NumPy reference exactly (IEEE arithmetic, no fast-math). :func:`fhan` is the reference's own
code (:func:`adrc.primitives.fhan_arithmetic`), compiled. Where the reference computes a power that NumPy
evaluates specially, the caller passes its value in: fal's linear-zone divisor ``delta ** (1 - alpha)`` is
computed in Python as the reference computes it (``lin_div``), and NumPy's ``array ** 0.5`` is a square root,
while ``array ** array`` is C's ``pow`` (``half_is_sqrt``).

Units follow the plant, as in :mod:`adrc.primitives`: for a level channel y is a velocity error (m/s), u a
commanded rate (rad/s), b0 in m/s^2 per rad; h, h0, h1 are in s.
"""

from __future__ import annotations

import numba
import numpy as np

from .primitives import fhan_arithmetic

#: Han's fhan, eq. (8), for one value: ``fhan(x1, x2, r, h, c)`` (:func:`adrc.primitives.fhan`).
fhan = numba.njit(cache=True)(fhan_arithmetic)


@numba.njit(cache=True)
def fal(e, alpha, delta, lin_div, half_is_sqrt):
    """Han's fal(e, alpha, delta), eq. (10), for one value (:func:`adrc.primitives.fal`).

    ``lin_div`` is ``delta ** (1 - alpha)``; ``half_is_sqrt``: abs(e) ** 0.5 is a square root (the reference's
    exponent is a Python float, for which NumPy takes the root) rather than ``pow`` (an array exponent)."""
    a = abs(e)
    if a > delta:
        return (np.sqrt(a) if half_is_sqrt and alpha == 0.5 else a ** alpha) * np.sign(e)
    return e / lin_div


@numba.njit(cache=True)
def eso3_step(z1, z2, z3, y, u, h, beta01, beta02, beta03, delta, div_half, div_quarter, b0):
    """One step of the third-order ESO, eq. (9) (:meth:`adrc.primitives.ExtendedStateObserver.update`), for one
    channel: measurement ``y``, the control ``u`` applied over the last step; ``div_half``, ``div_quarter`` are
    ``delta ** 0.5`` and ``delta ** 0.75``. Returns the new (z1, z2, z3)."""
    e = z1 - y
    fe = fal(e, 0.5, delta, div_half, True)
    fe1 = fal(e, 0.25, delta, div_quarter, True)
    return z1 + h * (z2 - beta01 * e), z2 + h * (z3 - beta02 * fe + b0 * u), z3 - h * beta03 * fe1


@numba.njit(cache=True)
def nlsef(e1, e2, z3, b0, r1, h1, c1):
    """The sign-corrected NLSEF, eq. (11), for one channel (:func:`adrc.primitives.nlsef`): the control u."""
    u0 = -fhan(e1, e2, r1, h1, c1)
    return np.sign(b0) * u0 - z3 / b0


@numba.njit(cache=True)
def fst(x1, x2, v, r, h1):
    """Han's fst for one value (:func:`adrc.primitives.fst`): the TD's acceleration towards ``v``."""
    d = h1 * r
    d0 = h1 * d
    y = x1 - v + h1 * x2
    ay = abs(y)
    g = x2 - np.sign(y) * (d - np.sqrt(8.0 * r * ay + d * d)) / 2.0 if ay >= d0 else x2 + y / h1
    return -r * (np.sign(g) if abs(g) >= d else g / d)


@numba.njit(cache=True)
def fst_step(x1, x2, v, h, r, h1):
    """One step of the fst TD, eqs. (14-15) (:meth:`adrc.primitives.FSTTrackingDifferentiator.update`): the new
    (x1, x2) from input ``v``."""
    return x1 + h * x2, x2 + h * fst(x1, x2, v, r, h1)


@numba.njit(cache=True)
def eso2_step(z1, z2, y, h, beta1, beta2, alpha, delta, lin_div):
    """One step of the second-order ESO, eq. (6) (:meth:`adrc.primitives.SecondOrderESO.update`), for one
    element; ``lin_div`` = ``delta ** (1 - alpha)``. Returns the new (z1, z2)."""
    e = z1 - y
    return z1 + h * (z2 - beta1 * e), z2 - h * beta2 * fal(e, alpha, delta, lin_div, False)
