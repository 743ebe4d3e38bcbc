"""Kalman fine alignment and its innovation-adaptive variant.

After a coarse alignment (or from the scenario's initial guess), the shared strapdown runs on the
IMU increments and an error-state filter per run estimates every ``step_s`` (the filters of all runs step
together in a :class:`baselines.filter_bank.FilterBank`: filterpy's arithmetic on arrays over runs, or
``engine="filterpy"``, one :class:`filterpy.kalman.KalmanFilter` per run, the reference)::

    x = [phiE, phiN, phiU, dvE, dvN, eps_x, eps_y, eps_z, nab_x, nab_y, nab_z]

(misalignment phi in ENU with C_est = (I - [phi x]) C_true, rad; horizontal velocity error, m/s;
gyro and accelerometer biases in the body frame, rad/s and m/s^2), with the psi-angle model::

    phi' = -[w_in x] phi - C_bn eps + w_g
    dv'  =  [f^n x] phi + C_bn nab - [(2 w_ie + w_en) x] dv + w_a      (east and north rows)

the transition and process noise accumulated over the update interval T (``step_s``; second-order expansion of
exp(F T) and of the Van Loan integral), and the measurement z = v_INS - v_ref (ENU, m/s; zero
velocity on a stationary base). The update is filterpy's Joseph form. After each update the estimate is fed back: the attitude is
turned by phi (C <- exp([phi x]) C), the velocity error removed, the biases added to the
compensation of later increments, and those states reset to zero (their covariance is unchanged).

Stationary-base limits: the filter cannot separate the horizontal accelerometer biases from tilt nor
the east gyro bias from azimuth, so it lands on :func:`fusionbench.metrics.theoretical_limits`.

:class:`AdaptiveKalmanAligner` (``akf``) adds innovation-based adaptation for noise that changes:
Sage-Husa estimation of R with a fading factor, and covariance matching of the innovations to inflate
the predicted covariance when they exceed what P and R explain (a stand-in for a Q that grew).
"""

from __future__ import annotations


import numpy as np

from fusionbench import earth
from fusionbench.aligner import AlignmentResult, Site
from fusionbench.claims import Supports, azimuth_bias_ratio
from fusionbench.aligner_base import AlignerBase, coarse_then_fine, per_increment_velocity
from fusionbench.attitude import rotvec_to_dcm, skew
from fusionbench.imu import load_spec
from fusionbench.strapdown import NavState, Strapdown

from fusionbench.coarse import InertialCoarseAligner
from .filter_bank import ENGINES, FilterBank

NX = 11


