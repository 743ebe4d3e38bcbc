"""The inertial-frame coarse alignment with aiding (``coarse-i0`` on a moving base): the fit on the rows.

:class:`fusionbench.methods.coarse.InertialCoarseAligner` fits ``V_i0 = C_b0^i0 V_b0`` (the specific force integrated in
the inertial frame i0 and in the frozen body frame b0). With aiding (:class:`fusionbench.simulation.aiding.Aiding`)
``V_i0`` comes from the rows, at their times of validity (``t - delay``), and ``V_b0`` from the IMU is interpolated to
the same times (it is known at the increment ends; a row between two is weighted linearly, exact for a row on one):

* **Velocity rows** give ``V_i0(tau) = C_n^i0(tau) v(tau) - C_n^i0(tau_0) v(tau_0) + int C_n^i0 (w_ie x v - g)``
  (:func:`fusionbench.methods.coarse_inertial.velocity_integral_inertial`, the integral by the trapezoid rule). A
  vertical velocity a row does not measure (NMEA VTG) is taken as zero.
* **Position rows alone** give the rotation in the fit's position (double-integral) form
  (:mod:`fusionbench.methods.coarse_position`: the positions enter with their own noise, not differenced: 1.8 arcmin of
  azimuth for 0.5 m at 1 Hz on a car, 14 differenced). Their differences
  (:meth:`fusionbench.simulation.aiding.Aiding.velocities_from_positions`: the mean velocity over each pair, at its
  middle, against the mean of ``V_b0`` over the pair, which the pass over the samples integrates) are the rows of the
  rest: the velocity form's diagnostics, the bridges, the track, the lever arm's passes.
* **Rows at rest**: the IMU's velocity, whatever the lever arm: the velocity they report (a fixed base's noisy zero,
  as the simulator's per-increment reference gives it), zero where they report none.
* **Gaps**: across an outage (an interval longer than 1.5 times the rows' median interval), before the first row
  and after the last, the trapezoid rule on the rows alone would integrate a straight line between them (a 60-s
  outage of a car's 1-Hz velocity: 1.2 arcmin of azimuth). There the IMU bridges: its velocity, navigated in i0 from
  the nearest row with the attitude of the previous fit (``C_n^i0 v = C_n^i0(tau_a) v_a + C_b0^i0 (V_b0 - V_b0(tau_a))
  - int C_n^i0 (w_ie x v - g)``), at increment ends spaced like the rows (at most :data:`BRIDGE_S`), enters the
  integral and the track, not the fit.
* **The local frame** ``C_n^i0(t)`` turns with the earth and is carried over it by the velocities (rows and
  bridges) integrated from the site (:func:`fusionbench.methods.coarse_inertial.integrate_track`).
* **The lever arm**: a row measures the antenna, ``v + C_bn (omega_nb^b x l)``, which needs the attitude: the rows
  are fitted as they are, the lever velocity (:func:`fusionbench.simulation.aiding_geometry.lever_velocity`) computed
  with the attitude found (``omega_nb^b`` the gyros' mean rate over the row's increment or interval less the navigation
  frame's rate) is taken off, and the rows are fitted again, :data:`PASSES` times (a 1.5-m lever arm on a car
  turning at 5 deg/s: 1.3 arcmin of azimuth ignored, 8e-4 after one pass, 8e-5 after two).
* **The blocks**: the rows' noise enters ``V_i0`` row by row, so both sides are averaged over ``fit_points`` blocks
  tiling the second half of the rows (by number), less their means over the first quarter (the anchor): rows at
  every increment end (``Aiding.from_vref``) tile the record as the per-increment fit of earlier versions did (in
  one pass: no lever arm, no gap), and an outage moves the blocks onto the rows there are (a 60-s outage of a car's
  10-Hz velocity of 0.05 m/s, perfect IMU: 1.3-1.7 arcmin of azimuth rms, against 1.0-1.3 without it and up to 3.8
  with the blocks fixed in the record's second half).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from fusionbench.methods.coarse_inertial import integrate_track, velocity_integral_inertial
from fusionbench.methods.coarse_position import displacement_integral, displacements, project_line
from fusionbench.simulation import earth
from fusionbench.simulation.aiding_geometry import bracket, lever_velocity, rate_at

#: Fits after the first, each with the lever velocity and the IMU's bridges of the gaps from the previous fit's
#: attitude (only with a lever arm or gaps).
PASSES = 2
#: Sweeps of the bridges per pass (each reduces their error by about OMEGA_IE times the gap).
BRIDGE_SWEEPS = 2
#: Longest spacing of the bridges' points, s.
BRIDGE_S = 1.0
#: Fewest position rows the position form takes (a constant and a line in time are projected out).
MIN_POSITIONS = 4


@dataclass
class Rows:
    """The aiding as the fit reads it: one velocity per row, at the row's time of validity.

    Attributes
    ----------
    tau : ndarray, shape (K,)
        Valid times, s (the IMU's clock), increasing.
    v : ndarray, shape (R, K, 3)
        Velocity over the earth, ENU, m/s: the antenna's, or the IMU's at rows at rest.
    moving : ndarray of bool, shape (K,)
        Rows the lever arm applies to (not at rest).
    span : ndarray, shape (K,)
        Interval, s, whose mean velocity a row gives (differenced positions); 0: the velocity at ``tau``.
    lever_arm : ndarray, shape (3,)
        IMU to antenna, body RFU, m.
    pos_t, pos : ndarray, shapes (Kp,) and (R, Kp, 3), or None
        Position rows without velocity rows (the fit's position form, :mod:`fusionbench.methods.coarse_position`): their
        valid times, s, and the antenna's latitude, longitude (rad) and height (m).
    """

    tau: np.ndarray
    v: np.ndarray
    moving: np.ndarray
    span: np.ndarray
    lever_arm: np.ndarray
    pos_t: np.ndarray | None = None
    pos: np.ndarray | None = None

    def runs(self, part: slice) -> Rows:
        """The rows of the recordings ``part`` (a slice of the R)."""
        return replace(self, v=self.v[part], pos=None if self.pos is None else self.pos[part])


def aiding_rows(aiding, runs, who) -> Rows:
    """The :class:`Rows` of ``aiding`` (an :class:`~fusionbench.simulation.aiding.Aiding` for ``runs`` recordings):
    its velocity rows (and rows at rest), else its position rows differenced. A one-line ``ValueError`` naming ``who``
    when there is neither."""
    vr = aiding.velocity_rows()
    if vr.any():
        tau = aiding.t_valid[vr]
        rest = np.zeros(tau.size, bool) if aiding.at_rest is None else aiding.at_rest[vr]
        v = np.zeros((runs, tau.size, 3)) if aiding.velocity is None else aiding.velocity[:, vr].copy()
        v[:, rest] = np.nan_to_num(v[:, rest])  # at rest without a velocity: zero
        span = np.zeros(tau.size)
    else:
        pr = aiding.position_rows()
        diff = aiding.velocities_from_positions() if pr.sum() >= MIN_POSITIONS else None
        if diff is None or diff.t.size < 2:
            raise ValueError(f"{who}: aiding: expected velocity rows or at least {MIN_POSITIONS} position rows with "
                             f"consecutive pairs, found {int(pr.sum())} position rows and no velocity")
        tau = diff.t_valid
        tv = aiding.t_valid[pr]
        b = np.clip(np.searchsorted(tv, tau), 1, tv.size - 1)
        span = tv[b] - tv[b - 1]
        v, rest = diff.for_runs(runs).velocity.copy(), np.zeros(tau.size, bool)
        v[..., 2] = np.nan_to_num(v[..., 2])
        return Rows(tau, v, ~rest, span, aiding.lever_arm, tv, aiding.for_runs(runs).position[:, pr])
    v[..., 2] = np.nan_to_num(v[..., 2])  # a vertical velocity not measured: level ground
    return Rows(tau, v, ~rest, span, aiding.lever_arm)


@dataclass
class Placement:
    """Where the rows fall on the IMU record (:func:`place`): for each row (K,) the increment ``k`` it falls in and
    its fraction ``w`` of it (:func:`fusionbench.simulation.aiding_geometry.bracket`), the nearest increment end
    ``near`` (-1: the initial state); the interval ``(a, b)`` (s) over which a row's velocity is a mean (``wide``
    rows, differenced positions; ``a == b`` otherwise) and the same for its ends ``(ka, wa)``, ``(kb, wb)``; the
    increment ends ``bridge`` (B,) where the IMU bridges the gaps (module docstring); for position rows (the position
    form) the increment ``kp`` each falls in, its fraction ``wp`` and the nearest increment end ``near_p`` (empty
    without)."""

    k: np.ndarray
    w: np.ndarray
    near: np.ndarray
    wide: np.ndarray
    a: np.ndarray
    b: np.ndarray
    ka: np.ndarray
    wa: np.ndarray
    kb: np.ndarray
    wb: np.ndarray
    bridge: np.ndarray
    kp: np.ndarray
    wp: np.ndarray
    near_p: np.ndarray

    def samples(self):
        """The increment ends (sorted, unique) after which the pass over the samples must keep ``V`` (and its
        integral for wide rows)."""
        s = np.concatenate([self.k, self.k - 1, self.ka, self.ka - 1, self.kb, self.kb - 1, self.bridge, self.kp,
                            self.kp - 1])
        return np.unique(s[s >= 0])

    def v_b0(self, V_out, P_out, vkeep):
        """``V_b0`` (R, K, 3), m/s, at the rows: interpolated linearly between the increment ends around each row,
        or for wide rows its mean over the row's interval (the integral ``P_out`` differenced), from the values
        ``V_out``, ``P_out`` (R, len(vkeep), 3) kept after the samples ``vkeep``."""
        def at(X, k, w):
            return (1.0 - w)[None, :, None] * at_samples(X, vkeep, k - 1, 0.0) \
                + w[None, :, None] * at_samples(X, vkeep, k, 0.0)
        V = at(V_out, self.k, self.w)
        if self.wide.any():
            wd = self.wide
            V[:, wd] = (at(P_out, self.kb[wd], self.wb[wd]) - at(P_out, self.ka[wd], self.wa[wd])) \
                / (self.b - self.a)[wd][None, :, None]
        return V


def place(t_end, t0, rows) -> Placement:
    """The :class:`Placement` of ``rows`` on the increments ending at ``t_end`` (N,) s from the initial state ``t0``."""
    k, w = bracket(t_end, t0, rows.tau)
    a, b = rows.tau - 0.5 * rows.span, rows.tau + 0.5 * rows.span
    kp, wp = bracket(t_end, t0, rows.pos_t) if rows.pos is not None else (np.zeros(0, int), np.zeros(0))
    return Placement(k, w, np.where(w >= 0.5, k, k - 1), rows.span > 0, a, b, *bracket(t_end, t0, a),
                     *bracket(t_end, t0, b), _bridge(t_end, t0, rows.tau), kp, wp, np.where(wp >= 0.5, kp, kp - 1))


def _bridge(t_end, t0, tau):
    """Increment ends (indices, sorted) inside the gaps of the rows at ``tau`` (s), before the first and after the
    last (the last sample always, unless a row is there): spaced like the rows, at most :data:`BRIDGE_S`."""
    dt = (t_end[-1] - t0) / t_end.size
    med = float(np.median(np.diff(tau))) if tau.size > 1 else t_end[-1] - t0
    step = max(1, int(round(min(med, BRIDGE_S) / dt)))
    edges = np.concatenate([[t0], tau, [t_end[-1]]])
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        if hi - lo > 1.5 * med:
            i0, i1 = np.searchsorted(t_end, [lo, hi], side="right")
            out.append(np.arange(i0 + step - 1, i1, step))
    out.append([t_end.size - 1])
    idx = np.unique(np.concatenate(out)).astype(int)
    k_rows, w_rows = bracket(t_end, t0, tau)
    return idx[~np.isin(idx, k_rows[w_rows == 1.0])]


def at_samples(out, kept, s, first):
    """What the pass over the samples kept, ``out`` (R, len(kept), ...) after the samples ``kept``, at the samples
    ``s`` (K,) (each one of ``kept``, or -1, the initial state: ``first``)."""
    vals = out[:, np.searchsorted(kept, np.maximum(s, 0))]
    vals[:, s < 0] = first
    return vals


def mean_rate(dth, dt, pl):
    """The gyros' rate (R, K, 3), rad/s, body frame, at each row of :class:`Placement` ``pl``
    (:func:`fusionbench.simulation.aiding_geometry.rate_at`), or the mean over a wide row's interval (the angle
    increments ``dth`` (R, N, 3) rad summed, their non-commutativity, second order in the angle, neglected); ``dt``
    the sample interval, s."""
    rate = rate_at(dth, dt, pl.k, pl.w)
    if pl.wide.any():
        theta = np.concatenate([np.zeros((dth.shape[0], 1, 3)), np.cumsum(dth, axis=1)], axis=1)

        def angle(j, f):
            return theta[:, j] + f[None, :, None] * dth[:, j]

        wd = pl.wide
        rate[:, wd] = (angle(pl.kb[wd], pl.wb[wd]) - angle(pl.ka[wd], pl.wa[wd])) / (pl.b - pl.a)[wd][None, :, None]
    return rate


def fit_rotation(V_i0, V_b0):
    """``C_b0^i0`` (R, 3, 3) with ``V_i0 ~ C_b0^i0 V_b0`` (Wahba's problem, per run, over (R, n, 3) m/s), the rms
    residual (R,) m/s once a common scale s is allowed, and ``1 / s - 1`` (R,), the specific force's excess over
    the model's gravity."""
    R = V_i0.shape[0]
    C, resid, excess = np.empty((R, 3, 3)), np.empty(R), np.empty(R)
    for r in range(R):
        rot, _ = Rotation.align_vectors(V_i0[r], V_b0[r])
        C[r] = rot.as_matrix()
        a = rot.apply(V_b0[r])
        s = np.sum(a * V_i0[r]) / np.sum(a * a)  # the common scale (the same rotation is optimal)
        resid[r] = np.sqrt(np.mean(np.sum((V_i0[r] - s * a) ** 2, axis=-1)))
        excess[r] = 1.0 / s - 1.0
    return C, resid, excess


def fit_blocks(k, fit_points, t_end, who):
    """The rows' blocks: row ranges ``(start, stop)`` (B + 1,) each, the anchor first, then the non-empty fit
    blocks, for K rows (``k`` (K,) the increments they fall in, increasing): the anchor the first quarter of the
    rows, the fit blocks ``fit_points`` tiles of their second half (by number: rows at every increment end tile
    the record as the per-increment fit did; an outage moves the tiles to the rows there are)."""
    K = k.size
    edges = np.concatenate([[0, max(1, K // 4)], np.linspace(K // 2, K, fit_points + 1).round().astype(int)])
    starts, stops = np.r_[edges[0], edges[2:-1]], np.r_[edges[1], edges[3:]]
    full = stops > starts
    if full[0] and full[1:].sum() >= 2:
        return starts[full], stops[full]
    raise ValueError(f"{who}: aiding: expected at least 3 rows, found {K} from {t_end[k[0]]:.3f} to "
                     f"{t_end[k[-1]]:.3f} s")


@dataclass
class ImuAtRows:
    """What the IMU gives at the rows (:func:`imu_at_rows`).

    Attributes
    ----------
    V, V_bridge : ndarray, shapes (R, K, 3) and (R, B, 3)
        ``V_b0`` at the rows (:meth:`Placement.v_b0`) and at the bridges' increment ends, m/s, frozen body frame b0.
    P_pos : ndarray, shape (R, Kp, 3), or None
        ``P_b0 = int V_b0`` at the position rows (the position form), m.
    C, C_pos : ndarray, shapes (R, K, 3, 3) and (R, Kp, 3, 3), or None
        ``C_b^b0`` at the nearest increment end of each row and position row (with a lever arm only).
    w : ndarray, shape (R, K, 3), or None
        The gyros' mean rate at each row (:func:`mean_rate`), body frame, rad/s (with a lever arm only).
    """

    V: np.ndarray
    V_bridge: np.ndarray
    P_pos: np.ndarray | None
    C: np.ndarray | None
    C_pos: np.ndarray | None
    w: np.ndarray | None


def imu_at_rows(pl, V_out, P_out, vkeep, C_out, ckeep, dth, dt, lever) -> ImuAtRows:
    """The :class:`ImuAtRows` of :class:`Placement` ``pl`` from what the pass over the samples kept (``V_out``,
    ``P_out`` after the samples ``vkeep``; ``C_out`` after ``ckeep``) and the angle increments ``dth`` (R, N, 3) rad
    of interval ``dt`` s; ``lever``: whether the lever arm's quantities are needed."""
    pos = pl.kp.size > 0
    P_pos = None
    if pos:
        P_pos = (1.0 - pl.wp)[None, :, None] * at_samples(P_out, vkeep, pl.kp - 1, 0.0) \
            + pl.wp[None, :, None] * at_samples(P_out, vkeep, pl.kp, 0.0)
    return ImuAtRows(pl.v_b0(V_out, P_out, vkeep), at_samples(V_out, vkeep, pl.bridge, 0.0), P_pos,
                     at_samples(C_out, ckeep, pl.near, np.eye(3)) if lever else None,
                     at_samples(C_out, ckeep, pl.near_p, np.eye(3)) if lever and pos else None,
                     mean_rate(dth, dt, pl) if lever else None)


def aided_fit(rows, pl, imu, site, t_end, t0, fit_points, who):
    """``C_b0^i0`` from the rows (module docstring; position rows alone: the position form of
    :mod:`fusionbench.methods.coarse_position`).

    Parameters
    ----------
    rows : Rows
    pl : Placement
        Where the rows, the bridges and the position rows fall on the record.
    imu : ImuAtRows
        What the IMU gives there.
    site : fusionbench.methods.aligner.Site
        Latitude (rad) and height (m) at ``t0``.
    t_end : ndarray, shape (N,)
        The IMU's increment ends, s; ``t0`` its initial state, s (the instant of i0).
    fit_points : int
        Blocks over the second half of the rows' span.
    who : str
        The method's name for messages.

    Returns
    -------
    C_b0_i0 : ndarray, shape (R, 3, 3)
    resid, excess : ndarray, shape (R,)
        As :func:`fit_rotation`, of the velocity form's blocks (m/s; in g).
    v : ndarray, shape (R, K, 3)
        The IMU's velocity at the rows (the lever velocity taken off), ENU m/s.
    T, track : ndarray (M,) and tuple of ndarray
        The grid's times (s: the rows', the bridges' and the position rows') and the track there: latitude (rad),
        longitude from the start (rad), height (m), each (R, M).
    """
    starts, stops = fit_blocks(pl.k, fit_points, t_end, who)
    R, K, _ = rows.v.shape
    B, Kp = pl.bridge.size, pl.kp.size
    T = np.concatenate([rows.tau, t_end[pl.bridge], rows.pos_t if Kp else np.zeros(0)])
    order = np.argsort(T, kind="stable")
    T, where = T[order], np.argsort(order)
    at_row, at_br, at_pos = where[:K], where[K:K + B], where[K + B:]
    Vb = np.concatenate([imu.V, imu.V_bridge, np.zeros((R, Kp, 3))], axis=1)[:, order]
    start = at_row[np.clip(np.searchsorted(rows.tau, T[at_br]) - 1, 0, K - 1)]  # each bridge's row: the one before
    known = np.sort(np.concatenate([at_row, at_br]))

    def interpolate(vm, at, src):  # vm at grid points ``at`` linearly from grid points ``src`` (held beyond them)
        for r in range(R):
            vm[r, at] = np.stack([np.interp(T[at], T[src], vm[r, src, i]) for i in range(3)], axis=-1)

    vm = np.zeros((R, T.size, 3))
    vm[:, at_row] = rows.v
    interpolate(vm, np.concatenate([at_br, at_pos]), at_row)  # the bridges start as a straight line between rows
    v, lever, C_bn_pos = rows.v, imu.C is not None, None
    C_n = C_b0_i0 = track = V_i0 = None  # each pass's, for the next
    for npass in range(1 + PASSES * (lever or B > 0)):
        if npass and lever:  # the antenna's velocity less the lever velocity, with the last fit's attitude
            C_bn = np.swapaxes(C_n[:, at_row], -1, -2) @ C_b0_i0[:, None] @ imu.C
            lat, h = track[0][:, at_row], track[2][:, at_row]
            w_in = earth.earth_rate_n(lat) + earth.transport_rate_n(v, lat, h)
            w_nb = imu.w - np.einsum("rkji,rkj->rki", C_bn, w_in)
            v = rows.v - lever_velocity(C_bn, w_nb, rows.lever_arm) * rows.moving[None, :, None]
            if Kp:
                C_bn_pos = np.swapaxes(C_n[:, at_pos], -1, -2) @ C_b0_i0[:, None] @ imu.C_pos
        vm[:, at_row] = v
        for _ in range(BRIDGE_SWEEPS if npass and B else 0):  # the IMU's velocity at the bridges
            interpolate(vm, at_pos, known)
            track = integrate_track(T, t0, vm, site.lat, site.h)
            V_i0, C_n = velocity_integral_inertial(T, t0, vm, site.lat, site.h, track=track)
            miss = np.einsum("rij,rkj->rki", C_b0_i0, Vb[:, at_br] - Vb[:, start]) - (V_i0[:, at_br] - V_i0[:, start])
            vm[:, at_br] += np.einsum("rkji,rkj->rki", C_n[:, at_br], miss)
        if Kp:
            interpolate(vm, at_pos, known)
        track = integrate_track(T, t0, vm, site.lat, site.h)
        V_i0, C_n = velocity_integral_inertial(T, t0, vm, site.lat, site.h, track=track)
        blocks = []
        for X in (V_i0[:, at_row], imu.V):  # block means from cumulative sums (the blocks are contiguous row ranges)
            cs = np.concatenate([np.zeros((R, 1, 3)), np.cumsum(X, axis=1)], axis=1)
            m = (cs[:, stops] - cs[:, starts]) / (stops - starts)[None, :, None]
            blocks.append(m[:, 1:] - m[:, :1])
        C_b0_i0, resid, excess = fit_rotation(*blocks)
        if Kp:  # position rows: the position form's rotation (the velocity form's residual stays the diagnostic)
            D = displacement_integral(T, vm, V_i0, C_n, at_pos, displacements(rows.pos, C_bn_pos, rows.lever_arm))
            C_b0_i0 = fit_rotation(project_line(D, rows.pos_t), project_line(imu.P_pos, rows.pos_t))[0]
    return C_b0_i0, resid, excess, v, T, track
