"""The compiled loop of seed 004's damped navigation (:class:`damping.navigator.DampedNavigator`, Gu 2017, adaptive
Schuler damping): whole network steps of all runs in one numba kernel, the damping network's lags, the commanded rate
``omega_en(v_H) - omega_en(v)`` (rad/s, ENU), the strapdown
(:func:`fusionbench.simulation.strapdown_compiled.integrate_compiled`) and the acceleration tracking of the adaptive
map; :class:`Loop` holds its state between chunks of data."""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from fusionbench.simulation import earth
from fusionbench.simulation.strapdown import NavState, Strapdown
from fusionbench.simulation.strapdown_compiled import integrate_compiled

from . import network, qmap

SCHEMES = ("undamped", "fixed", "adaptive")
#: Points of the tabulated acceleration -> q map (log-spaced over the map's accepted range).
MAP_TABLE_POINTS = 4001
_radii = numba.njit(cache=True)(earth.radii_from_sin2)


@lru_cache(maxsize=8)
def _network(dt, ws):
    return network.DiscreteNetwork(dt, ws)


@numba.njit(cache=True)
def _interp_grid(x, x0, dx, n):
    """Index and weight of ``x`` on the uniform grid x0 + i dx, i < n (clamped)."""
    f = (x - x0) / dx
    if f <= 0.0:
        return 0, 0.0
    if f >= n - 1:
        return n - 2, 1.0
    i = int(f)
    return i, f - i


@numba.njit(cache=True)
def _damped_steps(sd_state, dth, dv, ns, dt, step, damp_from, scheme, v_track, q_fixed, q0, dq, Ad_tab, Bd_tab,
                  la0, dla, q_tab, alpha, release, x, a_f, a_env, v_prev, flags, clock, out_C, out_q):
    """Whole network steps of ``ns`` samples for all runs: network (lags x, coefficient q), commanded rate,
    strapdown (:func:`fusionbench.simulation.strapdown_compiled.integrate_compiled`), acceleration tracking.
    ``scheme``: 0 undamped, 1 fixed, 2 adaptive; ``v_track`` (R, S, 2) the step-mean reference velocity for the adaptive
    map, or empty to track the INS's own velocity. Loop state (x, a_f, a_env, v_prev, flags = [engaged,
    has v_prev], clock = [t]) is updated in place."""
    C0, v0, lat0, lon0, h0, vp0, thp, dvp = sd_state
    runs = dth.shape[0]
    steps = dth.shape[1] // ns
    cmd = np.zeros((runs, ns, 3))
    rec_C = np.empty((runs, 1, 3, 3))
    rec_v = np.empty((runs, 1, 3))
    rec_p = np.empty((runs, 1, 3))
    v = np.empty(2)
    n_q = Ad_tab.shape[0]
    for j in range(steps):
        if scheme > 0 and flags[0] == 0 and clock[0] >= damp_from - 1e-9:
            flags[0] = 1
            for r in range(runs):  # lags at equilibrium: the damped velocity equals v, no jump
                for c in range(2):
                    x[r, c, 0] = v0[r, c]
                    x[r, c, 1] = v0[r, c]
        for r in range(runs):
            dvh = np.zeros(2)
            if flags[0] == 1:
                for c in range(2):
                    if scheme == 1:
                        q = q_fixed
                    else:
                        la = np.log10(min(max(a_env[r, c], 1e-300), 1e300))
                        i, w = _interp_grid(la, la0, dla, q_tab.size)
                        q = q_tab[i] * (1.0 - w) + q_tab[i + 1] * w
                    out_q[r, j, c] = q
                    i, w = _interp_grid(q, q0, dq, n_q)
                    u = v0[r, c]
                    dvh[c] = (q - 1.0) ** 2 / q * (x[r, c, 0] - x[r, c, 1])  # H v - v
                    x0 = (1 - w) * (Ad_tab[i, 0, 0] * x[r, c, 0] + Ad_tab[i, 0, 1] * x[r, c, 1] + Bd_tab[i, 0] * u) \
                        + w * (Ad_tab[i + 1, 0, 0] * x[r, c, 0] + Ad_tab[i + 1, 0, 1] * x[r, c, 1] + Bd_tab[i + 1, 0] * u)
                    x1 = (1 - w) * (Ad_tab[i, 1, 0] * x[r, c, 0] + Ad_tab[i, 1, 1] * x[r, c, 1] + Bd_tab[i, 1] * u) \
                        + w * (Ad_tab[i + 1, 1, 0] * x[r, c, 0] + Ad_tab[i + 1, 1, 1] * x[r, c, 1] + Bd_tab[i + 1, 1] * u)
                    x[r, c, 0], x[r, c, 1] = x0, x1
            else:
                out_q[r, j, 0] = 1.0
                out_q[r, j, 1] = 1.0
            rm, rn = _radii(np.sin(lat0[r]) ** 2)
            cE = -dvh[1] / (rm + h0[r])
            cN = dvh[0] / (rn + h0[r])
            for k in range(ns):
                cmd[r, k, 0], cmd[r, k, 1], cmd[r, k, 2] = cE, cN, cN * np.tan(lat0[r])
            if scheme == 2 and v_track.shape[1] == 0:
                v_prev[r, 0], v_prev[r, 1] = v0[r, 0], v0[r, 1]  # the INS velocity before the step
        k0 = j * ns
        integrate_compiled(C0, v0, lat0, lon0, h0, vp0, thp, dvp, dth[:, k0:k0 + ns], dv[:, k0:k0 + ns], cmd, dt,
                           False, True, ns, rec_C, rec_v, rec_p)
        for r in range(runs):
            out_C[r, j] = rec_C[r, 0]
            if scheme == 2:
                if v_track.shape[1] == 0:
                    a0, a1 = (v0[r, 0] - v_prev[r, 0]) / step, (v0[r, 1] - v_prev[r, 1]) / step
                    track = True
                else:
                    v[0], v[1] = v_track[r, j, 0], v_track[r, j, 1]
                    track = flags[1] == 1
                    a0, a1 = (v[0] - v_prev[r, 0]) / step, (v[1] - v_prev[r, 1]) / step
                    v_prev[r, 0], v_prev[r, 1] = v[0], v[1]
                if track:
                    a_f[r, 0] += alpha * (a0 - a_f[r, 0])
                    a_f[r, 1] += alpha * (a1 - a_f[r, 1])
                    a_env[r, 0] = max(abs(a_f[r, 0]), a_env[r, 0] * release)
                    a_env[r, 1] = max(abs(a_f[r, 1]), a_env[r, 1] * release)
        flags[1] = 1
        clock[0] += step


