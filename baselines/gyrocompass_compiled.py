"""The PID gyrocompass's control loop, compiled (the loop of :class:`baselines.gyrocompass.PIDGyrocompass`).

:func:`pid_steps` runs the control steps of all the runs in one numba call: the strapdown over the step's samples
with the commands held and the velocity error against the reference
(:func:`fusionbench.methods.compass_compiled.command_step`), the azimuth fit's sums until the shot
(:func:`fusionbench.methods.compass_compiled.fit_step`), and the staged level and compass loops with their velocity
damping, on the states of :class:`baselines.gyrocompass.PIDLoops` (that object's own arrays). It stops at the shot
(once per run), where the NumPy code turns the attitude by the fitted azimuth
(:meth:`baselines.gyrocompass.PIDLoops.shot`, from :func:`run_compiled`), and goes on from there. The operations are
those of the NumPy oracle ``tests/oracles/pid_gyrocompass.py``, in its order: the two give identical results
(``tests/test_gyrocompass.py``).
"""

from __future__ import annotations

import numba
import numpy as np

from fusionbench.methods.compass_compiled import command_step, fit_step, loop_arrays, velocity_error, work_arrays


@numba.njit(cache=True)
def pid_steps(arrays, j0, resume, fit_from, shot_step, stage_steps, close_step, ramp_steps, gains, radius, J, x, damp,
              omega_c, hist_C):
    """Control steps ``j0, j0 + 1, ...`` of :meth:`baselines.gyrocompass.PIDGyrocompass._align`'s loop, all runs,
    until the shot or the last step.

    Parameters
    ----------
    arrays : fusionbench.methods.compass_compiled.LoopArrays
        The loop's strapdown and azimuth fit (:func:`~fusionbench.methods.compass_compiled.loop_arrays`), updated
        in place.
    j0 : int
        First step.
    resume : bool
        Step ``j0`` is the shot's: its strapdown and fit are done, its loops are not.
    fit_from, shot_step : int
        The steps of the fit (``fit_from`` to ``shot_step``) and of the shot.
    stage_steps : ndarray of int
        First step of each stage after the first (the level stages, then the compass stages).
    close_step : int
        First step of the compass loop (of the first compass stage).
    ramp_steps : float
        The compass loop's azimuth gain rises linearly to its full value over this many steps from ``close_step``
        (the first compass step has 1 / ramp_steps of it); 0: at once.
    gains : ndarray, shape (stages + 1, 7)
        Per stage (0: the first level stage): the level gains k1, k2, k3 and the compass gains c1, c2, c3, c4
        (unused before ``close_step``).
    radius : float
        Earth radius at the site, m.
    J, x, damp, omega_c : ndarray
        ``PIDLoops``'s states (R, 2), (R,), (R, 2) and command (R, 3, rad/s, ENU), updated in place.
    hist_C : ndarray, shape (R, >= steps, 3, 3)
        Written: the loop's attitude C_bn after each step.

    Returns
    -------
    int
        The shot's step if it stopped there (strapdown and fit done), else the number of steps.
    """
    C0, v0 = arrays.sd_state.C_bn, arrays.sd_state.v_n
    h, wN = arrays.fit_consts.h, arrays.fit_consts.wN  # wN: OMEGA_IE cos L, as PIDLoops.wN
    steps, runs, m = arrays.dth.shape[0], arrays.dth.shape[1], arrays.dth.shape[2]
    work, dv, dv_en = work_arrays(runs, m), np.empty((runs, 3)), np.empty((runs, 2))
    for j in range(j0, steps):
        if not (resume and j == j0):
            command_step(arrays, j, omega_c, work, dv)
            if fit_from <= j <= shot_step:
                for r in range(runs):
                    dv_en[r, 0], dv_en[r, 1] = dv[r, 0] + damp[r, 0], dv[r, 1] + damp[r, 1]
                fit_step(arrays, dv_en, omega_c)
            if j == shot_step:
                return j
        else:
            velocity_error(arrays, j, dv)  # the shot turned the attitude, not the velocity
        stage = 0
        while stage < stage_steps.size and stage_steps[stage] <= j:
            stage += 1
        k1, k2, k3, c1, c2, c3, c4 = gains[stage]
        ramp = min(1.0, (j - close_step + 1) / ramp_steps) if ramp_steps > 0 else 1.0
        for r in range(runs):  # the oracle's step (tests/oracles/pid_gyrocompass.py)
            vE, vN = dv[r, 0], dv[r, 1]
            J[r, 1] += k3 * vE * h
            w_cN = (1 + k2) * vE / radius + J[r, 1]
            dE = k1 * vE * h
            if j < close_step:
                J[r, 0] += k3 * vN * h
                w_cE = -(1 + k2) * vN / radius - J[r, 0]
                w_cU = 0.0
                dN = k1 * vN * h
            else:
                x[r] += (vN - c4 * x[r]) * h
                w_cE = -(1 + c2) * vN / radius
                w_cU = ramp * c3 / wN * x[r]
                dN = c1 * vN * h
            damp[r, 0] += dE
            damp[r, 1] += dN
            omega_c[r, 0], omega_c[r, 1], omega_c[r, 2] = w_cE, w_cN, w_cU
            v0[r, 0] -= dE
            v0[r, 1] -= dN
            hist_C[r, j] = C0[r]
    return steps


def run_compiled(loop, fit, loops, fit_from, shot_step, stage_steps, closing, gains, hist_C):
    """The PID loop of :meth:`baselines.gyrocompass.PIDGyrocompass._align`, compiled.

    Parameters
    ----------
    loop, fit, loops : CommandLoop, AzimuthFit, PIDLoops
        The strapdown loop (:mod:`fusionbench.methods.compass`), the azimuth fit it feeds until the shot, and the
        level and compass loops (:class:`baselines.gyrocompass.PIDLoops`), all advanced in place; ``loop.omega_c`` is
        left at the last command, for ``loop.finish()``.
    fit_from, shot_step : int
        First step of the fit; step of the shot.
    stage_steps : list of int
        First step of each stage after the first (the level stages, then the compass stages).
    closing : (int, float)
        The compass loop's first step and the length of its gain's ramp, steps (:func:`pid_steps`'s ``close_step``
        and ``ramp_steps``).
    gains : ndarray, shape (stages + 1, 7)
        Per stage: k1, k2, k3 of the level loops and c1..c4 of the compass loop (zeros in the level stages).
    hist_C : ndarray, shape (R, records, 3, 3)
        The attitude history; the first ``loop.steps`` entries are written.

    Returns
    -------
    ndarray, shape (R,)
        The azimuth of the shot, rad (NaN if the record ends before it).
    """
    arrays = loop_arrays(loop, fit)
    state = (fit_from, shot_step, np.asarray(stage_steps, dtype=np.int64), int(closing[0]), float(closing[1]),
             np.asarray(gains, dtype=float),
             float(loops.radius), loops.J, loops.x, loops.damp, loops.omega_c, hist_C)
    az_shot = np.full(loop.R, np.nan)
    j = pid_steps(arrays, 0, False, *state)
    if j < loop.steps:  # the shot, by PIDLoops.shot (NumPy)
        az_shot = loops.shot(loop, fit)
        pid_steps(arrays, j, True, *state)
    loop.omega_c = loops.omega_c
    return az_shot
