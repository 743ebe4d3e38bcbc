"""The NumPy reference of the ADRC gyrocompass's compiled control loop (:func:`adrc.gyrocompass_compiled.run_compiled`).

A Python loop over control steps with arrays over runs, built from the NumPy primitives of :mod:`adrc.primitives`
(ESO eq. 9, NLSEF eq. 11), that makes the compiled loop's operations in its order: the oracle of the agreement tests
(``tests/test_gyrocompass.py``) and of ``benchmarks/perf_methods.py``. ``PATCH`` names the library's function it
stands in for, for ``monkeypatch.setattr``.
"""

from __future__ import annotations

import numpy as np

from adrc.primitives import ExtendedStateObserver, nlsef


def run_numpy(loop, fit, gains, b0, fit_from, shot_step, every, hist_C, hist_az, tilt):
    """The arguments, effects and result of :func:`adrc.gyrocompass_compiled.run_compiled` (``gains``: the step's
    gains with ``delta`` and ``c1`` added): one control step at a time, NumPy over the runs."""
    R, h, k = loop.R, loop.step_s, gains
    eso = ExtendedStateObserver((R, 2), h, k["beta01"], k["beta02"], k["beta03"], k["delta"], b0)
    u = np.zeros((R, 2))
    az_shot = np.full(R, np.nan)
    az = np.full(R, np.nan)
    for j, t, dv in loop:
        applied = np.stack([u[:, 1], u[:, 0]], axis=-1)  # [w_cE, w_cN] used during this period
        z1, z2, z3 = eso.update(dv[:, :2], u)
        # the TD's reference is zero and it starts at rest on it: v1 = v2 = 0 throughout
        u = nlsef(-z1, -z2, z3, b0, k["r1"], k["h1"], k["c1"])
        if j >= fit_from:
            fit.add(dv[:, :2], applied)
            if j == shot_step or (j - fit_from) % every == 0:
                az = fit.azimuth()
            hist_az[:, j] = az
            if j == shot_step:
                az_shot = az
        loop.omega_c = np.stack([u[:, 1], u[:, 0], np.zeros(R)], axis=-1)
        hist_C[:, j] = loop.sd.state.C_bn
        tilt[:, j] = z2 / b0
    return az_shot


#: (module, attribute, oracle): the library function this oracle replaces.
PATCH = ("adrc.gyrocompass", "run_compiled", run_numpy)
