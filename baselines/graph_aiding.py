"""The aiding in the factor graph (:mod:`baselines.factor_graph`): from a
:class:`fusionbench.simulation.aiding.Aiding` to the graph's rows, the moving-base compensation of the preintegration,
and the data of the tile factors (:mod:`baselines.graph_rows`) at the rows' times of validity.

* **Rows.** A velocity row measures the antenna's velocity at ``tau = t - delay``: ``v(tau) + C_bn(tau) (omega_nb^b x
  l)`` (:func:`fusionbench.simulation.aiding_geometry.lever_velocity`); a row at rest measures the IMU's velocity,
  zero (or the noisy zero it reports), with no lever arm. A position row measures the antenna at ``p(tau) + C_bn(tau)
  l``: its ENU offset from the site (:func:`fusionbench.simulation.aiding_geometry.enu_offset`) put into the graph's
  coordinates, the integral of the ENU velocity (:func:`path_offsets`). Each row weighs ``(sigma_ref / sigma_row)^2``
  on each axis it measures (its own sigma, else the method's), nothing on the others. Without aiding the base is
  fixed: a zero velocity at every increment end.
* **Lever arm.** ``C_bn(tau) = R_k C_{b_k}^{b(tau)}`` with ``R_k`` the keyframe's attitude and the relative rotation
  from the gyros, so the lever terms ``C_{b_k}^{b(tau)} (omega_nb^b x l)`` and ``C_{b_k}^{b(tau)} l`` join the
  IMU's increments ``U`` of the tile factor and enter its attitude Jacobian exactly; only ``omega_nb^b = omega_ib^b
  - C_bn^T omega_in^n`` takes the current attitude (a 1e-4 m/s term for a 1.5-m arm), and the graph is rebuilt
  when that moves. The gyros' rate at ``tau`` is interpolated between the mean rates of the samples around it.
* **Moving-base compensation** (:func:`motion`). The transport rate, the Coriolis acceleration of each sample,
  gravity along the path and gtsam's centrifugal term need the velocity at every sample and the position at the
  keyframes: the velocity rows interpolated linearly in time (or the positions differenced,
  :meth:`fusionbench.simulation.aiding.Aiding.velocities_from_positions`, when no velocity of a moving base is
  measured), integrated, and shifted onto the position rows when there are some. With rows at every increment end that
  is the reference itself; otherwise, once solved, the compensation is redone from the solution's own velocity at
  every sample and position at every keyframe (:func:`motion_from_solution`), which bridges outages and the
  rows' noise.
"""

from __future__ import annotations

import numpy as np
import gtsam
from gtsam.symbol_shorthand import B

from fusionbench.simulation import earth
from fusionbench.simulation.aiding_geometry import bracket, enu_offset, lever_offset, lever_velocity

from .graph_rows import (at_rows, axis_means, integral_at_rows, mean_at_rows, row_rotations, tile_increments,
                         tile_scatter, tile_sums, tiles)
from .graph_support import compensated_increments

#: Standard deviation of a position row without its own, m (the default of the graphs' ``aiding_position_sigma``):
#: a single-frequency GNSS fix with SBAS corrections, horizontally; give the rows' own (``Aiding.sigma_p``) for others.
POSITION_SIGMA = 1.0
#: Smallest standard deviation of a row used, m/s and m: an exact row still gives a well-conditioned factor.
ROW_SIGMA_FLOOR = 1e-3


