"""The PID gyrocompass's control loop compiled (``engine="numba"`` of :class:`baselines.gyrocompass.PIDGyrocompass`).

:func:`pid_steps` runs the control steps of all the runs in one numba call: the strapdown over the step's samples
with the commands held (:func:`fusionbench.compass_compiled.command_step`), the velocity error against the
reference, the azimuth fit's sums until the shot (:func:`fusionbench.compass_compiled.fit_add`), and the staged
level and compass loops of :class:`baselines.gyrocompass.PIDLoops` with their velocity damping, on that object's
own arrays. It stops at the shot (once per run), where the NumPy code turns the attitude by the fitted azimuth
(:meth:`baselines.gyrocompass.PIDLoops.shot`, from :func:`run_compiled`), and goes on from there. The operations
are the NumPy loop's, in its order: the two engines give identical results (``tests/test_gyrocompass.py``).
"""

from __future__ import annotations

import numba
import numpy as np

from fusionbench.compass_compiled import command_step, fit_add, velocity_error


@numba.njit(cache=True)
def pid_steps(sd_state, fit_state, dth, dvel, vref, dt, fit_consts, j0, resume, fit_from, shot_step, stage_steps,
              gains, radius, J, x, damp, omega_c, hist_C):
    """Control steps ``j0, j0 + 1, ...`` of :meth:`baselines.gyrocompass.PIDGyrocompass._align`'s loop, all runs,
    until the shot or the last step.

    Parameters
    ----------
    sd_state, fit_state : tuple
        ``Strapdown.compiled_state()`` of the loop's strapdown (position fixed) and ``AzimuthFit.compiled_state()``,
        updated in place.
    dth, dvel : ndarray, shape (steps, R, m, 3)
        Angle (rad) and velocity (m/s) increments, body frame, one block per step (``CommandLoop.dth``, ``.dv``).
    vref : ndarray, shape (steps, R, 3) or (0, R, 3)
        Step-mean reference velocity, ENU, m/s (``CommandLoop.vref``), or none.
    dt : float
        Sample interval, s.
    fit_consts : tuple
        ``(h, g, wN, wU, 2.0)``: the control step (s), gravity (m/s^2), the horizontal and vertical earth rates
        (rad/s), and the fit's square exponent (:mod:`fusionbench.compass_compiled`).
    j0 : int
        First step.
    resume : bool
        Step ``j0`` is the shot's: its strapdown and fit are done, its loops are not.
    fit_from, shot_step : int
        The steps of the fit (``fit_from`` to ``shot_step``) and of the shot.
    stage_steps : ndarray of int
        First step of each compass stage.
    gains : ndarray, shape (stages + 1, 7)
        Per stage (0: the level stage): the level gains k1, k2, k3 and the compass gains c1, c2, c3, c4 (unused in
        stage 0).
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
    h, g, wN, wU, two = fit_consts
    C0, v0 = sd_state[0], sd_state[1]
    steps, runs, m = dth.shape[0], dth.shape[1], dth.shape[2]
    cmd = np.empty((runs, m, 3))
    rec_C, rec_v, rec_p = np.empty((runs, 1, 3, 3)), np.empty((runs, 1, 3)), np.empty((runs, 1, 3))
    dv, dv_en = np.empty((runs, 3)), np.empty((runs, 2))
    for j in range(j0, steps):
        if not (resume and j == j0):
            command_step(sd_state, dth[j], dvel[j], omega_c, cmd, dt, rec_C, rec_v, rec_p)
            velocity_error(v0, vref, j, dv)
            if fit_from <= j <= shot_step:
                for r in range(runs):
                    dv_en[r, 0], dv_en[r, 1] = dv[r, 0] + damp[r, 0], dv[r, 1] + damp[r, 1]
                fit_add(fit_state, dv_en, omega_c, h, g, wN, wU, two)
            if j == shot_step:
                return j
        else:
            velocity_error(v0, vref, j, dv)  # the shot turned the attitude, not the velocity
        stage = 0
        while stage < stage_steps.size and stage_steps[stage] <= j:
            stage += 1
        k1, k2, k3, c1, c2, c3, c4 = gains[stage]
        for r in range(runs):  # PIDLoops.step
            vE, vN = dv[r, 0], dv[r, 1]
            J[r, 1] += k3 * vE * h
            w_cN = (1 + k2) * vE / radius + J[r, 1]
            dE = k1 * vE * h
            if stage == 0:
                J[r, 0] += k3 * vN * h
                w_cE = -(1 + k2) * vN / radius - J[r, 0]
                w_cU = 0.0
                dN = k1 * vN * h
            else:
                x[r] += (vN - c4 * x[r]) * h
                w_cE = -(1 + c2) * vN / radius
                w_cU = c3 / wN * x[r]
                dN = c1 * vN * h
            damp[r, 0] += dE
            damp[r, 1] += dN
            omega_c[r, 0], omega_c[r, 1], omega_c[r, 2] = w_cE, w_cN, w_cU
            v0[r, 0] -= dE
            v0[r, 1] -= dN
            hist_C[r, j] = C0[r]
    return steps


def run_compiled(loop, fit, loops, fit_from, shot_step, stage_steps, gains, hist_C):
    """The PID loop of :meth:`baselines.gyrocompass.PIDGyrocompass._align` with the numba engine.

    Parameters
    ----------
    loop : fusionbench.compass.CommandLoop
        The loop (its strapdown is advanced in place; ``loop.omega_c`` is left at the last command, for
        ``loop.finish()``).
    fit : fusionbench.compass.AzimuthFit
        The azimuth fit (fed in place).
    loops : baselines.gyrocompass.PIDLoops
        The level and compass loops (stepped in place).
    fit_from, shot_step : int
        First step of the fit; step of the shot.
    stage_steps : list of int
        First step of each compass stage.
    gains : ndarray, shape (stages + 1, 7)
        Per stage: k1, k2, k3 of the level loops and c1..c4 of the compass loop (zeros in stage 0).
    hist_C : ndarray, shape (R, records, 3, 3)
        The attitude history; the first ``loop.steps`` entries are written.

    Returns
    -------
    ndarray, shape (R,)
        The azimuth of the shot, rad (NaN if the record ends before it).
    """
    vref = np.zeros((0, loop.R, 3)) if loop.vref is None else loop.vref
    args = (loop.sd.compiled_state(), fit.compiled_state(), loop.dth, loop.dv, vref, loop.sd.dt,
            (fit.step_s, fit.g, fit.wN, fit.wU, 2.0))
    state = (fit_from, shot_step, np.asarray(stage_steps, dtype=np.int64), np.asarray(gains, dtype=float),
             float(loops.radius), loops.J, loops.x, loops.damp, loops.omega_c, hist_C)
    az_shot = np.full(loop.R, np.nan)
    j = pid_steps(*args, 0, False, *state)
    if j < loop.steps:  # the shot, by the NumPy loop's own code
        az_shot = loops.shot(loop, fit)
        pid_steps(*args, j, True, *state)
    loop.omega_c = loops.omega_c
    return az_shot