def error_model(C_bn, f_n, w_in, w_cor):
    """Continuous error-state matrix F (R, 11, 11) of the psi-angle model (module docstring).

    Parameters
    ----------
    C_bn : (R, 3, 3) attitude. f_n : (R, 3) specific force in ENU, m/s^2.
    w_in : (R, 3) navigation-frame rate, rad/s. w_cor : (R, 3) 2 w_ie + w_en, rad/s.
    """
    R = C_bn.shape[0]
    F = np.zeros((R, NX, NX))
    F[:, 0:3, 0:3] = -skew(w_in)
    F[:, 0:3, 5:8] = -C_bn
    F[:, 3:5, 0:3] = skew(f_n)[:, :2]
    F[:, 3:5, 8:11] = C_bn[:, :2]
    F[:, 3:5, 3:5] = -skew(w_cor)[:, :2, :2]
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
    the psi-angle model there (:func:`error_model`, :func:`discretize`), predicts and updates the filters with
    the measurement ``z = v_INS - v_ref`` and feeds the estimate back into the strapdown and the biases.

    Parameters
    ----------
    sd : fusionbench.strapdown.Strapdown
        The strapdown of the R runs.
    bank : baselines.filter_bank.FilterBank
        The filters (``x``, ``P``, ``H``, ``R``).
    qc : ndarray, shape (11,)
        Continuous noise densities of the states (:meth:`KalmanAligner._qc`).
    T, dt : float
        Update interval and sample interval, s.
    q_scale, update : callable
        The aligner's hooks: ``q_scale(bank)`` the factor (R,) on Q in the prediction, ``update(bank, z, k)`` the
        measurement update k (the adaptive variant adapts R and Q there).

    Attributes
    ----------
    x, P : ndarray
        The filters' state (R, 11) and covariance (R, 11, 11) (the bank's; ``x`` is zero after each feedback).
    z : ndarray, shape (R, 2)
        The last measurement, m/s.
    eps_hat, nab_hat : ndarray, shape (R, 3)
        Gyro (rad/s) and accelerometer (m/s^2) biases fed back so far, body frame.
    """

    def __init__(self, sd, bank, qc, T, dt, q_scale, update):
        self.sd, self.bank, self.qc, self.T, self.dt = sd, bank, qc, T, dt
        self._q_scale, self._update = q_scale, update
        R = sd.runs
        self.z = np.zeros((R, 2))
        self.eps_hat = np.zeros((R, 3))
        self.nab_hat = np.zeros((R, 3))

    @property
    def x(self):
        """The filters' error state (R, 11) (zero after each feedback)."""
        return self.bank.x

    @property
    def P(self):
        """The filters' covariance (R, 11, 11)."""
        return self.bank.P

    def step(self, dth, dv, v_ref, k):
        """Step k over the increments ``dth``, ``dv`` (R, m, 3) of one update interval; ``v_ref`` (R, 2) m/s the
        reference's horizontal velocity at its end (None: zero). Returns the misalignment sigma (R, 3) rad, ENU."""
        sd, bank, qc, T, dt = self.sd, self.bank, self.qc, self.T, self.dt
        R = dth.shape[0]
        g_in = dth - self.eps_hat[:, None] * dt
        a_in = dv - self.nab_hat[:, None] * dt
        C_prev = sd.state.C_bn.copy()
        sd.run(g_in, a_in, record_every=dth.shape[1])
        st = sd.state
        f_n = np.einsum("rij,rj->ri", 0.5 * (C_prev + st.C_bn), a_in.sum(axis=1) / T)
        w_ie = earth.earth_rate_n(st.lat)
        w_en = earth.transport_rate_n(st.v_n, st.lat, st.h)
        F = error_model(st.C_bn, f_n, w_ie + w_en, 2 * w_ie + w_en)
        Qc = np.zeros((R, NX, NX))
        Qc[:, 0:3, 0:3] = st.C_bn @ (qc[0:3, None] * np.swapaxes(st.C_bn, -1, -2))
        Qc[:, 3:5, 3:5] = (st.C_bn @ (np.r_[qc[3:5], 0.0][:, None] * np.swapaxes(st.C_bn, -1, -2)))[:, :2, :2]
        Qc[:, 5:, 5:] = np.diag(qc[5:])
        Phi, Qd = discretize(F, Qc, T)
        self.z = st.v_n[:, :2] - (0.0 if v_ref is None else v_ref)
        bank.predict(Phi, Qd * np.reshape(self._q_scale(bank), (-1, 1, 1)))
        self._update(bank, self.z, k)
        x = self.x.copy()
        bank.reset_x()  # feedback below resets every state
        sigma = np.sqrt(np.diagonal(self.P, axis1=1, axis2=2)[:, :3])
        st.C_bn[:] = rotvec_to_dcm(x[:, 0:3]) @ st.C_bn
        st.v_n[:, :2] -= x[:, 3:5]
        self.eps_hat += x[:, 5:8]
        self.nab_hat += x[:, 8:11]
        return sigma

    def coast(self, dth, dv):
        """Integrate the increments ``dth``, ``dv`` (R, n, 3) through the bias-compensated strapdown, no update."""
        self.sd.run(dth - self.eps_hat[:, None] * self.dt, dv - self.nab_hat[:, None] * self.dt,
                    record_every=dth.shape[1])