def recording_rows(aiding, r, t_end, site, vref_sigma, position_sigma):
    """The velocity and position rows of recording ``r`` (module docstring).

    Parameters
    ----------
    aiding : fusionbench.simulation.aiding.Aiding or None
        Rows for all recordings (arrays (R, K, 3)); None: a fixed base.
    r : int
        The recording.
    t_end : ndarray, shape (M,)
        The increment ends, s.
    site : fusionbench.methods.aligner.Site
        The origin of the positions.
    vref_sigma, position_sigma : float
        Standard deviation of a velocity row (m/s) and of a position row (m) without their own: the unit weights.

    Returns
    -------
    dict
        ``vel`` and ``pos``: None, or the rows' valid times ``t`` (n,) s, measured values ``z`` (n, 3) (ENU m/s, or
        m from the site), weights ``W`` (n, 3) (0 on an axis not measured) and, for velocities, ``lever`` (n,) bool
        (False at rest); ``lever_arm`` (3,) m, body RFU; ``dense`` (bool) the rows are velocities at every
        increment end (no positions).
    """
    M = t_end.size
    if aiding is None:
        return {"vel": {"t": t_end, "z": np.zeros((M, 3)), "W": np.ones((M, 3)), "lever": np.zeros(M, bool)},
                "pos": None, "lever_arm": np.zeros(3), "dense": True}
    K, tv = aiding.t.size, aiding.t_valid
    out = {"vel": None, "pos": None, "lever_arm": np.asarray(aiding.lever_arm, dtype=float)}
    if aiding.velocity is not None or aiding.at_rest is not None:
        val = np.full((K, 3), np.nan) if aiding.velocity is None else aiding.velocity[r]
        rest = np.zeros(K, bool) if aiding.at_rest is None else aiding.at_rest
        meas = np.isfinite(val) | rest[:, None]
        sig = vref_sigma if aiding.sigma_v is None else np.maximum(aiding.sigma_v, ROW_SIGMA_FLOOR)
        W = np.where(meas, (vref_sigma / sig) ** 2, 0.0)
        keep = meas.any(axis=1)
        if keep.any():
            out["vel"] = {"t": tv[keep], "z": np.where(meas, np.nan_to_num(val), 0.0)[keep], "W": W[keep],
                          "lever": ~rest[keep]}
    if aiding.position is not None:
        pos = aiding.position[r]
        meas = np.isfinite(pos)
        meas[:, :2] = meas[:, :2].all(axis=1, keepdims=True)
        keep = meas[:, 0]
        if keep.any():
            sig = position_sigma if aiding.sigma_p is None else np.maximum(aiding.sigma_p, ROW_SIGMA_FLOOR)
            W = np.where(meas, (position_sigma / sig) ** 2, 0.0)
            z = np.where(meas, enu_offset(np.nan_to_num(pos), np.array([site.lat, site.lon, site.h])), 0.0)
            out["pos"] = {"t": tv[keep], "z": z[keep], "W": W[keep]}
    rows = out["vel"]
    out["dense"] = (out["pos"] is None and rows is not None and rows["t"].size == M and bool(np.all(rows["W"] > 0))
                    and np.allclose(rows["t"], t_end, rtol=0.0, atol=1e-6 * (t_end[-1] - t_end[0]) / M))
    return out


def _interp(t, rows):
    """Rows' values (``t``, ``z``, ``W``) interpolated linearly at times ``t`` (M,) on each measured axis (zero on
    an axis never measured), (M, 3)."""
    out = np.zeros((t.size, 3))
    for a in range(3):
        m = rows["W"][:, a] > 0
        if m.any():
            out[:, a] = np.interp(t, rows["t"][m], rows["z"][m, a])
    return out


def motion(v, p_kf, counts, dt, site):
    """The moving-base compensation of one recording from its velocity ``v`` (M, 3), ENU m/s, at the increment
    ends and its positions ``p_kf`` (K, 3), m from the site, at the keyframes (``counts`` (K,) the keyframes'
    sample counts, ``dt`` s).

    Returns a dict: ``p_kf``; per keyframe interval ``w_in`` (K-1, 3) rad/s the turn rate of ENU (earth and
    transport rate at the interval's mean velocity, latitude and height), ``g`` (K-1,) m/s^2 gravity there and
    ``c_n`` (K-1, 3) m/s^2 the specific-force correction ``omega_en x v + omega_in x (omega_in x p)`` (gtsam
    applies ``2 omega_in x v`` where ENU needs ``(2 omega_ie + omega_en) x v``, and the centrifugal term of a frame
    turning about an axis through the origin, which normal gravity holds already); per sample ``w_s`` (M, 3) the turn
    rate of ENU and ``a_s`` (M, 3) ``g - (2 omega_ie + omega_en) x v``.
    """
    K, M = counts.size, v.shape[0]
    interval = np.minimum(np.searchsorted(counts, np.arange(M), side="right") - 1, K - 2)
    v_bar = np.diff(p_kf, axis=0) / (np.diff(counts) * dt)[:, None]
    p_mid = 0.5 * (p_kf[1:] + p_kf[:-1])
    rm, _ = earth.radii(site.lat)
    lat = site.lat + p_mid[:, 1] / (rm + site.h)
    h = site.h + p_mid[:, 2]
    w_ie = earth.earth_rate_n(lat)
    w_en = earth.transport_rate_n(v_bar, lat, h)
    w_in = w_ie + w_en
    g = earth.gravity(lat, h)
    c_n = np.cross(w_en, v_bar) + np.cross(w_in, np.cross(w_in, p_mid))
    g_s = np.zeros((M, 3))
    g_s[:, 2] = -g[interval]
    return {"p_kf": p_kf, "w_in": w_in, "c_n": c_n, "g": g, "w_s": w_in[interval],
            "a_s": g_s - np.cross((w_in + w_ie)[interval], v)}


