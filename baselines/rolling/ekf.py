"""Seed 002's (Ding, rolling-platform self-calibration) 45-state EKF for continuous rolling self-calibration and
self-alignment (method ``rolling-ekf``).

State ``x = [42 error coefficients (SI), phi, theta, psi (rad)]`` of :mod:`baselines.rolling`: the
attitude enters as the platform's Euler angles from North-Up-East, not as small misalignment angles,
so initial attitude errors of several degrees are allowed. Measurements: the three accelerometer
outputs (m/s^2) every ``filter_s`` (0.2 s). The filter knows its torque commands.

Model (``baselines.rolling`` module notes)::

    x' = f(x, w_cmd) = [0 (42);  E(angles) w_np^p]
    w_np^p = G^-1 ((I + diag KT) w_cmd + eps(c, f^p)) - C_pn^T w_ie^n   (exact; not the paper's eq. 19)
    f^p = g M^T e_U,   M = P C_pn = Rx(phi) Ry(theta) Rz(psi)
    y = h(x) = K0 + (1 + K1) a + K2 a^2,   a = A(c) f^p

with E the inverse of the Euler-rate matrix B (``w = B [phi', theta', psi']``)::

    phi' = (cos psi w_x - sin psi w_y) / cos theta
    theta' = sin psi w_x + cos psi w_y
    psi' = w_z - sin theta phi'

Jacobians: analytic, in :mod:`baselines.rolling.jacobians` (tests compare them with central finite
differences).

Filter (Joseph-form EKF update, the equations of filterpy's :class:`~filterpy.kalman.ExtendedKalmanFilter`)
on the states scaled by their prior standard deviations (``x = D z``; the raw states span 1e-12 rad/s to
0.1 rad, too wide for the covariance in float64). The covariance is error-state (next section); the estimate is
propagated over each filter step with 4th-order Runge-Kutta of ``f`` (command held), the covariance with
``Phi = I + F_e T + (F_e T)^2 / 2``. F_e has only three non-zero rows (the attitude's), so Phi = I + U
with U three rows too, and ``Phi P Phi^T = P + U P + P U^T + U P U^T`` takes two 3 x 45 x 45 products.
Process noise only on the attitude, from the gyros' white drift (``q T I``, q the rate noise density,
rad^2/s); measurement noise the accelerometers' white noise. The model evaluations of the inner loop
(RK4, F_e, H_e, h, the error injection, the sigmas) are compiled (:mod:`baselines.rolling.kernels`). The
update (``engine``): ``"numpy"`` (default) does filterpy's arithmetic directly on the arrays (:func:`joseph_update`:
``S = H P H^T + R``, ``K = P H^T inv(S)``, ``P = (I - K H) P (I - K H)^T + K R K^T``, in filterpy's
operation order and with its LAPACK inverse), without its per-call overhead (attribute juggling, copies of
the prior and posterior); ``"filterpy"`` calls :meth:`ExtendedKalmanFilter.update`, the reference (the two
agree to rounding: tests/test_rolling_ekf.py). One step takes about 0.15 ms with numpy, 0.175 ms with
filterpy (``benchmarks/perf_rolling.py --quick --engine``, 2 cores, load 3), one pass over the paper's
27 000 outputs about 4 s.

Error-state covariance. The estimate keeps the Euler angles, but the covariance is that of the error
``e = [c_true - c_est (42), eta (3)]`` with ``C_true = (I - [eta x]) C_est`` (eta a small rotation in n)::

    eta' = -C dw/dc dc + C dw/df C^T [f^n x] eta - [w_ie^n x] eta            (F_e: jacobians.error_F)
    y - h(x_est) = H_e e,  H_e = [dh/dc,  -diag(s) A C^T [f^n x]]             (jacobians.error_H)

after each update the estimated error is folded into the estimate (coefficients added, attitude turned by
``C <- R(-eta) C``) and reset to zero. Why: with the angles' own covariance, the filter linearised the
unobservable turn about the true vertical at the wrong tangent while the tilt was degrees off, read the
azimuth as observed (its sigma fell from 5 deg to 0.005 deg in 1 s with theta 3 deg off) and diverged;
in error-state form the vertical column of H_e is zero whatever the estimate. The filter starts levelled
(:func:`level`) and, while the attitude is degrees off, adds the second-order output term
``second_order * g^2 (s_h^2 s_v^2 + s_h^4)`` to R (s_h^2, s_v^2 the tilt and azimuth variances of eta).

Second pass (``passes=2``, the default). While the attitude is degrees off and the tilt is still
confounded with the accelerometer biases, the first pass inflates R by the second-order term, by up to
1e3-1e5 for the whole first south roll (1800 s): it converges from 5 deg but throws away most of that
information and ends 20-100 times above the information bound on the gyro and torquer terms (one draw:
gyro bias 0.0016 deg/h, torquer 40 ppm, azimuth 6-170 arcsec). Without the inflation it diverges even
when started on the truth: noise moves the 5-deg-uncertain azimuth, and the linearisation follows it. So
the first pass's final estimate is carried back to the start through the model (:func:`backward`) and
the data run again through a linearised Kalman filter about that fixed nominal trajectory (F and H along
it, the error carried rather than folded into the state; same prior, no inflation): one Gauss-Newton
step of the batch fit, whose linearisation error is second order in the first pass's error (arcseconds,
well under the 1-ug noise). Measured on ``paper002-rolling`` draws: every group inside the paper's
claims, the filter's sigmas 1-3 times the information bound, noise-free errors below 2e-5 of the truth.
The prior is then centred on the first pass's estimate rather than on zero; the data outweigh it by
5 to 14 orders of magnitude in every direction (the smallest eigenvalue of the scaled information is
2e5), so it changes nothing measurable.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.linalg
from filterpy.kalman import ExtendedKalmanFilter
from threadpoolctl import threadpool_limits

from fusionbench.simulation import earth

from . import kernels as K
from . import model
from .figures import sensitivity_figure
from .observability import information_rank, informed_directions, sensitivity_curves
from .priors import ANGLE_SIGMA_DEG, prior_sigma
from .protocol import CalibrationResult
from .scheme import scheme_events

#: ``passes="auto"``: stop when a linearised pass moved every coefficient by less than this many of its
#: sigmas from the pass before; never more than this many passes in all.
AUTO_TOLERANCE = 0.5
AUTO_MAX_PASSES = 5
#: Values of the ``engine`` option: the update done on the arrays here, or by filterpy (the reference).
ENGINES = ("numpy", "filterpy")


def level(y_mean):
    """Attitude angles levelled from the mean accelerometer outputs ``y_mean`` (m/s^2, ~ f^p), azimuth
    theta = 0: phi and psi put gravity on ``y_mean``'s direction.

    Why: gravity fixes two of the three angles; started from angles off in tilt by degrees, the EKF
    linearises the unobservable rotation about the true vertical at the wrong tangent, reads the azimuth
    as observed and locks it degrees off with a tiny sigma (measured: theta 3 deg off, sigma 0.005 deg
    after 1 s). Levelled first, only the azimuth is off, along the direction the filter sees as unobserved.
    With theta = 0, ``f^p / g = [sin psi cos phi, cos psi cos phi, -sin phi]``.
    """
    u = np.asarray(y_mean, dtype=float)
    u = u / np.linalg.norm(u)
    return np.array([-np.arcsin(np.clip(u[2], -1, 1)), 0.0, np.arctan2(u[0], u[1])])


class RollingEKF:
    """Seed 002's rolling self-calibration and self-alignment EKF (method ``rolling-ekf``).

    Parameters
    ----------
    gyro_noise : float
        Gyro white drift, standard deviation per simulator sample (rad/s), as in
        :func:`baselines.rolling.simulator.simulate`.
    sample_s : float
        The sample time that ``gyro_noise`` refers to, s (rate noise density ``gyro_noise^2 sample_s``).
    accel_noise : float
        Accelerometer output noise, m/s^2 per output.
    angle_sigma_deg : float
        Prior standard deviation of the attitude angles, deg.
    prior : dict, optional
        Overrides of :data:`baselines.rolling.priors.PRIOR_SIGMA` (customary units).
    level_s : float
        Seconds of outputs averaged for the initial levelling when no ``x0`` is given.
    second_order : float
        Weight of the second-order output term added to R in the first pass, ``g^2 (s_h^2 s_v^2 + s_h^4)``
        (s_h^2, s_v^2 the tilt and azimuth error variances). 3 by default: on three draws of
        ``paper002-rolling`` (one pass) the largest abs(error) / sigma of the coefficients was 2.8 with 3
        against 27 with 1 (overconfident), and 1.3 with 10 at the price of accuracy; 0.1 diverges.
    passes : int or "auto"
        1: the causal EKF alone (what a real-time system can run). 2 (default): then a linearised Kalman
        filter about the first pass's estimate carried back to the start (module notes, "Second pass").
        Each further pass relinearises about the last (Gauss-Newton). ``"auto"``: linearised passes until
        one moves no coefficient by more than :data:`AUTO_TOLERANCE` of its sigma from the pass before
        (the linearisation point was already the answer), at most :data:`AUTO_MAX_PASSES` in all. The count
        is in ``result.figures["passes"]`` and the last pass's largest move, in sigmas, in
        ``result.figures["last_pass_move_sigma"]``. From the third pass on a large move says the passes have
        not converged; the second always moves far from the first, whose R was inflated. Measured on ``paper002-rolling``
        with noise: two passes land within 3.3 sigmas for initial azimuth errors of -5, 3 and 5 deg; at
        10 deg the first pass ends outside the linear range and two passes are 118 and 1682 sigmas off on
        two draws; three passes land within 2.5 sigmas on the first, ``"auto"`` (5 passes) within 2.2 on the
        second.
    engine : {"numpy", "filterpy"}
        Who does the Kalman update: ``"numpy"`` (default), filterpy's equations on the arrays directly
        (:func:`joseph_update`); ``"filterpy"``, :class:`filterpy.kalman.ExtendedKalmanFilter`, the reference.
        Same estimates and sigmas to rounding (1e-9 relative checked by the tests); numpy is the faster.
    """

    name = "rolling-ekf"
    description = "seed 002's 45-state EKF: 42 platform error coefficients and the attitude angles from rolling"

    def __init__(self, gyro_noise=model.PAPER_GYRO_NOISE, sample_s=0.002, accel_noise=model.PAPER_ACCEL_NOISE,
                 angle_sigma_deg=ANGLE_SIGMA_DEG, prior=None, level_s=1.0, second_order=3.0, passes=2,
                 engine="numpy"):
        if not isinstance(engine, str) or engine not in ENGINES:
            raise ValueError(f"{self.name}: option engine: expected one of {ENGINES}, found {engine!r}")
        self.engine = engine
        if passes != "auto" and not (isinstance(passes, (int, np.integer)) and passes >= 1):
            raise ValueError(f"passes: expected a whole number >= 1 or 'auto', found {passes!r}")
        self.passes = passes
        self.q_rate = float(gyro_noise) ** 2 * float(sample_s)
        self.r = float(accel_noise) ** 2
        self.sigma0 = prior_sigma(angle_sigma_deg, prior)
        self.level_s = float(level_s)
        self.second_order = float(second_order)

    def calibrate(self, t, y, w_cmd, lat, h=0.0, x0=None):
        """Run the filter over one recording.

        Parameters
        ----------
        t : array_like, shape (M,)
            Filter times, s, uniformly spaced (the first is one step after the initial state).
        y : array_like, shape (M, 3)
            Accelerometer outputs at ``t``, m/s^2.
        w_cmd : array_like, shape (M, 3)
            Torque command (p frame, rad/s) held over the step ending at each ``t``.
        lat, h : float
            Latitude (rad) and height (m).
        x0 : array_like, shape (45,), optional
            Initial estimate. Default: zero coefficients (the paper's start) and the attitude levelled
            from the first ``level_s`` of outputs with theta (azimuth) 0 (:func:`level`).

        Returns
        -------
        CalibrationResult
        """
        t = np.asarray(t, dtype=float)
        y = np.asarray(y, dtype=float)
        w_cmd = np.asarray(w_cmd, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"t: expected at least two filter times, found shape {t.shape}")
        if y.shape != (t.size, 3) or w_cmd.shape != (t.size, 3):
            raise ValueError(f"y, w_cmd: expected shape ({t.size}, 3), found {y.shape} and {w_cmd.shape}")
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(w_cmd))):
            raise ValueError("y, w_cmd: expected finite values, found NaN or inf")
        with threadpool_limits(1):  # 45 x 45 products gain nothing from BLAS threads, and one thread keeps
            return self._run(t, y, w_cmd, lat, h, x0)  # the sums in a fixed order: identical numbers

    def _run(self, t, y, w_cmd, lat, h, x0):
        dt = float(t[1] - t[0])
        if x0 is None:
            x0 = np.zeros(model.N_STATES)
            x0[model.ANGLES] = level(y[t - t[0] < self.level_s].mean(axis=0))
        first = res = self._pass(t, y, w_cmd, lat, h, np.array(x0, dtype=float), self.second_order)
        auto = self.passes == "auto"
        done = 1
        while done < (AUTO_MAX_PASSES if auto else self.passes):
            # relinearise: a linearised Kalman filter about the last pass's estimate carried back to the start
            last = res
            res = self._pass(t, y, w_cmd, lat, h, backward(res.x[-1], w_cmd, dt, lat, h), 0.0, nominal=True)
            done += 1
            nc = model.N_COEFFS
            moved = np.max(np.abs(res.x[-1, :nc] - last.x[-1, :nc]) / res.sigma[-1, :nc])
            if auto and done >= 3 and moved < AUTO_TOLERANCE:
                break
        res.first_pass = first if done > 1 else None
        res.figures["passes"] = done
        if done > 1:  # how far the last pass moved from its linearisation point, in its sigmas
            res.figures["last_pass_move_sigma"] = float(moved)
        return res

    def _pass(self, t, y, w_cmd, lat, h, x, second_order, nominal=False):
        dt = float(t[1] - t[0])
        # covariance of the error state, scaled by the prior sigmas (e = D z): the raw errors span 1e-12
        # rad/s to 0.1 rad, too wide for a positive-definite covariance in float64
        D = self.sigma0
        kf = ExtendedKalmanFilter(dim_x=model.N_STATES, dim_z=3) if self.engine == "filterpy" else None
        P = np.eye(model.N_STATES)
        eye_x, eye_z = np.eye(model.N_STATES), np.eye(3)
        q_eta = self.q_rate * dt / D[model.ANGLES] ** 2  # gyro white drift as rotation noise in n
        g = float(earth.gravity(lat, h))
        wie = earth.earth_rate_n(lat)
        A = model.ANGLES
        xs = np.empty((t.size, model.N_STATES))
        sig = np.empty((t.size, model.N_STATES))
        info = np.zeros((model.N_STATES, model.N_STATES))
        Phi_0 = np.eye(model.N_STATES)
        scale = dt * D[None, :] / D[A, None]
        e = np.zeros((model.N_STATES, 1))
        for k in range(t.size):
            # Phi = I + F T + (F T)^2 / 2 = I + U: F_e has only the three attitude rows, so U does too and
            # Phi P Phi^T = P + U P + P U^T + U P U^T costs two 3 x 45 x 45 products instead of 45^3 ones
            Fr = K.error_F_rows(x, w_cmd[k], g, wie) * scale
            U = Fr + 0.5 * Fr[:, A] @ Fr
            Phi_0[A] += U @ Phi_0
            x = K.rk4(x, w_cmd[k], dt, g, wie)
            P[A] += U @ P
            P[:, A] += P @ U.T
            P[A, A] += np.diag(q_eta)
            Hs = K.error_H(x, g) * D[None, :]
            HP = Hs @ Phi_0
            info += HP.T @ HP / self.r
            # EKF: the error is folded into x after every update; linearised KF about a fixed nominal: it
            # is carried, x stays the nominal
            if nominal:
                e[A] += U @ e
            else:
                e = np.zeros((model.N_STATES, 1))
            # second-order term of h in the attitude error eta (the second-order EKF's added variance):
            # f^p changes by C^T (eta x (eta x f^n)) / 2 = g C^T (eta_h eta_U - |eta_h|^2 e_U) / 2 (eta_h the
            # tilt, eta_U the azimuth part); while the attitude is degrees off this is tens of ug, and
            # without it the 1-ug outputs make the filter trust the wrong linearisation (it diverges)
            s_h2 = P[42, 42] * D[42] ** 2 + P[43, 43] * D[43] ** 2
            s_v2 = P[44, 44] * D[44] ** 2
            Rk = (self.r + second_order * g * g * (s_h2 * s_v2 + s_h2 * s_h2)) * eye_z
            z = (y[k] - K.measurement(x, g)).reshape(3, 1)
            if kf is None:
                e, P = joseph_update(e if nominal else None, P, Hs, Rk, z, eye_x)
            else:
                kf.x, kf.P, kf.R = e, P, Rk
                kf.update(z, lambda z: Hs, lambda z: Hs @ z)
                e, P = kf.x, kf.P
            P = 0.5 * (P + P.T)
            xs[k] = K.inject(x, e[:, 0] * D)
            if not nominal:
                x = xs[k]
            sig[k] = K.state_sigmas(xs[k], P, D)
        figures = {"information_rank": information_rank(info), "informed_directions": informed_directions(info)}
        return CalibrationResult(t, xs, sig, figures, info, scale=D)

    def report_figures(self, folder, scheme, lat, h=0.0):
        """The output-sensitivity curves of ``scheme`` (seed 002 Figs. 4-7) into ``folder``; [(file, caption)]."""
        times, S = sensitivity_curves(scheme, lat, h)
        sensitivity_figure(times, S, path=Path(folder) / "sensitivity.png", events=scheme_events(scheme))
        return [("sensitivity.png", "output sensitivity of the coefficients along the scheme (seed 002 Figs. 4-7)")]


def joseph_update(x, P, H, R, z, eye):
    """One Kalman update, filterpy's :meth:`ExtendedKalmanFilter.update` arithmetic in its order, on the
    arrays: ``x`` (n, 1) the prior estimate (None: zero), ``P`` (n, n), ``H`` (m, n), ``R`` (m, m), ``z``
    (m, 1) the measurement, ``eye`` the (n, n) identity; returns the posterior ``(x, P)``. The residual is
    ``z - H x``; ``S = H P H^T + R``, ``K = P H^T inv(S)`` (scipy's LAPACK inverse, as filterpy), Joseph
    form ``P = (I - K H) P (I - K H)^T + K R K^T``. ``P`` is not modified."""
    PHT = P @ H.T
    Kg = PHT @ scipy.linalg.inv(H @ PHT + R, check_finite=False)
    if x is None:
        x = Kg @ z  # 0 + K (z - H 0): the same numbers
    else:
        x = x + Kg @ (z - H @ x)
    I_KH = eye - Kg @ H
    return x, (I_KH @ P) @ I_KH.T + (Kg @ R) @ Kg.T


def backward(x_end, w_cmd, dt, lat, h=0.0):
    """The 45-vector ``x_end`` at the last filter time carried back to the start (one step before the
    first filter time) through the model with its own coefficients: RK4 with step ``-dt`` (s) under the
    held commands ``w_cmd`` (M, 3) in reverse order. The gyros' white drift is not in it; over the
    paper's 5400 s it moves the attitude by about 0.2 arcsec."""
    x = np.array(x_end, dtype=float)
    w_cmd = np.asarray(w_cmd, dtype=float)
    g, wie = float(earth.gravity(lat, h)), earth.earth_rate_n(lat)
    for k in range(len(w_cmd) - 1, -1, -1):
        x = K.rk4(x, w_cmd[k], -dt, g, wie)
    return x


def _rk4(x, w_cmd, dt, lat, h):
    return K.rk4(np.asarray(x, dtype=float), np.asarray(w_cmd, dtype=float), dt, float(earth.gravity(lat, h)),
                 earth.earth_rate_n(lat))
