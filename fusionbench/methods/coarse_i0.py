"""The inertial-frame coarse alignment's solution (method ``coarse-i0``) as a function of the record.

:class:`fusionbench.methods.coarse.InertialCoarseAligner` is the method (its input policy, options and the
description of the fit); :func:`inertial_coarse` is what it computes, called too by the check of a given first
guess (:mod:`fusionbench.methods.init_check`) on the record's first seconds, which the policy has already checked.
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.aligner import AlignmentResult
from fusionbench.methods.coarse_aided import aided_fit, aiding_rows, fit_rotation, imu_at_rows, place
from fusionbench.methods.coarse_inertial import c_n_i0, gravity_integral_inertial
from fusionbench.methods.coarse_kernel import body_pass
from fusionbench.methods.coarse_level import relevel
from fusionbench.simulation import earth
from fusionbench.simulation.attitude import rotvec_to_dcm
from fusionbench.simulation.strapdown import body_increments

#: The method's name.
NAME = "coarse-i0"
#: Defaults of the level taken from the specific force before each attitude: the window, s, and the largest level
#: error its noise may cause, rad (3e-5: 0.1 arcmin); :func:`fusionbench.methods.coarse_level.relevel`.
LEVEL_WINDOW_S = 20.0
LEVEL_NOISE_MAX = 3e-5
#: Samples (runs x increments, or runs x rows of the aiding) whose body increments, or whose fit on the rows, are
#: formed at once: a whole batch's (50 runs of 600 s at 100 Hz, a velocity row on each sample) made coarse-i0 the
#: largest process of ``run all`` (1.85 GB; the body increments 0.25 GB of it, the fit on the rows 0.73 GB).
CHUNK_SAMPLES = 2**18


def inertial_coarse(imu, site, aiding, history_points: int = 100, fit_points: int = 50,
                    level_window_s: float | None = LEVEL_WINDOW_S, level_noise_max: float = LEVEL_NOISE_MAX,
                    who: str = NAME, name: str = NAME) -> AlignmentResult:
    """The inertial-frame coarse alignment of every recording of ``imu``.

    Parameters
    ----------
    imu : fusionbench.simulation.imudata.IMUData
        Body RFU increments or rates, R recordings, checked by the input policy.
    site : fusionbench.methods.aligner.Site
        Position at the start of the record.
    aiding : fusionbench.simulation.aiding.Aiding or None
        Rows for the R recordings, valid inside the record; None: a stationary or swaying base.
    history_points, fit_points : int
        Times at which the estimate is reported; fit times in the second half of the record (with aiding: blocks
        tiling the second half of the rows).
    level_window_s : float or None
        Seconds of specific force before each attitude its level is taken from (None: the fit's level).
    level_noise_max : float
        The largest level error (rad) the window's noise may cause for the level to be taken that way.
    who : str
        The name a refusal starts with (``"eso-td (coarse-i0 start)"`` as another method's first stage).
    name : str
        The result's method name.

    Returns
    -------
    AlignmentResult
        ``C_bn`` at ``history_points`` times of the second half of the record (not causal: each uses the fit over
        the whole record); ``extra``: ``fit_residual_mps`` (m/s) and ``gravity_excess`` (g) per recording.
    """
    t, dth, dv = imu.increments()
    R, N, _ = dth.shape
    keep = np.unique(np.linspace(0, N - 1, max(history_points, fit_points) * 4).round().astype(int))
    rows = None if aiding is None else aiding_rows(aiding, R, who)
    ckeep = vkeep = keep
    integral = lever = False
    if rows is not None:  # V at the increment ends around each row; C_b^b0 at the nearest for the lever arm
        pl = place(t, imu.t0, rows)
        integral = bool(pl.wide.any() or pl.kp.size)
        lever = bool(np.any(rows.lever_arm != 0) and rows.moving.any())
        vkeep = np.unique(np.concatenate([keep, pl.samples()]))
        if lever:
            near = np.concatenate([pl.near, pl.near_p])
            ckeep = np.unique(np.concatenate([keep, near[near >= 0]]))
    C_out, V_out = np.empty((R, ckeep.size, 3, 3)), np.empty((R, vkeep.size, 3))
    P_out = np.empty((R, vkeep.size if integral else 0, 3))
    step = max(1, CHUNK_SAMPLES // max(N, 1))  # runs at a time: each run's pass is its own
    for r in range(0, R, step):
        part = slice(r, r + step)
        n = dth[part].shape[0]
        C_b, dv_b = body_increments(dth[part], dv[part], np.zeros((n, 3)), np.zeros((n, 3)))
        body_pass(np.ascontiguousarray(C_b), np.ascontiguousarray(dv_b), imu.dt, ckeep, vkeep, C_out[part],
                  V_out[part], P_out[part])
    C_keep, V_keep = C_out[:, np.searchsorted(ckeep, keep)], V_out[:, np.searchsorted(vkeep, keep)]
    tk = t[keep] - imu.t0
    fit = np.unique(np.linspace(keep.size // 2, keep.size - 1, fit_points).round().astype(int))
    if rows is None:
        V_i0 = np.broadcast_to(gravity_integral_inertial(tk[fit], site.lat, site.g), (R, fit.size, 3))
        C_b0_i0, resid, excess = fit_rotation(V_i0, V_keep[:, fit])
        u = np.array([0.0, np.cos(site.lat), np.sin(site.lat)])
        C_n_i0 = np.broadcast_to(rotvec_to_dcm(np.outer(tk, u * earth.OMEGA_IE)), (R, keep.size, 3, 3))
        level_rows = None
    else:
        C_b0_i0, resid, excess, v, T, track = _aided_fit_by_runs(
            rows, pl, lambda part: imu_at_rows(pl, V_out[part], P_out[part], vkeep, C_out[part], ckeep, dth[part],
                                               imu.dt, lever), site, t, imu.t0, fit_points, who)
        lat_k, dlon_k = (np.stack([np.interp(t[keep], T, x[r]) for r in range(R)]) for x in track[:2])
        C_n_i0 = c_n_i0(tk, site.lat, lat_k, dlon_k)
        level_rows = (rows.tau, v)
    hist = np.linspace(0, keep.size - 1, history_points).round().astype(int)
    hist = np.unique(hist[hist >= fit[0]])
    C_bn = np.swapaxes(C_n_i0[:, hist], -1, -2) @ C_b0_i0[:, None] @ C_keep[:, hist]
    if level_window_s:
        C_bn = relevel(C_bn, hist, keep, t, tk, C_n_i0, C_b0_i0, V_keep, level_rows, site, level_window_s,
                       level_noise_max)
    # not causal: every attitude of the history uses the fit over the second half of the whole record (its
    # settling is measured on prefixes; the attitude at the last sample is what a user gets)
    return AlignmentResult(name, t[keep][hist], C_bn, {"fit_residual_mps": resid, "gravity_excess": excess},
                           causal=False)


def _aided_fit_by_runs(rows, pl, imu_rows, site, t, t0, fit_points, who):
    """:func:`fusionbench.methods.coarse_aided.aided_fit` a few recordings at a time (each recording's fit is its own):
    the same outputs, the runs joined. ``imu_rows(part)``: the :class:`~fusionbench.methods.coarse_aided.ImuAtRows`
    of the recordings ``part`` (a slice), formed a part at a time like the fit."""
    R, grid = rows.v.shape[0], rows.tau.size + pl.bridge.size + pl.kp.size
    step = max(1, CHUNK_SAMPLES // max(grid, 1))
    parts = [aided_fit(rows.runs(slice(r, r + step)), pl, imu_rows(slice(r, r + step)), site, t, t0, fit_points, who)
             for r in range(0, R, step)]
    if len(parts) == 1:
        return parts[0]
    C_b0_i0, resid, excess, v = (np.concatenate([p[i] for p in parts]) for i in range(4))
    track = tuple(np.concatenate([p[5][i] for p in parts]) for i in range(len(parts[0][5])))
    return C_b0_i0, resid, excess, v, parts[0][4], track