def build_problem(rows, site, t_end, t_kf, counts, dt, dtheta, dvel, C0=None, differenced=None):
    """What does not depend on the attitude, for one recording (a dict).

    Parameters
    ----------
    rows : dict
        The recording's rows (:func:`recording_rows`).
    site : fusionbench.methods.aligner.Site
    t_end : ndarray, shape (M,)
        Increment ends, s.
    t_kf : ndarray, shape (K,)
        Keyframe times, s (the first the record's initial state).
    counts : ndarray of int, shape (K,)
        Keyframe sample counts.
    dt : float
        Sample interval, s.
    dtheta, dvel : ndarray, shape (M, 3)
        The recording's increments, rad and m/s, body frame.
    C0 : ndarray, shape (3, 3), optional
        The attitude prior's mean.
    differenced : dict, optional
        Velocity rows differenced from the positions (``t``, ``z``, ``W``), for the compensation when no velocity
        of a moving base is measured (none, or only rows at rest).

    Returns
    -------
    dict
        ``phi``, ``dv`` (M, 3) the compensated increments; ``tile`` (M,) the samples' keyframes, ``u`` (M, 3) their
        velocity increments in the keyframes' body frames, ``R_start`` (M, 3, 3) those frames in the samples' (at
        their start), ``U`` (M, 3) m/s and ``Mb`` (M, 3, 3) s the sums of ``u`` and of ``mb = R_start dt`` from the
        keyframe to each sample's end, ``tau`` (M,) each sample's start less its keyframe's time; ``vel``, ``pos``
        the rows with their samples ``j``, fractions ``w``, tiles ``tile``, rotations ``Rr`` (n, 3, 3) (with a lever
        arm), ``U_rows`` (n, 3) and ``Mb_rows`` (n, 3, 3): ``U`` and ``Mb`` at the rows' times (velocity rows, m/s and
        s) or their integrals from the keyframe (position rows, m and s^2, with the lever arm's offset), and adaptive
        ``scale`` (n,) (1); the compensation (:func:`motion`); ``v_kf`` (K, 3) the reference
        velocity at the keyframes; ``refine_motion`` whether the compensation is to be redone from the solution
        (rows of a moving base elsewhere than at every increment end).
    """
    phi, dv = compensated_increments(dtheta, dvel)
    tile = tiles(t_end, t_kf)
    u, R_start = tile_increments(phi, dv, counts, tile)
    mb = R_start * dt
    lever = bool(np.any(rows["lever_arm"]))
    out = {"phi": phi, "dv": dv, "dt": dt, "counts": counts, "t_end": t_end, "t_kf": t_kf, "tile": tile, "u": u,
           "R_start": R_start, "U": tile_sums(u, tile, counts), "mb": mb, "Mb": tile_sums(mb, tile, counts),
           "tau": t_end - dt - t_kf[tile], "C0": C0, "lever_arm": rows["lever_arm"],
           "refine_motion": not rows["dense"] and (rows["pos"] is not None or bool(rows["vel"]["lever"].any()))}
    for name in ("vel", "pos"):
        g = rows[name]
        if g is not None:
            j, w = bracket(t_end, t_kf[0], g["t"])
            g = {**g, "j": j, "w": w, "tile": tile[j], "scale": np.ones(j.size)}
            if lever:
                g["Rr"] = row_rotations(R_start, phi, j, w)
            if name == "pos":
                g["dtk"] = g["t"] - t_kf[g["tile"]]
                g["U_rows"] = integral_at_rows(out["U"], u, j, w, dt, tile, counts)
                if lever:
                    g["U_rows"] += lever_offset(g["Rr"], rows["lever_arm"])
                g["Mb_rows"] = integral_at_rows(out["Mb"], mb, j, w, dt, tile, counts)
            else:
                g["U_rows"], g["Mb_rows"] = at_rows(out["U"], u, j, w), at_rows(out["Mb"], mb, j, w)
        out[name] = g
    source = rows["vel"]
    if differenced is not None and (source is None or not source["lever"].any()):  # no velocity of a moving base
        both = [g for g in (source, differenced) if g is not None]
        order = np.argsort(np.concatenate([g["t"] for g in both]), kind="stable")
        source = {k: np.concatenate([g[k] for g in both])[order] for k in ("t", "z", "W")}
    v = np.zeros((t_end.size, 3)) if source is None else (source["z"] if rows["dense"] else _interp(t_end, source))
    v_prev = np.vstack([v[:1], v[:-1]])
    p = np.vstack([np.zeros((1, 3)), np.cumsum(0.5 * (v + v_prev) * dt, axis=0)])
    if rows["pos"] is not None:  # the integrated velocity onto the positions (the antenna's, within the lever arm)
        pr = rows["pos"]
        at = np.stack([np.interp(pr["t"], np.r_[t_kf[0], t_end], p[:, a]) for a in range(3)], axis=1)
        p = p + np.sum(pr["W"] * (pr["z"] - at), axis=0) / np.maximum(pr["W"].sum(axis=0), 1e-300)
    out["v_kf"] = v[np.maximum(counts - 1, 0)]
    return _with_motion(out, v, p[counts], site)