class KalmanAligner(AlignerBase):
    """Kalman fine alignment (method ``kf``) on filterpy, feedback-corrected strapdown.

    Parameters
    ----------
    step_s : float
        Filter step, s (0.1: 10 Hz), rounded to a whole number of IMU samples: the interval of its predictions
        and updates.
    imu : str, path or IMUSpec
        Noise model of the filter (:func:`fusionbench.imu.load_spec`): a preset name, an IMU spec TOML
        file or an IMUSpec; default the ``navigation`` preset. Its white noises give Q; its bias sigmas
        (fixed part taken as a sigma too) the initial bias covariance, floored so that the prior is never
        tight (a tight gyro-bias prior biases the tilt). The result's ``imu_model`` names it.
    vref_sigma : float
        Standard deviation of each velocity-reference sample, m/s: R of each update (floored at 1 mm/s, so that
        an exact reference keeps the update well conditioned). A scenario gives a method with this option the
        noise of its reference (:func:`fusionbench.aligner.load_method`); 0.05 m/s by default, the disturbance of
        a vehicle at rest.
    att_sigma_deg : (3,) float
        Initial misalignment standard deviations [E, N, U] after the initialisation, deg. ``None`` for U (the
        default): 5 deg, or three times the azimuth error the IMU model's gyro bias allows at the site
        (asin(bias / (earth rate cos L))) when that is larger: a prior tighter than the coarse start's real error
        makes the filter overconfident (a tactical gyro at 60 deg: 7.4 deg of limit alone).
    coarse_s : float
        Length of the inertial-frame coarse alignment when no initial guess is given, s.
    engine : {"numpy", "filterpy"}
        The filters of all runs on arrays (default), or one filterpy KalmanFilter per run (the reference:
        the same estimates to rounding, several times slower).
    """

    name = "kf"
    uses_aiding = True
    # not moving: on the 0.1 g moving base it ends 1.3-1.7 bounds off with a -1.2 to -1.4 arcmin mean azimuth offset
    # whatever the heading (gtsam 1.0 on the same data); not tactical gyros: 1.5-2.1 bounds off (conformance)
    supports = Supports(bases=("static", "sway"), max_abs_lat_deg=89.0, max_bias_ratio=0.05)
    max_latitude_deg = 89.0
    description = "Kalman fine alignment (11-state psi-angle model, filterpy arithmetic batched over runs, feedback), coarse start"

    def __init__(self, step_s=0.1, imu="navigation", vref_sigma=0.05, att_sigma_deg=(1.0, 1.0, None), coarse_s=60.0,
                 engine="numpy"):
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, found {engine!r}")
        self.engine = engine
        self.step_s = float(step_s)
        if not (np.isfinite(self.step_s) and self.step_s > 0):
            raise ValueError(f"step_s: expected a positive filter step in s, found {step_s!r}")
        self.spec = load_spec(imu)
        self.vref_sigma = float(vref_sigma)
        if not (np.isfinite(self.vref_sigma) and self.vref_sigma >= 0):
            raise ValueError(f"vref_sigma: expected a non-negative standard deviation in m/s, found {vref_sigma!r}")
        att = list(np.broadcast_to(np.asarray(att_sigma_deg, dtype=object), (3,)))
        self._att_sigma_u = att[2]
        self.att_sigma = np.radians([float(att[0]), float(att[1]), 5.0 if att[2] is None else float(att[2])])
        self.coarse_s = float(coarse_s)
        self.min_duration_s = self.coarse_s + 10.0

    def events(self, init_given):
        """Stages for the figures (:mod:`fusionbench.figures`): the hand-over from the own coarse alignment at
        ``coarse_s`` (s), when no initial attitude is given."""
        return [] if init_given else [(self.coarse_s, "coarse -> fine hand-over")]

    # ---------------------------------------------------------------- noise model
    def _qc(self):
        g, a = self.spec.gyro, self.spec.accel
        q = np.zeros(NX)
        q[0:3] = np.square(g.white)
        q[3:5] = np.square(a.white)[:2]
        q[5:8] = np.square(g.random_walk) + 2 * np.square(g.instability) / g.tau
        q[8:11] = np.square(a.random_walk) + 2 * np.square(a.instability) / a.tau
        return q

    def _p0(self, lat=None):
        """Initial covariance (11,): attitude, velocity (0.1 m/s), body-frame biases; ``lat`` (rad) sets the default
        azimuth prior from the gyro bias (``att_sigma_deg``)."""
        g, a = self.spec.gyro, self.spec.accel
        eps = np.hypot(np.hypot(g.bias, g.bias_sigma), g.instability)
        nab = np.hypot(np.hypot(a.bias, a.bias_sigma), a.instability)
        # floors: 0.01 deg/h and 10 ug, so that a zero datasheet figure does not freeze the state
        eps = np.maximum(eps, 0.01 * np.pi / 180 / 3600)
        nab = np.maximum(nab, 10e-6 * 9.80665)
        att = self.att_sigma.copy()
        if self._att_sigma_u is None and lat is not None:
            ratio = min(1.0, azimuth_bias_ratio(self.spec, lat))
            att[2] = min(max(att[2], 3.0 * np.arcsin(ratio)), np.radians(60.0))
        return np.concatenate([att, [0.1, 0.1], eps, nab]) ** 2

    def _new_bank(self, runs, P0):
        H = np.zeros((2, NX))
        H[0, 3] = H[1, 4] = 1.0
        return FilterBank(runs, P0, H, np.eye(2) * max(self.vref_sigma, 1e-3) ** 2, self.engine)

    def _q_scale(self, bank):
        """Factor (R,) on Q in the next prediction (1; the adaptive variant inflates it)."""
        return 1.0

    def _update(self, bank, z, k):
        """Measurement update k with z (R, 2) (the adaptive variant adapts R and Q first)."""
        bank.update(z)

    # ---------------------------------------------------------------- alignment
    def _align(self, imu, site: Site, aiding, init) -> AlignmentResult:
        """Align R recordings (body RFU increments, aiding rows or None): from ``init``, or after an inertial-frame
        coarse alignment over the first ``coarse_s`` seconds."""
        vref = per_increment_velocity(aiding, imu, self.name)
        if init is not None:
            return self._fine(imu, site, vref, init, np.zeros((imu.runs, 3)) if vref is None else vref[:, 0], imu.dt)
        coarse = InertialCoarseAligner(history_points=20, caller=self.name)
        k0 = int(round(self.coarse_s / imu.dt))
        # the fine stage keeps the whole record's sample interval (the rest's own, from its span, differs in the
        # last bits) and starts at the reference velocity at the hand-over
        return coarse_then_fine(imu, site, aiding, coarse, self.coarse_s, lambda rest, aid, C0, t_hand: self._fine(
            rest, site, None if vref is None else vref[:, k0:], C0,
            np.zeros((imu.runs, 3)) if vref is None else vref[:, k0 - 1], imu.dt))

    def _fine(self, imu, site, vref, C0, v0, dt) -> AlignmentResult:
        """The filter around the feedback-corrected strapdown from attitude ``C0`` (R, 3, 3) and velocity ``v0``
        (R, 3) m/s ENU, with sample interval ``dt`` (s)."""
        t, dth, dv = imu.increments()
        R, N, _ = dth.shape
        sd = Strapdown(NavState.broadcast(R, C0, v0, site.lat, site.lon, site.h), dt, height_fixed=True)
        m = max(1, int(round(self.step_s / dt)))
        T = m * dt  # the filter's update interval: step_s in whole samples
        steps = N // m
        tail = N - steps * m  # samples after the last filter step, integrated at the end (time rule)
        kf = FeedbackKalman(sd, self._new_bank(R, self._p0(site.lat)), self._qc(), T, dt, self._q_scale, self._update)
        out_t = np.empty(steps + (tail > 0))
        out_C = np.empty((R, steps + (tail > 0), 3, 3))
        out_s = np.empty((R, steps + (tail > 0), 3))
        for j in range(steps):
            a, b = j * m, (j + 1) * m
            out_s[:, j] = kf.step(dth[:, a:b], dv[:, a:b], None if vref is None else vref[:, b - 1, :2], j)
            out_t[j] = t[b - 1]
            out_C[:, j] = sd.state.C_bn
        if tail:  # the last samples, through the bias-compensated strapdown without an update
            kf.coast(dth[:, N - tail:], dv[:, N - tail:])
            out_t[-1], out_C[:, -1], out_s[:, -1] = t[-1], sd.state.C_bn, out_s[:, -2] if steps else np.nan
        return AlignmentResult(self.name, out_t, out_C, {"gyro_bias": kf.eps_hat, "accel_bias": kf.nab_hat},
                               sigma_phi=out_s, imu_model=self.spec.name)


