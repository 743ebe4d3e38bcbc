"""Free-inertial navigation with seed 004's (Gu 2017, adaptive Schuler damping) internal horizontal damping (Sec. 4.1),
method ``damped-nav``.

The strapdown (:class:`fusionbench.strapdown.Strapdown`, ENU, body RFU) runs at the IMU rate; every
``step_s`` (1 s, the paper's step) the damping network H(s) (:mod:`damping.network`) filters the
horizontal velocity, and the transport rate of the computed frame is taken from the filtered
velocity ``v_H = H(s) v`` instead of ``v``. The strapdown computes ``omega_en(v)`` itself, so the
network adds the commanded rate (rad/s, ENU)::

    omega_cmd = omega_en(v_H) - omega_en(v)
              = [-(vN_H - vN) / (RM + h),  (vE_H - vE) / (RN + h),  tan(L) (vE_H - vE) / (RN + h)]

Sign check, north loop (phi = [phiE, phiN, phiU], C_est = (I - [phi x]) C_true, so
phi' = d(omega_in) - omega_in x phi - C eps and the specific-force error is -phi x f):
d(vN)' = g phiE and phiE' = d(omega_E) = -H(s) d(vN) / R, hence s^2 + H(s) ws^2 = 0, the loop of
eq. 1; an acceleration a of the vehicle enters through (H - 1) v_true / R, which is eq. 2. Each level
loop has its own network: the east velocity's network drives phiN, the north velocity's drives phiE.

Schemes (``scheme``):

* ``undamped``: H = 1 throughout (Schuler-tuned, the oscillations never decay);
* ``fixed``: undamped until ``damp_from_s`` (3 h in the paper), then q = q_fixed, the paper's
  xi = 0.5 network: q_fixed = 1 + 0.5 / 0.09 = 6.56 from eq. 6 (its pole damping ratio is 0.46);
* ``adaptive``: as ``fixed``, but each loop's q is min(q_fixed, q_map(|a|)), with q_map the RBF map of
  :mod:`damping.qmap` (clipped to [1, 7], eq. 12) and a that channel's measured horizontal
  acceleration: the change of the INS velocity over a step, low-passed with time constant
  ``accel_tau_s``. The paper's adaptive scheme keeps xi = 0.5 while the acceleration is small (its
  Fig. 9, where both schemes coincide), hence the min.

On engagement the network's lag states start at the current velocity, so the commanded rate does
not jump; afterwards q may change at every step (:class:`damping.network.DiscreteNetwork`, discretised
with scipy.signal.cont2discrete). The vertical channel is held (height fixed): an attitude system
takes its height from outside. The map is evaluated once on a fine log-spaced grid of acceleration and
interpolated at each step (within 1e-3 in q of the regressor itself).

Memory: the data are processed step by step and the history is kept once per step (attitude,
q), so a 20-hour run at 5 Hz holds 72 000 attitudes per run besides its input;
:meth:`DampedNavigator.navigate_chunks` takes the IMU data as an iterator of chunks (e.g.
:func:`fusionbench.imu.simulate_chunks`), so the input need not be held either.

:class:`DampedNavigator` is a :class:`fusionbench.aligner.Navigator` (``navigate(imu, site, init, vref=None)``);
its ``align`` is the adapter the runner calls, through the input policy of
:class:`fusionbench.aligner_base.AlignerBase` (which refuses it without ``init``: ``supports.needs_init``).
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from fusionbench import earth
from fusionbench.aligner import AlignmentResult
from fusionbench.claims import Supports
from fusionbench.aligner_base import AlignerBase, per_increment_velocity
from fusionbench.imudata import IMUData
from fusionbench.inputs import check_init
from fusionbench.strapdown import NavState, Strapdown, integrate_compiled

from . import network, qmap

SCHEMES = ("undamped", "fixed", "adaptive")
#: Points of the tabulated acceleration -> q map (log-spaced over the map's accepted range).
MAP_TABLE_POINTS = 4001
_radii = numba.njit(cache=True)(earth.radii_from_sin2)


@lru_cache(maxsize=4)
def default_map(max_error_deg=0.03):
    """The acceleration -> q map fitted to :func:`damping.qmap.training_data` on the default grid (cached)."""
    a = qmap.default_accels()
    return qmap.QMap().fit(*qmap.training_data(a, max_error=np.radians(max_error_deg)))


@lru_cache(maxsize=8)
def _network(dt, ws):
    return network.DiscreteNetwork(dt, ws)


def q_for_damping(xi):
    """q giving damping ratio ``xi`` by the paper's fit xi = 0.09 (q - 1) (eq. 6), clipped to [1, 7]."""
    return float(np.clip(1.0 + float(xi) / 0.09, qmap.Q_MIN, qmap.Q_MAX))