def _velocity_changes(problem, C_kf):
    """The attitude-free part of the velocity change over each sample (M, 3), m/s: gravity and Coriolis, and the
    turn of ENU since the keyframe (small, with attitudes ``C_kf`` (K, 3, 3)); and its :func:`tile_sums`."""
    pr = problem
    turn = -np.cross(pr["w_s"] * pr["tau"][:, None], np.einsum("mij,mj->mi", C_kf[pr["tile"]], pr["u"]))
    x = pr["a_s"] * pr["dt"] + turn
    return x, tile_sums(x, pr["tile"], pr["counts"])


def tile_data(problem, C_kf):
    """The tile factors' data at attitudes ``C_kf`` (K, 3, 3) (:func:`baselines.graph_rows.tile_error`): ``v`` and
    ``p`` (None without such rows), each with the tiles' means (``z``, ``U``, ``Mb``, ``c_v``, ``var`` (K, 3) the
    variance of a mean per unit row variance) and the rows' own ``y`` (the measurement less the attitude-free part of
    the prediction), ``Urow``, ``Mbrow`` and weights ``W`` (for the scatter)."""
    pr = problem
    K, dt, l = pr["counts"].size, pr["dt"], pr["lever_arm"]
    x, G = _velocity_changes(pr, C_kf)
    out = {"v": None, "p": None}
    g = pr["vel"]
    if g is not None:
        j, w = g["j"], g["w"]
        y = g["z"] - at_rows(G, x, j, w)
        U = g["U_rows"].copy()
        if "Rr" in g and g["lever"].any():
            m = g["lever"]
            Rr = g["Rr"][m]
            C_row = C_kf[g["tile"][m]] @ Rr
            w_nb = mean_at_rows(pr["phi"] / dt, j[m], w[m]) - np.einsum("nji,nj->ni", C_row, pr["w_s"][j[m]])
            U[m] += lever_velocity(Rr, w_nb, l)
        Mb = g["Mb_rows"]
        W = g["W"] * g["scale"][:, None]
        var, (z, Ub, Mbb) = axis_means(g["tile"], K, W, per_axis=[y], shared=[U, Mb])
        out["v"] = {"z": z, "U": Ub, "Mb": Mbb, "c_v": np.ones((K, 3)), "position": False, "var": var, "y": y,
                    "Urow": U, "Mbrow": Mb, "W": W}
    g = pr["pos"]
    if g is not None:
        j, w, tl, cnt = g["j"], g["w"], pr["tile"], pr["counts"]
        y = g["z"] + g["dz"] - integral_at_rows(G, x, j, w, dt, tl, cnt)
        U, Mb = g["U_rows"], g["Mb_rows"]
        W = g["W"] * g["scale"][:, None]
        var, (z, c_v, Ub, Mbb) = axis_means(g["tile"], K, W, per_axis=[y, np.repeat(g["dtk"][:, None], 3, 1)],
                                            shared=[U, Mb])
        out["p"] = {"z": z, "U": Ub, "Mb": Mbb, "c_v": c_v, "position": True, "var": var, "y": y, "Urow": U,
                    "Mbrow": Mb, "W": W}
    return out


def row_scatter(problem, data, group, C_kf, b_acc):
    """The rows' weighted scatter about what the solution (attitudes ``C_kf`` (K, 3, 3), accelerometer biases
    ``b_acc`` (K, 3) per keyframe) predicts at their times, per keyframe, less a straight line per tile, and its
    degrees of freedom (:func:`baselines.graph_rows.tile_scatter`); ``group`` ``"v"`` or ``"p"``, ``data`` the
    :func:`tile_data` at the solution."""
    d, g = data[group], problem["vel" if group == "v" else "pos"]
    tl = g["tile"]
    r = d["y"] - np.einsum("nij,nj->ni", C_kf[tl], d["Urow"] - np.einsum("nij,nj->ni", d["Mbrow"], b_acc[tl]))
    return tile_scatter(r, tl, g["t"], problem["t_kf"], d["W"])


