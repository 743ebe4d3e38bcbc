"""Compiled twins of the per-step pieces of :mod:`fusionbench.methods.compass`, for control loops written as numba code.

A gyrocompass-type aligner whose whole control loop is compiled (``adrc``, ``pid``) steps the strapdown of a
:class:`fusionbench.methods.compass.CommandLoop` with :func:`command_step` and feeds an
:class:`fusionbench.methods.compass.AzimuthFit` with :func:`fit_step`, both on the objects' own arrays
(:func:`loop_arrays`: ``Strapdown.compiled_state()``, ``AzimuthFit.compiled_state()``), so the objects stay
consistent for the NumPy code that runs before or after the compiled loop (a one-shot correction, the tail of the
record, the azimuth solve).

The arithmetic is that of the NumPy methods, operation for operation and in the same order, so a compiled loop and
its NumPy oracle (``tests/oracles/``) give identical results (IEEE arithmetic, no fast-math). One detail matters:
``(n h) ** 2`` is Python's float power, C's ``pow``, which differs from ``x * x`` in the last bit for about one value
in a thousand; numba turns a power with a literal exponent into a product, so the exponent reaches :func:`fit_add`
at run time (``two``).
"""

from __future__ import annotations

from collections import namedtuple

import numba
import numpy as np

from fusionbench.simulation.strapdown_compiled import integrate_compiled

#: An :class:`fusionbench.methods.compass.AzimuthFit`'s arrays, updated in place by :func:`fit_add`: the integrals
#: ``I`` and double integrals ``D`` (R, 3) of [w_cE, w_cN, 1] (rad, rad s; s, s^2), the integrals ``V`` (R, 2) of
#: [dvE, dvN] (m), the last step's velocity errors ``prev_dv`` (R, 2) m/s, the sums ``t_sums`` (3,) of tau^0..2 and
#: ``sums`` (R, 9) per run (:class:`~fusionbench.methods.compass.AzimuthFit`), the step count ``count`` (1,) int.
FitState = namedtuple("FitState", "I D V prev_dv t_sums sums count")
#: The fit's constants: its step ``h`` (s), gravity ``g`` (m/s^2), the horizontal and vertical earth rates ``wN``,
#: ``wU`` (rad/s) and ``two`` (2.0 at run time: module docstring).
FitConsts = namedtuple("FitConsts", "h g wN wU two")
#: What a compiled control loop works on (:func:`loop_arrays`): the strapdown's ``sd_state``
#: (:data:`~fusionbench.simulation.strapdown_compiled.StrapdownState`) and the fit's ``fit_state`` (:data:`FitState`),
#: both updated in place; the increments ``dth``, ``dvel`` (steps, R, m, 3), rad, m/s, body frame, one block per
#: step; ``vref`` (steps, R, 3) the step-mean reference velocity, m/s ENU, or (0, R, 3) without one; ``dt`` the
#: sample interval, s; ``fit_consts`` (:data:`FitConsts`).
LoopArrays = namedtuple("LoopArrays", "sd_state fit_state dth dvel vref dt fit_consts")


def loop_arrays(loop, fit):
    """The arrays a compiled control loop works on, a :data:`LoopArrays` (the first argument of :func:`command_step`
    and :func:`fit_step`).

    Parameters
    ----------
    loop : fusionbench.methods.compass.CommandLoop
        The loop: ``sd_state`` its ``Strapdown.compiled_state()`` (position fixed), updated in place; ``dth``,
        ``dvel`` its angle (rad) and velocity (m/s) increments, body frame, one block (R, m, 3) per step, shape
        (steps, R, m, 3); ``vref`` its step-mean reference velocity (steps, R, 3), ENU, m/s, or an empty (0, R, 3);
        ``dt`` the sample interval, s.
    fit : fusionbench.methods.compass.AzimuthFit
        The fit: ``fit_state`` its ``compiled_state()``, updated in place; ``fit_consts`` = ``(h, g, wN, wU, 2.0)``,
        its step (s), gravity (m/s^2), the horizontal and vertical earth rates (rad/s), and the square's exponent
        (module docstring).
    """
    vref = np.zeros((0, loop.R, 3)) if loop.vref is None else loop.vref
    return LoopArrays(loop.sd.compiled_state(), fit.compiled_state(), loop.dth, loop.dv, vref, loop.sd.dt,
                      FitConsts(fit.step_s, fit.g, fit.wN, fit.wU, 2.0))


@numba.njit(cache=True)
def work_arrays(runs, m):
    """Work arrays of :func:`command_step` for ``runs`` runs of ``m`` samples a step."""
    return np.empty((runs, m, 3)), np.empty((runs, 1, 3, 3)), np.empty((runs, 1, 3)), np.empty((runs, 1, 3))