class Loop:
    """State of a damped navigation over a batch of runs between chunks: ``nav`` the
    :class:`damping.navigator.DampedNavigator` whose options it runs."""

    def __init__(self, nav, site, C0, dt, n_sub, t0):
        runs = C0.shape[0]
        self.nav, self.n_sub, self.dt = nav, n_sub, dt
        self.sd = Strapdown(NavState.broadcast(runs, C0, (0.0, 0.0, 0.0), site.lat, site.lon, site.h), dt,
                            height_fixed=True)
        self.net = _network(nav.step_s, float(earth.schuler_frequency(site.lat, site.h)))
        self.scheme = SCHEMES.index(nav.scheme)
        self.use_vref = nav.scheme == "adaptive" and nav.accel_source == "vref"
        self.x = np.zeros((runs, 2, 2))  # lag states per run, channel (E, N velocity), lag
        self.a_f = np.zeros((runs, 2))  # low-passed measured acceleration, m/s^2
        self.a_env = np.zeros((runs, 2))  # its envelope: follows rises at once, decays with release_s
        self.v_prev = np.zeros((runs, 2))  # the velocity the last acceleration was measured from
        self.flags = np.zeros(2, dtype=np.int64)  # network engaged, v_prev set
        self.clock = np.array([float(t0)])  # time at the start of the next step, s
        self.alpha = 1.0 - np.exp(-nav.step_s / nav.accel_tau_s)
        self.release = np.exp(-nav.step_s / nav.release_s) if nav.release_s > 0 else 0.0
        self.log_a = np.linspace(np.log10(qmap.MIN_ACCEL), np.log10(qmap.MAX_ACCEL), MAP_TABLE_POINTS)
        self.q_tab = np.full(MAP_TABLE_POINTS, nav.q_fixed)
        if nav.scheme == "adaptive":
            self.q_tab = np.minimum(nav.map()(10.0**self.log_a), nav.q_fixed)

    def run(self, dth, dv, vref=None):
        """Integrate whole steps; returns the attitude after each step (R, S, 3, 3) and q (R, S, 2).

        ``vref`` (R, n, 3): reference velocity at the samples, for ``accel_source="vref"``."""
        runs, n, _ = dth.shape
        ns = self.n_sub
        steps = n // ns
        v_track = np.zeros((runs, 0, 2))
        if self.use_vref:
            if vref is None:
                raise ValueError("damped-nav: vref: accel_source 'vref' needs a reference velocity, found none")
            v_track = np.ascontiguousarray(vref[:, :steps * ns, :2].reshape(runs, steps, ns, 2).mean(axis=2))
        out_C = np.empty((runs, steps, 3, 3))
        out_q = np.ones((runs, steps, 2))
        net = self.net
        _damped_steps(self.sd.compiled_state(), np.ascontiguousarray(dth[:, :steps * ns], dtype=float),
                      np.ascontiguousarray(dv[:, :steps * ns], dtype=float), ns, self.dt, self.nav.step_s,
                      self.nav.damp_from_s, self.scheme, v_track, self.nav.q_fixed, net.q[0], net.q[1] - net.q[0],
                      net.Ad, net.Bd, self.log_a[0], self.log_a[1] - self.log_a[0], self.q_tab, self.alpha,
                      self.release, self.x, self.a_f, self.a_env, self.v_prev, self.flags, self.clock, out_C, out_q)
        return out_C, out_q
