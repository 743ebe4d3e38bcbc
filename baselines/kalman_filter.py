"""The error-state filter of ``kf`` and ``akf`` (:mod:`baselines.kalman`) around one feedback-corrected strapdown.

State per Monte Carlo run (the filters of all runs step together in a :class:`baselines.filter_bank.FilterBank`)::

    x = [phiE, phiN, phiU, dvE, dvN, eps_x, eps_y, eps_z, nab_x, nab_y, nab_z (, dpE, dpN)]

(misalignment phi in ENU with C_est = (I - [phi x]) C_true, rad; horizontal velocity error, m/s; gyro and
accelerometer biases (frames below), rad/s and m/s^2; the horizontal position error, m, only when the aiding
measures positions), with the psi-angle model::

    phi' = -[w_in x] phi - C_bn eps + w_g
    dv'  =  [f^n x] phi + B nab - [(2 w_ie + w_en) x] dv + w_a      (east and north rows)
    dp'  =  dv

with ``f^n`` the specific force: on a moving base the strapdown's (``C_bn f^b``), on a fixed base the one the
reference implies, gravity's reaction ``[0, 0, g]``. The strapdown's horizontal part there is ``g`` times the
estimate's tilt error: formed at it, F couples the azimuth into the velocity where the true errors do not, and the
filter takes information on the azimuth that the data do not hold (``docs/open-claims.md``: what it cost).

The gyro biases are body-frame states. The accelerometer biases are body-frame states (``B = C_bn``) on a moving
base, where the turns make them partly observable, and navigation-frame states (``B = I``) on a fixed one. There
the horizontal accelerometer biases are unobservable against the tilts, and body-frame states turn that unobservable
direction with the estimated attitude: every correction and the gyro noise's wander of ``C_bn`` gave the filter
spurious information on it. With a tactical IMU (300 ug, 0.1 deg/sqrt(h)) its north level then ended 1.0-1.8
arcmin beside the limit, 0.1-0.3 with navigation-frame states (level bound 0.08-0.27). The same change for the gyro
biases fails: an observable north gyro bias, estimated in the navigation frame and fed back to the body through an
attitude whose azimuth is still being corrected, leaves part of it as an east bias (noise-free, 1 deg/h, from the
true attitude: 71 arcmin of azimuth, 0.01 with body-frame states). A sway turns the body by a few degrees, which
moves a navigation-frame bias by a few percent at the sway's frequency, averaged out in the level channels.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import earth
from fusionbench.simulation.attitude import rotvec_to_dcm, skew

from fusionbench.simulation.aiding_geometry import displace

from .kalman_aiding import step_measurement

#: States without the position errors.
NX = 11


def error_model(C_bn, f_n, w_in, w_cor, position=False, nav_accel_biases=False):
    """Continuous error-state matrix F (R, n, n) of the psi-angle model (module docstring); n = 11, or 13 with the
    position errors (east, north, m: ``dp' = dv``).

    Parameters
    ----------
    C_bn : (R, 3, 3) attitude. f_n : (R, 3) specific force in ENU, m/s^2.
    w_in : (R, 3) navigation-frame rate, rad/s. w_cor : (R, 3) 2 w_ie + w_en, rad/s.
    position : bool
        Add the position-error states.
    nav_accel_biases : bool
        The accelerometer bias states in the navigation frame (ENU; ``B = I``), else in the body frame (RFU;
        ``B = C_bn``).
    """
    R = C_bn.shape[0]
    n = NX + 2 * bool(position)
    B = np.broadcast_to(np.eye(3), C_bn.shape) if nav_accel_biases else C_bn
    F = np.zeros((R, n, n))
    F[:, 0:3, 0:3] = -skew(w_in)
    F[:, 0:3, 5:8] = -C_bn
    F[:, 3:5, 0:3] = skew(f_n)[:, :2]
    F[:, 3:5, 8:11] = B[:, :2]
    F[:, 3:5, 3:5] = -skew(w_cor)[:, :2, :2]
    if position:
        F[:, 11, 3] = F[:, 12, 4] = 1.0
    return F


def discretize(F, Qc, T):
    """Second-order transition and process noise over T: Phi = I + F T + (F T)^2 / 2,
    Qd = Qc T + (F Qc + Qc F^T) T^2 / 2 (batched over the leading axis)."""
    FT = F * T
    Phi = np.eye(F.shape[-1]) + FT + FT @ FT / 2
    FQ = F @ Qc
    return Phi, Qc * T + (FQ + np.swapaxes(FQ, -1, -2)) * T * T / 2


class FeedbackKalman:
    """R error-state Kalman filters, one per run, around one feedback-corrected strapdown (module docstring).

    Each :meth:`step` integrates one update interval of bias-compensated increments through the strapdown, forms
    the psi-angle model there (:func:`error_model`, :func:`discretize`), predicts, updates the filters with the
    aiding rows valid in the interval (:func:`baselines.kalman_aiding.step_measurement`; prediction only when there
    are none) and feeds the estimate back into the strapdown and the biases.

    Parameters
    ----------
    sd : fusionbench.simulation.strapdown.Strapdown
        The strapdown of the R runs.
    bank : baselines.filter_bank.FilterBank
        The filters (``x``, ``P``), of 11 states, or 13 with the position errors.
    qc : ndarray, shape (11,)
        Continuous noise densities of the states (:meth:`KalmanAligner._qc`).
    T, dt : float
        Update interval and sample interval, s.
    q_scale, update : callable
        The aligner's hooks: ``q_scale(bank)`` the factor (R,) on Q in the prediction, ``update(bank, z, H, r,
        chan, k)`` the measurement update k (the adaptive variant adapts R and Q there).
    fixed_base : bool
        A base at rest (the reference's velocity zero): the accelerometer bias states in the navigation frame, and F
        at gravity's reaction instead of the strapdown's specific force (module docstring).

    Attributes
    ----------
    x, P : ndarray
        The filters' state (R, nx) and covariance (R, nx, nx) (the bank's; ``x`` is zero after each feedback).
    z : ndarray, shape (R, q)
        The last measurement (m/s, m).
    eps_hat, nab_hat : ndarray, shape (R, 3)
        Gyro (rad/s) and accelerometer (m/s^2) biases fed back so far, body frame.
    updates : int
        Measurement updates so far.
    """

    def __init__(self, sd, bank, qc, T, dt, q_scale, update, fixed_base=False):
        self.sd, self.bank, self.qc, self.T, self.dt = sd, bank, qc, T, dt
        self.fixed_base = bool(fixed_base)
        self._q_scale, self._update = q_scale, update
        R = sd.runs
        self.z = np.zeros((R, 0))
        self.eps_hat = np.zeros((R, 3))
        self.nab_hat = np.zeros((R, 3))
        self.updates = 0

    @property
    def x(self):
        """The filters' error state (R, nx) (zero after each feedback)."""
        return self.bank.x

    @property
    def P(self):
        """The filters' covariance (R, nx, nx)."""
        return self.bank.P

    def step(self, dth, dv, rows, span, a):
        """One update interval over the increments ``dth``, ``dv`` (R, m, 3), the record's ``a .. a + m - 1``, with
        ``rows`` (:class:`baselines.kalman_aiding.Rows`) ``span = (i0, i1)`` valid in it. Returns the misalignment
        sigma (R, 3) rad, ENU, after the update."""
        sd, bank, qc, T, dt = self.sd, self.bank, self.qc, self.T, self.dt
        R, m = dth.shape[0], dth.shape[1]
        nx = bank.n
        g_in = dth - self.eps_hat[:, None] * dt
        a_in = dv - self.nab_hat[:, None] * dt
        st = sd.state
        C_prev = st.C_bn.copy()
        rowed = span[1] > span[0]
        inside = rowed and rows.need_history(*span)  # else the state at the step's end is enough
        start = {"C_bn": C_prev, "v_n": st.v_n.copy(), "pos": np.stack([st.lat, st.lon, st.h], -1)} if inside else {}
        hist = sd.run(g_in, a_in, record_every=1 if inside else m)
        if self.fixed_base:  # the specific force the reference implies, gravity's reaction (module docstring)
            f_n = -earth.gravity_n(st.lat, st.h)
        else:
            f_n = np.einsum("rij,rj->ri", 0.5 * (C_prev + st.C_bn), a_in.sum(axis=1) / T)
        w_ie = earth.earth_rate_n(st.lat)
        w_en = earth.transport_rate_n(st.v_n, st.lat, st.h)
        F = error_model(st.C_bn, f_n, w_ie + w_en, 2 * w_ie + w_en, position=nx > NX,
                         nav_accel_biases=self.fixed_base)
        Qc = np.zeros((R, nx, nx))
        Qc[:, 0:3, 0:3] = st.C_bn @ (qc[0:3, None] * np.swapaxes(st.C_bn, -1, -2))
        Qc[:, 3:5, 3:5] = (st.C_bn @ (np.r_[qc[3:5], 0.0][:, None] * np.swapaxes(st.C_bn, -1, -2)))[:, :2, :2]
        Qc[:, 5:NX, 5:NX] = np.diag(qc[5:])
        Phi, Qd = discretize(F, Qc, T)
        bank.predict(Phi, Qd * np.reshape(self._q_scale(bank), (-1, 1, 1)))
        if rowed:
            def state(name, j):  # at the step's start (j = 0) and after its j-th increment
                now = np.stack([hist["lat"], hist["lon"], hist["h"]], -1) if name == "pos" else hist[name]
                if not inside:  # every j is m: the end
                    return now[:, np.zeros_like(j)]
                return np.concatenate([start[name][:, None], now], axis=1)[:, j]

            z, H, r, chan = step_measurement(rows, *span, a, state, g_in / dt, F)
            self.z = z
            self._update(bank, z, H, r, chan, self.updates)
            self.updates += 1
            self._feedback()
        return np.sqrt(np.diagonal(self.P, axis1=1, axis2=2)[:, :3])

    def _feedback(self):
        """Feed the estimate into the strapdown (attitude, velocity, position) and the biases (navigation-frame
        accelerometer bias states taken to the body with the corrected attitude); reset it to zero."""
        x = self.x.copy()
        self.bank.reset_x()  # feedback below resets every state
        st = self.sd.state
        st.C_bn[:] = rotvec_to_dcm(x[:, 0:3]) @ st.C_bn
        st.v_n[:, :2] -= x[:, 3:5]
        if self.fixed_base:  # navigation-frame accelerometer biases: b_body = C_bn^T b_nav
            x[:, 8:11] = np.einsum("rji,rj->ri", st.C_bn, x[:, 8:11])
        self.eps_hat += x[:, 5:8]
        self.nab_hat += x[:, 8:11]
        if x.shape[1] > NX:  # position errors east and north, m
            p = displace(np.stack([st.lat, st.lon, st.h], axis=-1), -np.pad(x[:, 11:13], ((0, 0), (0, 1))))
            st.lat[:], st.lon[:] = p[:, 0], p[:, 1]

    def coast(self, dth, dv):
        """Integrate the increments ``dth``, ``dv`` (R, n, 3) through the bias-compensated strapdown, no update."""
        self.sd.run(dth - self.eps_hat[:, None] * self.dt, dv - self.nab_hat[:, None] * self.dt,
                    record_every=dth.shape[1])
