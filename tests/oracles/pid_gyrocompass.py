"""The NumPy reference of the PID gyrocompass's compiled control loop
(:func:`baselines.gyrocompass_compiled.run_compiled`).

A Python loop over control steps with arrays over runs (the level and compass loops' step on
:class:`baselines.gyrocompass.PIDLoops`'s states, :func:`step`) that makes the compiled loop's operations in its
order: the oracle of the agreement tests (``tests/test_gyrocompass.py``) and of ``benchmarks/perf_methods.py``.
``PATCH`` names the library's function it stands in for, for ``monkeypatch.setattr``.
"""

from __future__ import annotations

import numpy as np


def step(loops, vE, vN, level, compass=None, ramp=1.0):
    """One control step of ``loops`` (:class:`baselines.gyrocompass.PIDLoops`) with the velocity errors ``vE``, ``vN``
    (R,) m/s.

    ``level`` = (k1, k2, k3) of :func:`baselines.gyrocompass.level_gains`; ``compass`` = (c1, c2, c3, c4) of
    :func:`baselines.gyrocompass.compass_gains` makes the north channel the compass loop, its azimuth gain c3 times
    ``ramp`` (the soft closing's fraction, 0 to 1). Updates ``loops.omega_c``;
    returns the velocity corrections ``dE``, ``dN`` (R,) m/s that the damping terms take off the strapdown's
    velocity."""
    h, radius = loops.h, loops.radius
    k1, k2, k3 = level
    J = loops.J
    # east channel: third-order level loop in every stage
    J[:, 1] += k3 * vE * h
    w_cN = (1 + k2) * vE / radius + J[:, 1]
    dE = k1 * vE * h
    if compass is None:
        J[:, 0] += k3 * vN * h
        w_cE = -(1 + k2) * vN / radius - J[:, 0]
        w_cU = np.zeros(vN.shape)
        dN = k1 * vN * h
    else:
        c1, c2, c3, c4 = compass
        loops.x += (vN - c4 * loops.x) * h
        w_cE = -(1 + c2) * vN / radius
        w_cU = ramp * c3 / loops.wN * loops.x
        dN = c1 * vN * h
    loops.damp += np.stack([dE, dN], axis=-1)
    loops.omega_c = np.stack([w_cE, w_cN, w_cU], axis=-1)
    return dE, dN


def run_numpy(loop, fit, loops, fit_from, shot_step, stage_steps, closing, gains, hist_C):
    """The arguments, effects and result of :func:`baselines.gyrocompass_compiled.run_compiled`: one control step
    at a time, NumPy over the runs."""
    az_shot = np.full(loop.R, np.nan)
    for j, t, dv in loop:
        if j >= fit_from and j <= shot_step:
            fit.add(dv[:, :2] + loops.damp, loops.omega_c[:, :2])
        if j == shot_step:
            az_shot = loops.shot(loop, fit)
        stage = int(np.searchsorted(stage_steps, j, side="right"))
        close_step, ramp_steps = closing
        ramp = min(1.0, (j - close_step + 1) / ramp_steps) if ramp_steps > 0 else 1.0
        dE, dN = step(loops, dv[:, 0], dv[:, 1], gains[stage][:3], None if j < close_step else gains[stage][3:], ramp)
        loop.sd.state.v_n[:, 0] -= dE
        loop.sd.state.v_n[:, 1] -= dN
        loop.omega_c = loops.omega_c
        hist_C[:, j] = loop.sd.state.C_bn
    return az_shot


#: (module, attribute, oracle): the library function this oracle replaces.
PATCH = ("baselines.gyrocompass", "run_compiled", run_numpy)