def motion_from_solution(problem, site, C_kf, v_kf, p_kf, b_acc):
    """The problem with its compensation (:func:`motion`) redone from a solution: the velocity at every sample that
    the keyframes' velocities ``v_kf`` (K, 3) m/s, attitudes ``C_kf`` (K, 3, 3) and accelerometer biases ``b_acc``
    (K, 3) m/s^2 predict with the IMU, and the keyframes' positions ``p_kf`` (K, 3) m."""
    pr = problem
    _, G = _velocity_changes(pr, C_kf)
    tl = pr["tile"]
    v = v_kf[tl] + np.einsum("mij,mj->mi", C_kf[tl], pr["U"] - np.einsum("mij,mj->mi", pr["Mb"], b_acc[tl])) + G
    return _with_motion({**pr, "refine_motion": False}, v, p_kf, site)


def _with_motion(problem, v, p_kf, site):
    """``problem`` with the compensation (:func:`motion`) of velocity ``v`` (M, 3) and keyframe positions ``p_kf``
    (K, 3), and its position rows' ``dz`` (n, 3), m: what turns their ENU offsets into the graph's coordinates
    (:func:`path_offsets` interpolated at their times)."""
    out = {**problem, **motion(v, p_kf, problem["counts"], problem["dt"], site)}
    g = out["pos"]
    if g is not None:
        d = path_offsets(v, p_kf[0], problem["dt"], site)
        t = np.r_[problem["t_kf"][0], problem["t_end"]]
        out["pos"] = {**g, "dz": np.stack([np.interp(g["t"], t, d[:, a]) for a in range(3)], axis=1)}
    return out


def path_offsets(v, p0, dt, site):
    """The graph's positions less the ENU offsets from the site
    (:func:`fusionbench.simulation.aiding_geometry.enu_offset`) along a path, (M + 1, 3), m, at the record's start and
    its increment ends.

    The graph's position is the integral of the ENU velocity ``v`` (M, 3), m/s (at the increment ends, ``dt`` s
    apart), from ``p0`` (3,) m; an ENU offset is a function of latitude, longitude and height, whose rates are
    ``v_N / (R_M + h)``, ``v_E / ((R_N + h) cos L)`` and ``v_U``. They differ by the meridians' convergence, second
    order in the distance over the earth's radius (millimetres over a kilometre or two, a metre over tens), which
    a position row read as the integral would put into the heading (0.08 arcmin on 1.5 km of a car's drive).
    """
    def integral(x, x0):
        x_prev = np.concatenate([x[:1], x[:-1]])
        return np.concatenate([[x0], x0 + np.cumsum(0.5 * (x + x_prev) * dt, axis=0)])

    p = integral(v, np.asarray(p0, dtype=float))
    rm, rn = earth.radii(site.lat)
    lat, h = site.lat + p[1:, 1] / (rm + site.h), site.h + p[1:, 2]  # first order: enough for the rates
    rm, rn = earth.radii(lat)
    lat0 = site.lat + p0[1] / (rm[0] + site.h)
    geo = np.stack([integral(v[:, 1] / (rm + h), lat0),
                    integral(v[:, 0] / ((rn + h) * np.cos(lat)), site.lon + p0[0] / ((rn[0] + site.h) * np.cos(lat0))),
                    integral(v[:, 2], site.h + p0[2])], axis=1)
    return p - enu_offset(geo, np.array([site.lat, site.lon, site.h]))


def keyframe_states(values, K, seg):
    """The keyframes' attitudes ``C_bn`` (K, 3, 3), positions (K, 3) m, velocities (K, 3) m/s and accelerometer
    biases (K, 3) m/s^2 in a solution (``gtsam.Values``; ``seg`` (K-1,) the bias key of each interval)."""
    poses = gtsam.utilities.extractPose3(values)  # (K, 12): every Pose3 in key order, R row-major then t
    vel = gtsam.utilities.extractVectors(values, "v")
    if poses.shape[0] != K or vel.shape[0] != K:
        raise ValueError(f"keyframe_states: expected {K} poses and velocities, found {poses.shape[0]} and "
                         f"{vel.shape[0]}")
    seg = np.asarray(seg)
    b_acc = np.stack([values.atConstantBias(B(j)).accelerometer() for j in range(int(seg.max()) + 1)])
    return (poses[:, :9].reshape(K, 3, 3).copy(), poses[:, 9:].copy(), vel,
            b_acc[seg[np.minimum(np.arange(K), K - 2)]])