class AdaptiveKalmanAligner(KalmanAligner):
    """Innovation-adaptive Kalman alignment (method ``akf``).

    * R by Sage-Husa with fading factor ``b``: ``R_k = (1 - d_k) R_{k-1} + d_k (nu nu^T - H P^- H^T)``,
      ``d_k = (1 - b) / (1 - b^(k+1))``, on the diagonal (the two channels' noises are independent;
      the full form can turn R indefinite once floored), floored at ``r_floor`` times the nominal R.
    * Q by covariance matching: over the last ``window`` updates the mean innovation covariance C
      is compared with ``H P^- H^T + R``; the ratio ``tr(C - R) / tr(H P^- H^T)``, bounded to
      [1, ``max_inflation``] and smoothed over the window, scales Q in the next predictions. (Scaling
      P^- itself runs away here: the unobservable azimuth and bias directions grow without bound.)
    """

    name = "akf"
    # as kf, and up to 70 deg: under seed 000's sway at 75 deg its adaptation leaves 1.95 bounds (kf 1.02)
    supports = Supports(bases=("static", "sway"), max_abs_lat_deg=70.0, max_bias_ratio=0.05)
    description = "innovation-adaptive Kalman alignment (Sage-Husa R, covariance-matched Q inflation)"

    def __init__(self, b=0.98, window=50, r_floor=0.1, max_inflation=100.0, imu="navigation", **kw):
        super().__init__(imu=imu, **kw)
        self.b, self.window, self.r_floor = float(b), int(window), float(r_floor)
        self.max_inflation = float(max_inflation)

    def _new_bank(self, runs, P0):
        bank = super()._new_bank(runs, P0)
        bank.R0 = bank.R.copy()
        bank.innov = np.zeros((runs, self.window, 2, 2))  # the last `window` innovation products, a ring
        bank.count = 0
        bank.q_scale = np.ones(runs)
        return bank

    def _q_scale(self, bank):
        return bank.q_scale

    def _update(self, bank, z, k):
        H = bank.H
        HPH = H @ bank.P @ H.T
        nu = z - bank.x @ H.T  # (R, 2)
        bank.innov[:, bank.count % self.window] = nu[:, :, None] * nu[:, None, :]
        bank.count += 1
        # Sage-Husa R, per channel (a diagonal R stays positive definite once floored), floored at a
        # fraction of the nominal R
        d = (1 - self.b) / (1 - self.b ** (k + 1))
        diag = lambda A: np.diagonal(A, axis1=1, axis2=2)  # noqa: E731
        r = (1 - d) * diag(bank.R) + d * (nu**2 - diag(HPH))
        R_new = np.zeros_like(bank.R0)
        R_new[:, [0, 1], [0, 1]] = np.maximum(r, self.r_floor * diag(bank.R0))
        bank.R = R_new
        # covariance matching: scale Q (for the next predictions) when the innovations exceed what
        # H P^- H^T + R explain; smoothed and bounded, so that P cannot run away
        if bank.count >= self.window:
            C = bank.innov.mean(axis=1)
            tr = lambda A: np.trace(A, axis1=1, axis2=2)  # noqa: E731
            lam = np.clip(tr(C - R_new) / tr(HPH), 1.0, self.max_inflation)
            bank.q_scale = (1 - 1.0 / self.window) * bank.q_scale + lam / self.window
        bank.update(z)
