"""The aiding's measurement model of ``kf`` and ``akf`` (:mod:`baselines.kalman`): rows at their times of validity.

The filter steps every ``step_s``; each row valid within a step (:attr:`fusionbench.simulation.aiding.Aiding.t_valid`
in the step's ``(start, end]``) is compared with the strapdown's state interpolated at its valid time between the sample
ends bracketing it (:func:`fusionbench.simulation.aiding_geometry.bracket`):

* **velocity rows** (east, north; the height is held): ``z = v + C_bn (omega_nb^b x l) - v_row``, the lever-arm
  term's attitude coupling in H (``[a x]`` with ``a = C_bn (omega_nb^b x l)``, first order; the gyro bias's
  coupling through ``omega_nb^b``, ``eps x l``, is left out: 7e-6 m/s for a 1 deg/h gyro and 1.5 m);
* **rows at rest**: ``z = v - v_row`` (the IMU's velocity, no lever arm; ``v_row`` zero when the row has none);
* **position rows** (east, north, m; only when the aiding measures positions, which adds the position-error states):
  ``z = enu_offset(p, p_row) + C_bn l`` (:func:`fusionbench.simulation.aiding_geometry.enu_offset`,
  :func:`~fusionbench.simulation.aiding_geometry.lever_offset`), ``[(C_bn l) x]`` in H.

A row valid ``s`` seconds before the step's end measures the state there: its H is ``H (I - F s)`` (the step's own
error model, first order in s <= ``step_s``; the process noise between the row and the step's end, a step's at
most, is left out).

**One update per step.** The step's rows of each kind (velocity, position) make one measurement per channel at
the step's end: their weighted mean (weights 1 / sigma^2) of z and of H, with variance ``1 / sum(1 / sigma^2)``.
This is the stacked update of all the rows, less what the variation of H within one step carries (the velocity
error's slope over 0.1 s, which 10 rows of 0.01 m/s measure to 0.1 m/s^2 where f x phi is 1e-3 m/s^2, and the
lever arm's turn over a step), and costs the same 2- or 4-channel update whatever the rows' rate: the filters of
every Monte Carlo run step together (:class:`baselines.filter_bank.FilterBank`), rows at every IMU sample
included. Sequential updates per row would cost one update per row. Each row has its own sigma when it has one,
else the aligner's (``vref_sigma``, ``aiding_position_sigma``).

Without aiding the rows are the zero velocity of a fixed base at every step's end (as the filter always had).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fusionbench.simulation import earth
from fusionbench.simulation.aiding_geometry import bracket, displace, enu_offset, lever_offset, lever_velocity, rate_at
from fusionbench.simulation.attitude import rotvec_to_dcm, skew
from fusionbench.simulation.strapdown import NavState, Strapdown

#: Change of acceleration a vehicle may make between two rows, m/s^2: the error of a velocity (position)
#: interpolated over a gap of ``dt`` seconds is taken as this times ``dt / 4`` (``dt^2 / 8``) in the hand-over's
#: initial covariance (an overstatement there only costs the first update; an understatement tilts the level).
GAP_ACCEL_MPS2 = 2.0
#: Measurement channels: the indices :func:`step_measurement` returns name these (the adaptive variant adapts each).
CHANNELS = ("velocity east", "velocity north", "position east", "position north")


@dataclass
class Rows:
    """Aiding rows prepared for the filter: where each lies on the IMU record and what it measures.

    Attributes
    ----------
    k, w : ndarray, shape (n,)
        The increment containing each row's valid time and the fraction of it
        (:func:`fusionbench.simulation.aiding_geometry.bracket`).
    t_valid : ndarray, shape (n,)
        Valid time of each row, s.
    vel, rest, pos : ndarray of bool, shape (n,)
        The row measures the antenna's horizontal velocity; says the base is at rest; measures its horizontal
        position.
    v : ndarray, shape (R, n, 2)
        Measured velocity, east and north, m/s (zero where not measured).
    p : ndarray, shape (R, n, 3) or None
        Measured position (latitude, longitude rad, height m; NaN where not measured).
    sv, sp : ndarray, shape (n, 2)
        Standard deviations, east and north, m/s and m.
    lever : ndarray, shape (3,)
        IMU to antenna, body RFU, m.
    s : ndarray, shape (n,)
        Time from each row's valid time to the end of the filter step it falls in, s (:meth:`before_end`).
    wv, wp : ndarray, shape (n, 2)
        Weights ``1 / sv^2`` and ``1 / sp^2`` of the rows in a step's mean (set from ``sv`` and ``sp``).
    at_end : ndarray of bool, shape (n,)
        Rows valid at the end of their filter step (:meth:`before_end`).
    """

    k: np.ndarray
    w: np.ndarray
    t_valid: np.ndarray
    vel: np.ndarray
    rest: np.ndarray
    pos: np.ndarray
    v: np.ndarray
    p: np.ndarray | None
    sv: np.ndarray
    sp: np.ndarray
    lever: np.ndarray
    s: np.ndarray | None = None
    at_end: np.ndarray | None = None

    @property
    def has_position(self) -> bool:
        """Whether some row measures a position (the filter then carries position-error states)."""
        return bool(self.pos.any())

    def __post_init__(self):
        self.wv, self.wp = 1.0 / self.sv ** 2, 1.0 / self.sp ** 2  # the rows' weights in a step's mean

    def before_end(self, t_end, m):
        """Set :attr:`s` for filter steps of ``m`` increments ending at ``t_end`` (M,) s, and :attr:`at_end`."""
        ends = np.minimum((self.k // m + 1) * m - 1, np.size(t_end) - 1)
        self.s = np.where(np.isnan(self.t_valid), 0.0, t_end[ends] - self.t_valid)
        self.at_end = (self.k == ends) & (self.w == 1.0)
        return self

    def need_history(self, i0, i1) -> bool:
        """Whether rows ``i0`` to ``i1 - 1`` need the states inside their step (not only at its end)."""
        return not self.at_end[i0:i1].all()

    def span(self, a, b):
        """Indices ``(i0, i1)`` of the rows in the increments ``a`` to ``b - 1``."""
        return int(np.searchsorted(self.k, a, side="left")), int(np.searchsorted(self.k, b, side="left"))


def prepare_rows(aiding, t_end, t0, runs, vref_sigma, position_sigma, floor=0.0) -> Rows:
    """The rows of ``aiding`` (an :class:`~fusionbench.simulation.aiding.Aiding` for ``runs`` recordings, or None: no
    row) on the increments ending at ``t_end`` (M,) s from the initial state at ``t0`` s; ``vref_sigma`` (m/s) and
    ``position_sigma`` (m) for rows without their own sigma, every sigma at least ``floor``. Rows that measure
    nothing horizontal are dropped."""
    if aiding is None or not aiding.measures.any():
        none = np.zeros(0, bool)
        return Rows(np.zeros(0, int), np.zeros(0), np.zeros(0), none, none, none, np.zeros((runs, 0, 2)), None,
                    np.ones((0, 2)), np.ones((0, 2)), np.zeros(3))
    a = aiding.for_runs(runs)
    vel_rows, pos_rows = a.velocity_rows(), a.position_rows()
    keep = vel_rows | pos_rows
    a = a.rows(keep)
    vel_rows, pos_rows = vel_rows[keep], pos_rows[keep]
    n = a.t.size
    k, w = bracket(t_end, t0, a.t_valid)
    rest = np.zeros(n, bool) if a.at_rest is None else a.at_rest.copy()
    v = np.zeros((runs, n, 2))
    if a.velocity is not None:
        v = np.where(np.isfinite(a.velocity[..., :2]), a.velocity[..., :2], 0.0)
    sv = np.full((n, 2), vref_sigma) if a.sigma_v is None else a.sigma_v[:, :2].copy()
    sp = np.full((n, 2), position_sigma) if a.sigma_p is None else a.sigma_p[:, :2].copy()
    return Rows(k, w, a.t_valid, vel_rows, rest, pos_rows, v, a.position, np.maximum(sv, floor), np.maximum(sp, floor),
                a.lever_arm.copy())


def zero_velocity_rows(k_end, runs, sigma) -> Rows:
    """A fixed base without aiding: zero velocity (at rest) at the ends of the increments ``k_end`` (n,), with
    ``sigma`` m/s."""
    n = np.size(k_end)
    return Rows(np.asarray(k_end), np.ones(n), np.full(n, np.nan), np.zeros(n, bool), np.ones(n, bool),
                np.zeros(n, bool), np.zeros((runs, n, 2)), None, np.full((n, 2), sigma), np.full((n, 2), np.inf),
                np.zeros(3))


def step_measurement(rows, i0, i1, a, state, w_ib, F):
    """The measurement of rows ``i0`` to ``i1 - 1`` in the step whose first increment is ``a``: per channel (east, north
    velocity; east, north position) the rows' weighted mean (module docstring).

    Parameters
    ----------
    rows : Rows
        With :attr:`Rows.s` set (:meth:`Rows.before_end`).
    state : callable
        ``state(name, j)`` for ``"C_bn"``, ``"v_n"``, ``"pos"`` and indices j (n,) from 0 (the step's start) to m
        (after its m-th increment): the attitude C_bn (R, n, 3, 3), velocity (ENU, m/s) or position (latitude,
        longitude rad, height m) (R, n, 3) there.
    w_ib : ndarray, shape (R, m, 3)
        Body rate over each increment (bias-compensated), body frame, rad/s.
    F : ndarray, shape (R, nx, nx)
        The step's error model (:func:`baselines.kalman.error_model`).

    Returns
    -------
    z : ndarray, shape (R, q)
        Measurements (velocity channels, then position channels), m/s and m; q = 2 or 4.
    H : ndarray, shape (R, q, nx)
    r : ndarray, shape (q,)
        Variance of each channel (m/s)^2 or m^2.
    chan : ndarray of int, shape (q,)
        Index of each channel in :data:`CHANNELS`.
    """
    R, nx = F.shape[0], F.shape[-1]
    kl, w, s = rows.k[i0:i1] - a, rows.w[i0:i1], rows.s[i0:i1]
    on_ends = bool(np.all(w == 1.0))

    def at(name, sel):  # interpolated between the sample ends bracketing rows sel: (R, n_sel, ...)
        after = state(name, kl[sel] + 1)
        if on_ends:
            return after
        ww = w[sel].reshape((1, -1) + (1,) * (after.ndim - 2))
        return (1.0 - ww) * state(name, kl[sel]) + ww * after

    def mean(z, att, wt, sel, col):
        """The rows' weighted mean of z (R, n, 2) and of H, their attitude coupling ``att`` (R, n, 3) (None: none) and
        the time shift: (z (R, 2), H (R, 2, nx), r (2,))."""
        wt = wt[i0:i1][sel]  # (n, 2) weights 1 / sigma^2
        W = wt.sum(axis=0)
        sw = s[sel][:, None] * wt
        H = np.zeros((R, 2, nx))
        H[:, 0, col] = H[:, 1, col + 1] = 1.0
        shift = sw.sum(axis=0) / W  # (2,) the weighted mean time before the step's end, s
        if np.any(shift):  # H (I - F s): the state at each row's time from the step's end
            H -= shift[None, :, None] * F[:, col:col + 2, :]
        if att is not None:
            L = skew(att)[..., :2, :]  # (R, n, 2, 3)
            La = np.einsum("rnci,nc->rci", L, wt) / W[:, None]
            H[..., 0:3] += La
            if np.any(shift):
                H -= (np.einsum("rnci,nc->rci", L, sw) / W[:, None]) @ F[:, 0:3, :]
        return np.einsum("rnc,nc->rc", z, wt) / W, H, 1.0 / W

    parts = []
    vel = rows.vel[i0:i1] | rows.rest[i0:i1]
    if vel.any():
        z = at("v_n", vel)[..., :2] - rows.v[:, i0:i1][:, vel]
        lev = None
        moving = vel & ~rows.rest[i0:i1]
        if moving.any() and np.any(rows.lever):  # the antenna's velocity about the IMU; at rest: the IMU itself
            Cv, p_v = at("C_bn", vel), at("pos", vel)
            w_in = earth.earth_rate_n(p_v[..., 0]) + earth.transport_rate_n(at("v_n", vel), p_v[..., 0], p_v[..., 2])
            w_nb = rate_at(w_ib, 1.0, kl[vel], w[vel]) - np.einsum("rnji,rnj->rni", Cv, w_in)
            lev = lever_velocity(Cv, w_nb, rows.lever) * moving[vel][None, :, None]
            z = z + lev[..., :2]
        parts.append(mean(z, lev, rows.wv, vel, 3) + ((0, 1),))
    pos = rows.pos[i0:i1]
    if pos.any():
        d = lever_offset(at("C_bn", pos), rows.lever)
        z = (enu_offset(at("pos", pos), rows.p[:, i0:i1][:, pos]) + d)[..., :2]
        parts.append(mean(z, d if np.any(rows.lever) else None, rows.wp, pos, 11) + ((2, 3),))
    if len(parts) == 1:
        z, H, r, chan = parts[0]
        return z, H, r, np.asarray(chan)
    return tuple(np.concatenate(x, axis=1 if i < 2 else 0) for i, x in enumerate(zip(*parts)))


def _at_time(tv, X, sig, t):
    """Rows (valid times ``tv`` (n,) s, values ``X`` (R, n, d), sigmas ``sig`` (n, d)) at time ``t`` s: the two
    rows bracketing it interpolated, or the nearest row held; returns (value (R, d), sigma (d,), the gap s: the
    bracketing interval, or four times the distance to the row held)."""
    j = int(np.searchsorted(tv, t))
    if 0 < j < tv.size:
        dt = tv[j] - tv[j - 1]
        u = (t - tv[j - 1]) / dt
        val = (1 - u) * X[:, j - 1] + u * X[:, j]
        return val, np.hypot((1 - u) * sig[j - 1], u * sig[j]), dt
    j = min(j, tv.size - 1)
    return X[:, j].copy(), sig[j].copy(), 4.0 * abs(tv[j] - t)


def initial_motion(aiding, t, C0, w_ib, lat, runs, vref_sigma, position_sigma, att_sigma):
    """The IMU's velocity and position at the start of the fine stage from the aiding, and how good they are.

    Velocity rows (and rows at rest) at ``t`` (s) interpolated, or velocities differenced from the position rows
    (:meth:`fusionbench.simulation.aiding.Aiding.velocities_from_positions`), less the lever arm's velocity with the
    attitude ``C0`` (R, 3, 3) and the body rate ``w_ib`` (R, 3) rad/s there
    (:func:`~fusionbench.simulation.aiding_geometry.lever_velocity`, the earth rate removed); zero without aiding. The
    position from the position rows less ``C0 l``.

    Parameters
    ----------
    aiding : fusionbench.simulation.aiding.Aiding or None
    t : float
        Time of the fine stage's initial state, s.
    C0 : ndarray, shape (R, 3, 3)
        Attitude C_bn there.
    w_ib : ndarray, shape (R, 3)
        Body rate there, body frame, rad/s.
    lat : float
        Latitude of the site, rad (the earth rate in the lever arm's term: a few km off changes nothing).
    runs : int
    vref_sigma, position_sigma : float
        Sigmas of rows without their own, m/s and m (``vref_sigma`` is also that of the zero velocity of a fixed
        base without aiding).
    att_sigma : float
        Standard deviation of ``C0``'s attitude, rad (the lever arm's terms).

    Returns
    -------
    v0 : ndarray, shape (R, 3)
        Velocity, ENU, m/s (vertical zero: the height is held).
    sigma_v0 : ndarray, shape (2,)
        Its standard deviation, east and north, m/s: the rows' (interpolated), the interpolation over the gap
        (:data:`GAP_ACCEL_MPS2`) and the lever arm's through the attitude's.
    p0 : ndarray, shape (R, 3) or None
        Latitude, longitude (rad), height (m; NaN where the rows have none) of the IMU; None without position rows.
    sigma_p0 : ndarray, shape (2,) or None
        Its standard deviation, east and north, m.
    """
    v0 = np.zeros((runs, 3))
    if aiding is None:
        return v0, np.full(2, vref_sigma), None, None
    a = aiding.for_runs(runs)
    if a.sigma_p is None and a.position is not None:
        a = replace(a, sigma_p=position_sigma)
    src = a.rows(a.velocity_rows()) if a.has_velocity else a.velocities_from_positions()
    sigma_v0 = np.full(2, vref_sigma)
    if src is not None and src.t.size:
        rest = np.zeros(src.t.size, bool) if src.at_rest is None else src.at_rest
        vals = np.zeros((runs, src.t.size, 2)) if src.velocity is None else \
            np.where(np.isfinite(src.velocity[..., :2]), src.velocity[..., :2], 0.0)
        sig = np.full((src.t.size, 2), vref_sigma) if src.sigma_v is None else src.sigma_v[:, :2]
        val, sig0, gap = _at_time(src.t_valid, vals, sig, t)
        j = min(int(np.searchsorted(src.t_valid, t)), src.t.size - 1)
        lev = np.zeros((runs, 3))
        if not rest[j]:
            w_nb = w_ib - np.einsum("rji,rj->ri", C0, earth.earth_rate_n(np.full(runs, lat)))
            lev = lever_velocity(C0, w_nb, a.lever_arm)
        v0[:, :2] = val - lev[:, :2]
        sigma_v0 = np.sqrt(sig0 ** 2 + (GAP_ACCEL_MPS2 * gap / 4) ** 2 + (np.max(np.abs(lev)) * att_sigma) ** 2)
    if not a.has_position:
        return v0, sigma_v0, None, None
    pr = a.rows(a.position_rows())
    tv = pr.t_valid
    lon = np.unwrap(pr.position[..., 1], axis=-1)  # across the antimeridian
    P = np.concatenate([pr.position[..., :1], lon[..., None], pr.position[..., 2:]], axis=-1)
    val, sig0, gap = _at_time(tv, P, pr.sigma_p[:, :2], t)
    p0 = displace(val, -lever_offset(C0, a.lever_arm))
    sigma_p0 = np.sqrt(sig0 ** 2 + (GAP_ACCEL_MPS2 * gap ** 2 / 8) ** 2
                       + (np.linalg.norm(a.lever_arm) * att_sigma) ** 2)
    return v0, sigma_v0, p0, sigma_p0


def attitude_at_start(C_end, dth, dv, dt, site, aiding, t0, t1):
    """The attitude C_bn (R, 3, 3) at ``t0`` (s) that the strapdown turns into ``C_end`` (R, 3, 3) at ``t1`` (s) over
    the increments ``dth``, ``dv`` (R, n, 3) (body RFU, rad and m/s, sample interval ``dt`` s) between them.

    The strapdown turns the attitude as ``C <- exp(-[zeta x]) C B`` per sample
    (:mod:`fusionbench.simulation.strapdown`), so ``C(t0) = exp([theta x]) C(t1) B_total^T``, with ``B_total`` the
    body's turn over the increments (the strapdown's own coning-compensated product, run with the navigation frame
    held) and ``theta`` the navigation frame's (ENU) turn: the earth rate at the ``site`` and the transport rate of
    the base's mean velocity over the span, from ``aiding`` (:func:`mean_velocity`; the transport rate is linear in
    the velocity; None: a fixed base). The steps' rotations do not share one axis (the transport rate turns with the
    velocity): their product differs from this by about the earth's turn times the transport rate's over the span,
    6e-7 rad (0.002 arcmin) over a minute at 0.1 g."""
    R = dth.shape[0]
    w_ie = earth.earth_rate_n(site.lat)
    held = Strapdown(NavState.broadcast(R, np.eye(3), (0.0, 0.0, 0.0), site.lat, site.lon, site.h), dt,
                     position_fixed=True)
    held.run(dth, dv, omega_cmd=np.broadcast_to(-w_ie, (R, 3)), record_every=dth.shape[1])  # zeta = 0 each sample
    v = np.zeros((R, 3)) if aiding is None else mean_velocity(aiding, t0, t1, R)
    theta = (w_ie + earth.transport_rate_n(v, site.lat, site.h)) * (t1 - t0)
    return rotvec_to_dcm(theta) @ C_end @ np.swapaxes(held.state.C_bn, -1, -2)


def mean_velocity(aiding, t0, t1, runs):
    """The base's mean velocity (R, 3), ENU m/s, over the valid times ``(t0, t1]`` (s): the mean of the velocity rows
    there (rows at rest without one: zero), else the position rows' displacement over their interval, else zero."""
    v = np.zeros((runs, 3))
    part = aiding.window(t0, t1)
    if part is None:
        return v
    part = part.for_runs(runs)
    if part.has_velocity:
        rows = part.rows(part.velocity_rows())
        if rows.velocity is not None:
            v[:, :2] = np.mean(np.where(np.isfinite(rows.velocity[..., :2]), rows.velocity[..., :2], 0.0), axis=1)
        return v
    pr = part.rows(part.position_rows())
    if pr.t.size > 1:
        v[:, :2] = enu_offset(pr.position[:, -1], pr.position[:, 0])[:, :2] / (pr.t[-1] - pr.t[0])
    return v
