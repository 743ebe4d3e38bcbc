"""Free-inertial navigation with seed 004's (Gu 2017, adaptive Schuler damping) internal horizontal damping (Sec. 4.1),
method ``damped-nav``.

The strapdown (:class:`fusionbench.simulation.strapdown.Strapdown`, ENU, body RFU) runs at the IMU rate; every
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
* ``adaptive``: as ``fixed``, but each loop's q is min(q_fixed, q_map(abs(a))), with q_map the RBF map of
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
:func:`fusionbench.simulation.imu.simulate_chunks`), so the input need not be held either.

:class:`DampedNavigator` is a :class:`fusionbench.methods.aligner.Navigator` (``navigate(imu, site, init, vref=None)``);
its ``align`` is the adapter the runner calls, through the input policy of
:class:`fusionbench.methods.aligner_base.AlignerBase` (which refuses it without ``init``: ``supports.needs_init``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from fusionbench.methods.aligner import AlignmentResult
from fusionbench.methods.aligner_base import AlignerBase, per_increment_velocity
from fusionbench.methods.claims import Supports
from fusionbench.methods.inputs import check_init
from fusionbench.simulation.imudata import IMUData

from . import network, qmap
from .navigator_loop import SCHEMES, Loop


@lru_cache(maxsize=4)
def default_map(max_error_deg=0.03):
    """The acceleration -> q map fitted to :func:`damping.qmap.training_data` on the default grid (cached)."""
    a = qmap.default_accels()
    return qmap.QMap().fit(*qmap.training_data(a, max_error=np.radians(max_error_deg)))


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
        """Stages for the figures (:mod:`fusionbench.reports.figures`), s: the network switched in at
        ``damp_from_s``."""
        return [] if self.scheme == "undamped" else [(self.damp_from_s, "damping network switched in")]

    #: Axis labels of the series of :meth:`navigate` for the figures (q is a pure number).
    series_labels = {"q_E": "q_E, east velocity (1 = off)", "q_N": "q_N, north velocity (1 = off)"}

    def navigate(self, imu: IMUData, site, init, vref=None) -> AlignmentResult:
        """Navigate R recordings from the initial attitude ``init``, at rest at ``site``
        (:class:`fusionbench.methods.aligner.Navigator`; the input policy of
        :class:`fusionbench.methods.aligner_base.AlignerBase` first).

        Parameters
        ----------
        imu : IMUData
            Recordings, body RFU; increments or rates.
        site : fusionbench.methods.aligner.Site
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
        """The runner's stream of a long record (:meth:`fusionbench.methods.aligner_base.AlignerBase.align_chunks`,
        after the input policy): :meth:`navigate_chunks`, the reference velocity passed on only where the scheme reads
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
                loop = Loop(self, site, check_init(init, runs, self.name, required=True), dt, n_sub, t0)
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
