"""The ADRC gyrocompass's control loop, compiled (the loop of :class:`adrc.gyrocompass.ADRCGyrocompass`).

:func:`adrc_steps` runs every control step of all the runs in one numba call: the strapdown over the step's
samples with the commands held and the velocity error against the reference
(:func:`fusionbench.methods.compass_compiled.command_step`), the ESO (eq. 9) and the NLSEF (eq. 11) of both level
channels, and the azimuth fit's sums (:func:`fusionbench.methods.compass_compiled.fit_step`). The fit is read (its 6x6
solve) every ``every`` steps from ``fit_from`` (0.1 s) and at the shot, from the sums kept at those steps, in one
batched NumPy call afterwards (:func:`run_compiled`); the method makes the attitude it reports from the histories. The
operations are those of the NumPy oracle ``tests/oracles/adrc_gyrocompass.py`` (a loop over control steps on the
primitives of :mod:`adrc.primitives`), in its order: the two give identical results (``tests/test_gyrocompass.py``).
"""

from __future__ import annotations

import numba
import numpy as np

from fusionbench.methods.compass import fit_azimuth
from fusionbench.methods.compass_compiled import command_step, fit_step, loop_arrays, work_arrays

from .primitives_compiled import eso3_step, nlsef


@numba.njit(cache=True)
def adrc_steps(arrays, gains, b0, z, u, fit_from, record, hist_C, tilt, rec_t_sums, rec_sums):
    """All the control steps of :meth:`adrc.gyrocompass.ADRCGyrocompass._align`'s loop, for all runs.

    Parameters
    ----------
    arrays : fusionbench.methods.compass_compiled.LoopArrays
        The loop's strapdown and azimuth fit (:func:`~fusionbench.methods.compass_compiled.loop_arrays`), updated
        in place.
    gains : ndarray, shape (9,)
        ``beta01, beta02, beta03, delta, delta ** 0.5, delta ** 0.75, r1, h1, c1``.
    b0 : ndarray, shape (2,)
        b0 of the channels [east, north] (m/s^2 per rad: -g, +g).
    z : ndarray, shape (R, 2, 3)
        ESO states z1, z2, z3 of each channel, updated in place.
    u : ndarray, shape (R, 2)
        Commands of the channels [w_cN, w_cE] (rad/s), updated in place (the last step's on return).
    fit_from : int
        First step added to the fit.
    record : ndarray of int, shape (steps,)
        For each step, the index into ``rec_t_sums``, ``rec_sums`` at which the fit's sums after it are kept, or -1.
    hist_C : ndarray, shape (R, >= steps, 3, 3)
        Written: the loop's attitude C_bn after each step.
    tilt : ndarray, shape (R, >= steps, 2)
        Written: the ESO's tilt estimate z2 / b0 after each step, rad.
    rec_t_sums, rec_sums : ndarray, shapes (K, 3), (R, K, 9)
        Written: the fit's sums at the recorded steps.
    """
    beta01, beta02, beta03, delta, div_half, div_quarter, r1, h1, c1 = gains
    C0, t_sums, sums, h = arrays.sd_state.C_bn, arrays.fit_state.t_sums, arrays.fit_state.sums, arrays.fit_consts.h
    steps, runs, m = arrays.dth.shape[0], arrays.dth.shape[1], arrays.dth.shape[2]
    work, omega, dv, applied = work_arrays(runs, m), np.empty((runs, 3)), np.empty((runs, 3)), np.empty((runs, 2))
    for j in range(steps):
        for r in range(runs):
            omega[r, 0], omega[r, 1], omega[r, 2] = u[r, 1], u[r, 0], 0.0
        command_step(arrays, j, omega, work, dv)
        for r in range(runs):
            applied[r, 0], applied[r, 1] = u[r, 1], u[r, 0]  # [w_cE, w_cN] used during this step
            for c in range(2):
                z1, z2, z3 = eso3_step(z[r, c, 0], z[r, c, 1], z[r, c, 2], dv[r, c], u[r, c], h, beta01, beta02,
                                       beta03, delta, div_half, div_quarter, b0[c])
                z[r, c, 0], z[r, c, 1], z[r, c, 2] = z1, z2, z3
                # the TD's reference is zero and it starts at rest on it: v1 = v2 = 0 throughout
                u[r, c] = nlsef(-z1, -z2, z3, b0[c], r1, h1, c1)
                tilt[r, j, c] = z2 / b0[c]
            hist_C[r, j] = C0[r]
        if j >= fit_from:
            fit_step(arrays, dv, applied)
            k = record[j]
            if k >= 0:
                rec_t_sums[k] = t_sums
                rec_sums[:, k] = sums


def run_compiled(loop, fit, gains, b0, fit_from, shot_step, every, hist_C, hist_az, tilt):
    """The ADRC loop of :meth:`adrc.gyrocompass.ADRCGyrocompass._align`, compiled.

    Parameters
    ----------
    loop : fusionbench.methods.compass.CommandLoop
        The loop (its strapdown is advanced in place; ``loop.omega_c`` is left at the last command, for
        ``loop.finish()``).
    fit : fusionbench.methods.compass.AzimuthFit
        The azimuth fit (fed in place).
    gains : dict
        The step's gains (``ADRCGyrocompass.gains``) with ``delta`` and ``c1`` added.
    b0 : ndarray, shape (2,)
        b0 of the channels [east, north], m/s^2 per rad.
    fit_from, shot_step, every : int
        First step of the fit, step of the azimuth shot, and the interval (steps) at which the azimuth is read.
    hist_C, hist_az, tilt : ndarray
        The histories (R, records, ...); the first ``loop.steps`` entries are written.

    Returns
    -------
    ndarray, shape (R,)
        The azimuth at the shot, rad (NaN if the record ends before it).
    """
    R, steps = loop.R, loop.steps
    js = np.arange(fit_from, steps)
    read = js[(js == shot_step) | ((js - fit_from) % every == 0)]  # the steps at which the fit is read
    record = np.full(steps, -1, dtype=np.int64)
    record[read] = np.arange(read.size)
    rec_t_sums, rec_sums = np.zeros((read.size, 3)), np.zeros((R, read.size, 9))
    k = gains
    d = float(k["delta"])
    consts = np.array([k["beta01"], k["beta02"], k["beta03"], d, d ** (1.0 - 0.5), d ** (1.0 - 0.25), k["r1"],
                       k["h1"], k["c1"]], dtype=float)
    z, u = np.zeros((R, 2, 3)), np.zeros((R, 2))
    adrc_steps(loop_arrays(loop, fit), consts, np.asarray(b0, dtype=float), z, u, fit_from, record, hist_C, tilt,
               rec_t_sums, rec_sums)
    loop.omega_c = np.stack([u[:, 1], u[:, 0], np.zeros(R)], axis=-1)
    az = np.full((R, read.size), np.nan)
    ok = read - fit_from + 1 >= 4  # the fit's n at each read: NaN before 4 steps, as AzimuthFit.azimuth
    az[:, ok] = fit_azimuth(rec_t_sums[ok], rec_sums[:, ok], fit.g, fit.wN)
    if js.size:  # each step carries the last estimate read at or before it
        hist_az[:, fit_from:steps] = az[:, np.searchsorted(read, js, side="right") - 1]
    return az[:, record[shot_step]] if shot_step < steps else np.full(R, np.nan)