class DampedNavigator(AlignerBase):
    """Free-inertial ENU navigation with the seed-004 damping network in both level loops.

    Parameters
    ----------
    scheme : {"undamped", "fixed", "adaptive"}
        Damping scheme (module docstring).
    damp_from_s : float
        Time from the start of the data at which the network is switched in, s (3 h in the paper).
    step_s : float
        Network step, s; a whole number of IMU samples.
    xi_fixed : float
        Damping ratio of the fixed network by eq. 6 (0.5 in the paper).
    accel_tau_s : float
        Time constant of the low-pass filter on the measured acceleration, s.
    max_error_deg : float
        Peak attitude error the map allows for an acceleration step, deg (0.03 in the paper).
    qmap_path : str, optional
        A map saved with :meth:`damping.qmap.QMap.save` to use instead of the default fit.
    """

    positive_options = ("step_s", "accel_tau_s", "max_error_deg")

    name = "damped-nav"
    uses_aiding = True  # the adaptive scheme may read the ship's velocity (accel_source="vref")
    supports = Supports(bases=(), needs_init=True)  # a navigator: it needs an initial attitude from an alignment
    description = "free-inertial navigation with seed 004's damping network (undamped, fixed xi = 0.5, or adaptive q)"
    min_duration_s = 10.0

    def __init__(self, scheme="adaptive", damp_from_s=3 * 3600.0, step_s=1.0, xi_fixed=0.5, accel_tau_s=10.0,
                 max_error_deg=0.03, qmap_path=None, release_s=None, accel_source="ins"):
        if scheme not in SCHEMES:
            raise ValueError(f"damped-nav scheme: expected one of {SCHEMES}, found {scheme!r}")
        for key, val in (("damp_from_s", damp_from_s), ("step_s", step_s), ("accel_tau_s", accel_tau_s),
                         ("max_error_deg", max_error_deg)):
            if not np.isfinite(val) or val < 0 or (val == 0 and key != "damp_from_s"):
                raise ValueError(f"damped-nav {key}: expected a positive number, found {val!r}")
        if not 0 < xi_fixed < 1:
            raise ValueError(f"damped-nav xi_fixed: expected a damping ratio in (0, 1), found {xi_fixed!r}")
        self.scheme = scheme
        self.damp_from_s = float(damp_from_s)
        self.step_s = float(step_s)
        self.q_fixed = q_for_damping(xi_fixed)
        self.accel_tau_s = float(accel_tau_s)
        if accel_source not in ("ins", "vref"):
            raise ValueError(f"damped-nav accel_source: expected 'ins' or 'vref', found {accel_source!r}")
        self.accel_source = accel_source
        # hold the lowered q until the fixed network's lag pair has forgotten the acceleration:
        # its memory of a step decays as (1 + t/T) exp(-t/T), to 4 % at 5 T
        self.release_s = 5.0 * network.time_constant(self.q_fixed) if release_s is None else float(release_s)
        self.max_error_deg = float(max_error_deg)
        self.qmap_path = qmap_path
        self.description = f"{scheme} damping: {self._scheme_text()}"

    def _scheme_text(self):
        if self.scheme == "undamped":
            return "Schuler-tuned free inertial navigation, no network"
        text = f"network from {self.damp_from_s / 3600:g} h, q = {self.q_fixed:.2f} (xi = 0.09 (q - 1) = " \
               f"{0.09 * (self.q_fixed - 1):.2f}, pole damping {network.damping_from_poles(self.q_fixed):.2f})"
        if self.scheme == "adaptive":
            text += f", lowered by the RBF map of the measured acceleration (tau {self.accel_tau_s:g} s) to keep " \
                    f"the acceleration error under {self.max_error_deg:g} deg"
        return text

    def map(self):
        """The acceleration -> q map (:class:`damping.qmap.QMap`)."""
        return qmap.QMap.load(self.qmap_path) if self.qmap_path else default_map(self.max_error_deg)

    def events(self, init_given):
        """Stages for the figures (:mod:`fusionbench.figures`), s: the network switched in at ``damp_from_s``."""
        return [] if self.scheme == "undamped" else [(self.damp_from_s, "damping network switched in")]

    #: Axis labels of the series of :meth:`navigate` for the figures (q is a pure number).
    series_labels = {"q_E": "q_E, east velocity (1 = off)", "q_N": "q_N, north velocity (1 = off)"}

    def navigate(self, imu: IMUData, site, init, vref=None) -> AlignmentResult:
        """Navigate R recordings from the initial attitude ``init``, at rest at ``site``
        (:class:`fusionbench.aligner.Navigator`; the input policy of :class:`fusionbench.aligner_base.AlignerBase`
        first).

        Parameters
        ----------
        imu : IMUData
            Recordings, body RFU; increments or rates.
        site : fusionbench.aligner.Site
            Initial latitude, longitude (rad) and height (m); the vehicle starts at rest.
        init : ndarray, shape (R, 3, 3) or (3, 3)
            Initial attitude C_bn (body RFU to ENU), e.g. the result of an alignment.
        vref : ndarray, shape (R, M, 3), optional
            Reference velocity (ENU, m/s) at the increment ends: read only by the adaptive scheme with
            ``accel_source="vref"`` (its acceleration); internal damping uses no external velocity.

        Returns
        -------
        AlignmentResult
            Attitude after every network step; ``series["q_E"]``, ``series["q_N"]`` (R, M) the
            coefficients of the networks on the east and north velocity (1: not engaged),
            ``figures`` the scheme's q_fixed and, for ``adaptive``, the map's held-out MSE ``map_mse``.
        """
        aiding, init = self.check(imu, site, vref, init)
        return self._navigate(imu, site, init, per_increment_velocity(aiding, imu, self.name))

    def _align(self, imu: IMUData, site, aiding, init) -> AlignmentResult:
        """The adapter the runner calls (``align``): after the input policy, which requires ``init``, the
        navigation of :meth:`navigate` (aiding as a velocity at every increment end)."""
        return self._navigate(imu, site, init, per_increment_velocity(aiding, imu, self.name))

    def _navigate(self, imu: IMUData, site, init, vref) -> AlignmentResult:
        """:meth:`navigate` on checked arguments: the record in chunks of an hour (:meth:`navigate_chunks`)."""
        t, dth, dv = imu.increments()
        if self.scheme == "adaptive" and self.accel_source == "vref" and vref is None:
            raise ValueError(f"{self.name}: vref: accel_source 'vref' needs a reference velocity, found none")
        vref = vref if self.accel_source == "vref" else None
        chunk = max(1, int(round(3600.0 / imu.dt)))
        chunks = ((IMUData(t[k:k + chunk], dth[:, k:k + chunk], dv[:, k:k + chunk], "increment"),
                   None if vref is None else vref[:, k:k + chunk]) for k in range(0, t.size, chunk))
        return self.navigate_chunks(chunks, site, init, dt=imu.dt, t0=imu.t0, runs=imu.runs)

    def _align_chunks(self, chunks, site, init, dt, t0, runs):
        """The runner's stream of a long record (:meth:`fusionbench.aligner_base.AlignerBase.align_chunks`, after
        the input policy): :meth:`navigate_chunks`, the reference velocity passed on only where the scheme reads
        it (``accel_source="vref"``), as :meth:`navigate` does."""
        use_vref = self.accel_source == "vref"

        def feed():
            for ch, vref in chunks:
                if use_vref and self.scheme == "adaptive" and vref is None:
                    raise ValueError(f"{self.name}: vref: accel_source 'vref' needs a reference velocity, found none")
                yield ch, vref if use_vref else None

        return self.navigate_chunks(feed(), site, init, dt, t0=t0, runs=runs)

    def navigate_chunks(self, chunks, site, init, dt, t0=0.0, runs=None):
        """Navigate increments given as an iterator of ``(IMUData, vref)`` chunks, consecutive.

        Each IMUData chunk is of kind ``"increment"``; ``vref`` is the reference velocity (R, n, 3),
        ENU, m/s, at its samples, or None (needed only with ``accel_source="vref"``). ``dt`` is the
        sample interval (s) and ``t0`` the time of the initial state (s). Samples left over after a
        chunk's whole network steps are carried into the next chunk; those after the last whole step of
        the data go through the strapdown alone (less than one step: the network's command over it turns
        the attitude by well under 0.001 arcmin), so the history ends at the last sample. Returns what
        :meth:`navigate` returns. The chunks' samples are not checked (a stream is not held); ``init`` is.
        """
        n_sub = int(round(self.step_s / dt))
        if n_sub < 1 or abs(n_sub * dt - self.step_s) > 1e-6 * self.step_s:
            raise ValueError(f"{self.name}: step_s: expected a whole number of samples of {dt:g} s, found {self.step_s:g} s")
        loop = None
        ts, Cs, qs = [], [], []
        left = None  # samples after the last whole step: (t, dth, dv, vref)
        for ch, vref in chunks:
            t, dth, dv = ch.increments()
            if left is not None and left[0].size:
                t, dth, dv = (np.concatenate([a, b], axis=-1 if a.ndim == 1 else 1)
                              for a, b in zip(left[:3], (t, dth, dv)))
                vref = None if vref is None else np.concatenate([left[3], vref], axis=1)
            if loop is None:
                runs = dth.shape[0] if runs is None else runs
                loop = _Loop(self, site, check_init(init, runs, self.name, required=True), dt, n_sub, t0)
            n = (t.size // n_sub) * n_sub
            left = (t[n:], dth[:, n:], dv[:, n:], None if vref is None else vref[:, n:])
            if n == 0:
                continue
            C, q = loop.run(dth[:, :n], dv[:, :n], None if vref is None else vref[:, :n])
            ts.append(t[n_sub - 1:n:n_sub])
            Cs.append(C)
            qs.append(q)
        if loop is None or not ts:
            raise ValueError(f"{self.name}: imu: expected at least one step of {self.step_s:g} s of samples, found none")
        if left[0].size:  # the time rule: the history ends at the last sample
            loop.sd.run(left[1], left[2], record_every=left[0].size)
            ts.append(left[0][-1:])
            Cs.append(loop.sd.state.C_bn[:, None].copy())
            qs.append(qs[-1][:, -1:])
        q = _join(qs)
        figures = {}
        if self.scheme != "undamped":
            figures = {"q_fixed": self.q_fixed, "xi_fixed_poles": network.damping_from_poles(self.q_fixed)}
        if self.scheme == "adaptive":
            figures["map_mse"] = float(self.map().mse_)
        return AlignmentResult(self.name, np.concatenate(ts), _join(Cs),
                               series={"q_E": q[..., 0], "q_N": q[..., 1]}, figures=figures)

    def report_figures(self, folder):
        """Write the network's figures (seed 004 Figs. 4, 5, 6 and 8) into ``folder``; [(file, caption)]."""
        if self.scheme == "undamped":
            return []
        from .figures import theory_figures  # matplotlib only when a report is written

        return theory_figures(folder, self.map() if self.scheme == "adaptive" else None, self.max_error_deg)


def _join(pieces):
    """The arrays ``pieces`` (R, m_i, ...) joined along their second axis, each freed (removed from the list) once
    copied: a long history is held once, not twice, while it is joined (20 h at 1 s: 5 MB of attitudes a run)."""
    out = np.empty(pieces[0].shape[:1] + (sum(p.shape[1] for p in pieces),) + pieces[0].shape[2:])
    k = 0
    while pieces:
        p = pieces.pop(0)
        out[:, k:k + p.shape[1]] = p
        k += p.shape[1]
    return out


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
    strapdown (:func:`fusionbench.strapdown.integrate_compiled`), acceleration tracking. ``scheme``: 0
    undamped, 1 fixed, 2 adaptive; ``v_track`` (R, S, 2) the step-mean reference velocity for the adaptive
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


class _Loop:
    """State of a damped navigation over a batch of runs between chunks."""

    def __init__(self, nav: DampedNavigator, site, C0, dt, n_sub, t0):
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