@numba.njit(cache=True)
def command_step(arrays, j, omega, work, dv):
    """Control step ``j`` of a :class:`fusionbench.methods.compass.CommandLoop`, as its iterator makes it: the step's
    samples through the strapdown with the commanded rate ``omega`` (R, 3), rad/s, ENU, held; ``dv`` (R, 3) is then the
    velocity error against the reference, m/s (the velocity itself without one).

    ``arrays`` is a :data:`LoopArrays`, ``work`` :func:`work_arrays`'s tuple.
    """
    C0, v0, lat0, lon0, h0, vp0, thp, dvp = arrays.sd_state
    dth, dvel, dt = arrays.dth[j], arrays.dvel[j], arrays.dt
    cmd, rec_C, rec_v, rec_p = work
    runs, m = dth.shape[0], dth.shape[1]
    for r in range(runs):
        for k in range(m):
            cmd[r, k, 0], cmd[r, k, 1], cmd[r, k, 2] = omega[r, 0], omega[r, 1], omega[r, 2]
    integrate_compiled(C0, v0, lat0, lon0, h0, vp0, thp, dvp, dth, dvel, cmd, dt, True, True, m, rec_C, rec_v, rec_p)
    velocity_error(arrays, j, dv)


@numba.njit(cache=True)
def velocity_error(arrays, j, dv):
    """``dv`` (R, 3) = the strapdown's velocity less the reference of step ``j`` (m/s; the velocity itself without
    a reference), as :class:`fusionbench.methods.compass.CommandLoop` yields it; ``arrays`` is a :data:`LoopArrays`."""
    v_n, vref = arrays.sd_state.v_n, arrays.vref
    for r in range(v_n.shape[0]):
        for i in range(3):
            dv[r, i] = v_n[r, i] - vref[j, r, i] if vref.shape[0] else v_n[r, i]


@numba.njit(cache=True)
def fit_step(arrays, dv_en, w_c):
    """Add a step to the loop's :class:`fusionbench.methods.compass.AzimuthFit` (:func:`fit_add`): the velocity errors
    ``dv_en`` (R, >= 2) [dvE, dvN], m/s, at the end of the step, the commands ``w_c`` (R, >= 2) [w_cE, w_cN],
    rad/s, applied during it; ``arrays`` is a :data:`LoopArrays`."""
    c = arrays.fit_consts
    fit_add(arrays.fit_state, dv_en, w_c, c.h, c.g, c.wN, c.wU, c.two)


@numba.njit(cache=True)
def fit_add(fit_state, dv_en, w_c, h, g, wN, wU, two):
    """:meth:`fusionbench.methods.compass.AzimuthFit.add` on ``AzimuthFit.compiled_state()`` (updated in place).

    Parameters
    ----------
    fit_state : FitState
        ``I, D, V, prev_dv, t_sums, sums, count`` of the fit.
    dv_en : ndarray, shape (R, 2)
        Velocity errors [dvE, dvN] at the end of the step, m/s.
    w_c : ndarray, shape (R, 2)
        Commands [w_cE, w_cN] applied during the step, rad/s.
    h, g, wN, wU : float
        The fit's step (s), gravity (m/s^2), and the horizontal and vertical earth rates (rad/s).
    two : float
        2.0, given at run time (module docstring).
    """
    I, D, V, prev, t_sums, sums, count = fit_state
    n = count[0]
    scale = 100.0  # AzimuthFit._SCALE
    tau = n * h / scale
    nh2 = (n * h) ** two
    for r in range(dv_en.shape[0]):
        if n:
            for c in range(3):
                rate = w_c[r, c] if c < 2 else 1.0
                D[r, c] = D[r, c] + (I[r, c] * h + 0.5 * rate * h * h)
                I[r, c] = I[r, c] + rate * h
            for c in range(2):
                V[r, c] = V[r, c] + 0.5 * (prev[r, c] + dv_en[r, c]) * h
        prev[r, 0], prev[r, 1] = dv_en[r, 0], dv_en[r, 1]
        P = D[r, 2] / (scale * scale)
        yN = dv_en[r, 1] + 3.0 * wU * V[r, 0] - g * D[r, 0]
        yE = dv_en[r, 0] - 3.0 * wU * V[r, 1] + g * D[r, 1] + 0.5 * g * wN * nh2
        s = sums[r]
        s[0] += P
        s[1] += tau * P
        s[2] += P * P
        s[3] += yN
        s[4] += tau * yN
        s[5] += yE
        s[6] += tau * yE
        s[7] += P * yN
        s[8] += P * yE
    t_sums[0] += 1.0
    t_sums[1] += tau
    t_sums[2] += tau * tau
    count[0] = n + 1
