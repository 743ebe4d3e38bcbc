"""Shared machinery of gyrocompass-type aligners: the closed loop around the strapdown, the azimuth
read from steady level commands (seed 000 (Zhou 2011, ADRC gyrocompass), eq. 19), and the one-shot azimuth correction
(eqs. 17-18).

A gyrocompass drives the computed navigation frame n' with commanded angular rates ``omega_c``
(rad/s, ENU, resolved in n') so that the velocity errors vanish. On a stationary base with the
level channels steady and no azimuth command, the Euler platform error angles
``alpha = [ax, ay, az]`` (see :mod:`fusionbench.simulation.attitude`) obey (seed 000, eqs. 14-15 with the
level coupling kept)::

    ax' = -sin(az) wN + ay wU - epsE + w_cE = 0
    ay' = (1 - cos(az)) wN - ax wU - epsN + w_cN = 0

with ``wN = OMEGA_IE cos L`` and ``wU = OMEGA_IE sin L``, so that (eq. 19)::

    sin(az) = (w_cE + ay wU - epsE) / wN
    cos(az) = 1 + (w_cN - ax wU - epsN) / wN

The unknown gyro biases are taken as zero, which leaves the azimuth limit -epsE / wN.
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.compass_compiled import FitState
from fusionbench.simulation import earth
from fusionbench.simulation.attitude import euler_to_dcm
from fusionbench.simulation.strapdown import NavState, Strapdown

#: Highest abs(latitude) of the gyrocompass-type aligners, deg (their ``max_latitude_deg``): they lose the compass
#: effect toward the poles (wN = OMEGA_IE cos L -> 0).
MAX_LATITUDE_DEG = 80.0


class AzimuthFit:
    """Least-squares form of eq. (19): the azimuth error from the level channels over the whole record.

    With the level loops closed (small level errors ax, ay) the level velocity errors of a
    stationary strapdown obey (seed 000, eqs. 12-15 with the level coupling, plus the strapdown's
    Coriolis terms)::

        dvN' =  g ax + nabN - 2 wU dvE,   ax' = -sin(az) wN + ay wU - epsE + w_cE
        dvE' = -g ay + nabE + 2 wU dvN,   ay' = (1 - cos(az)) wN - ax wU - epsN + w_cN

    Eq. 19 reads sin(az) and cos(az) off the steady commands. Here the level angles in the coupling
    terms are replaced by the velocity equations (``g ay wU = wU (nabE - dvE' + ...)``), which turns
    them into integrals of the measured velocity. With S = sin(az), C = cos(az), P = tau^2 / 2 the
    double integral of 1 over the window, D_E and D_N the double integrals of the commands and V the
    integrals of the velocity errors, the signals::

        yN = dvN + 3 wU V_E - g D_E                  = c0N + c1N tau - gwN S P + bN tau^2
        yE = dvE - 3 wU V_N + g D_N + g wN tau^2 / 2 = c0E + c1E tau + gwN C P + bE tau^2

    are linear in [c0N, c1N, c0E, c1E, S, C] but for the bias terms b (gyro and accelerometer
    biases: -g epsE/2 + wU nabE/2, ...), which cannot be told apart from S and C on a stationary
    base and so stay in them: the azimuth limit -epsE / wN + tan L nabE / g. The least-squares
    solution over the growing window gives az = atan2(S, C) from any heading, without waiting for
    the loops to be steady. The azimuth must not change during the fit: the aligners turn the loop's
    attitude only after it (the PID's one-shot correction ends its fit; the ADRC turns only the
    attitude it reports). Velocity corrections a loop applies itself (a classical damping term) must be
    added back to the velocity it passes in (terms of order wU^2 are neglected).

    Parameters
    ----------
    runs : int
        Batch size.
    step_s : float
        Control step of the loop, s (one ``add`` per step).
    lat : float
        Latitude, rad.
    g : float
        Gravity, m/s^2.
    """

    _SCALE = 100.0  # time unit of the fit, s (keeps the normal equations well conditioned)

    def __init__(self, runs, step_s, lat, g):
        self.step_s, self.lat, self.g = float(step_s), float(lat), float(g)
        self.wN = earth.OMEGA_IE * np.cos(lat)
        self.wU = earth.OMEGA_IE * np.sin(lat)
        self.R = runs
        self.I = np.zeros((runs, 3))       # integrals of [w_cE, w_cN, 1]
        self.D = np.zeros((runs, 3))       # double integrals of the same
        self.V = np.zeros((runs, 2))       # integrals of [dvE, dvN] (coupling and Coriolis terms)
        self._prev_dv = np.zeros((runs, 2))  # the velocity errors of the last step (read once n > 0)
        self.t_sums = np.zeros(3)          # sums of tau^0, tau^1, tau^2
        # per-run sums: P, tau P, P^2, yN, tau yN, yE, tau yE, P yN, P yE
        self.sums = np.zeros((runs, 9))
        self._count = np.zeros(1, dtype=np.int64)  # n, in an array that compiled loops update in place

    @property
    def n(self):
        """Number of steps added so far."""
        return int(self._count[0])

    def compiled_state(self):
        """The arrays :func:`fusionbench.methods.compass_compiled.fit_add` updates in place, in its argument order:
        a :data:`~fusionbench.methods.compass_compiled.FitState` (a compiled loop adds its steps to this very fit)."""
        return FitState(self.I, self.D, self.V, self._prev_dv, self.t_sums, self.sums, self._count)

    def add(self, dv_en, w_c_en):
        """Add one step.

        Parameters
        ----------
        dv_en : ndarray, shape (R, 2)
            Velocity errors [dvE, dvN] at the end of the step, m/s.
        w_c_en : ndarray, shape (R, 2)
            Commands [w_cE, w_cN] applied during the step, rad/s.
        """
        h = self.step_s
        if self.n:
            rate = np.empty((self.R, 3))
            rate[:, :2] = w_c_en
            rate[:, 2] = 1.0
            self.D += self.I * h + 0.5 * rate * h * h
            self.I += rate * h
            self.V += 0.5 * (self._prev_dv + dv_en) * h
        self._prev_dv[:] = dv_en
        tau = self.n * h / self._SCALE
        g = self.g
        P = self.D[:, 2] / self._SCALE**2
        cross = 3.0 * self.wU * self.V  # level coupling (1x) and Coriolis (2x) terms, integrated
        yN = dv_en[:, 1] + cross[:, 0] - g * self.D[:, 0]
        yE = dv_en[:, 0] - cross[:, 1] + g * self.D[:, 1] + 0.5 * g * self.wN * (self.n * h) ** 2
        self.t_sums += (1.0, tau, tau * tau)
        self.sums += np.stack([P, tau * P, P * P, yN, tau * yN, yE, tau * yE, P * yN, P * yE], axis=-1)
        self._count[0] += 1

    def azimuth(self):
        """The azimuth error az (R,) rad, in (-pi, pi], or NaN before 4 samples."""
        if self.n < 4:
            return np.full(self.R, np.nan)
        return fit_azimuth(self.t_sums, self.sums, self.g, self.wN)


def fit_azimuth(t_sums, sums, g, wN):
    """The azimuth error (rad, in (-pi, pi]) of :class:`AzimuthFit`'s sums after at least 4 steps, batched.

    Parameters
    ----------
    t_sums : ndarray, shape (..., 3)
        Sums of tau^0, tau^1, tau^2 (``AzimuthFit.t_sums``; one row per fit state).
    sums : ndarray, shape (R, ..., 9)
        The per-run sums (``AzimuthFit.sums``), the middle axes those of ``t_sums``: a history of fit states
        solves in one call (the same 6x6 solve per state as one at a time).
    g : float
        Gravity, m/s^2.
    wN : float
        Horizontal earth rate OMEGA_IE cos L, rad/s.

    Returns
    -------
    ndarray, shape (R, ...)
    """
    k = g * wN * AzimuthFit._SCALE**2
    s0, s1, s2 = np.moveaxis(t_sums, -1, 0)
    P, tP, PP, yN, tyN, yE, tyE, PyN, PyE = np.moveaxis(sums, -1, 0)
    # rows of xN = [1, tau, 0, 0, -k P, 0] and xE = [0, 0, 1, tau, 0, k P], summed products
    M = np.zeros(sums.shape[:-1] + (6, 6))
    M[..., 0, 0] = M[..., 2, 2] = s0
    M[..., 0, 1] = M[..., 1, 0] = M[..., 2, 3] = M[..., 3, 2] = s1
    M[..., 1, 1] = M[..., 3, 3] = s2
    M[..., 0, 4] = M[..., 4, 0] = -k * P
    M[..., 1, 4] = M[..., 4, 1] = -k * tP
    M[..., 2, 5] = M[..., 5, 2] = k * P
    M[..., 3, 5] = M[..., 5, 3] = k * tP
    M[..., 4, 4] = M[..., 5, 5] = k * k * PP
    b = np.stack([yN, tyN, yE, tyE, -k * PyN, k * PyE], axis=-1)
    theta = np.linalg.solve(M, b[..., None])[..., 0]
    return np.angle(np.exp(1j * np.arctan2(theta[..., 4], theta[..., 5])))


def correct_azimuth(C_bn, alpha_z):
    """Attitude after removing an azimuth error alpha_z (rad), eqs. (17-18).

    The computed frame n' is the true n turned by alpha_z about up, so ``C_bn = Rz(alpha_z) C_bn'``
    (the rotation acts on the navigation side; the paper's right-hand product coincides with it
    only for a level body). Batched: ``C_bn`` (..., 3, 3), ``alpha_z`` broadcast to (...).
    """
    C = np.asarray(C_bn, dtype=float)
    a = np.asarray(alpha_z, dtype=float)[..., None]
    c, s = np.cos(a), np.sin(a)
    out = C.copy()
    out[..., 0, :] = c * C[..., 0, :] - s * C[..., 1, :]
    out[..., 1, :] = s * C[..., 0, :] + c * C[..., 1, :]
    return out


def level_guess(imu, seconds=1.0):
    """C_bn guess (R, 3, 3) levelled from the mean specific force of the first ``seconds``, yaw 0.

    Pitch = asin(f_y / norm(f)), roll = atan2(-f_x, f_z) for C_bn = Rz(yaw) Rx(pitch) Ry(roll).
    """
    t, _, dv = imu.increments()
    n = max(1, int(round(seconds / imu.dt)))
    f = dv[:, :n].sum(axis=1)
    f = f / np.linalg.norm(f, axis=-1, keepdims=True)
    pitch = np.arcsin(np.clip(f[:, 1], -1, 1))
    roll = np.arctan2(-f[:, 0], f[:, 2])
    return euler_to_dcm(np.stack([pitch, roll, np.zeros_like(pitch)], axis=-1))


class CommandLoop:
    """Strapdown on a stationary base, stepped one control step at a time with commanded rates.

    Parameters
    ----------
    imu : IMUData
        The recordings (R runs).
    site : Site
        Position (held fixed).
    C0 : ndarray, shape (R, 3, 3), or None
        Initial attitude; None: levelled from the first second of data with yaw 0 (:func:`level_guess`).
    step_s : float
        Control step, s; rounded to a whole number of samples (the attribute :attr:`step_s` is the rounded one).
    vref : ndarray, shape (R, M, 3), optional
        Reference velocity (ENU, m/s) at the end of each increment interval; zero if None. The
        samples of each control step are averaged (the base is stationary, so this only filters
        the reference's noise).

    Iterate over the loop: each step integrates ``m`` samples with the current command and yields
    ``(j, t, dv)``: step index, time (s) and velocity error (R, 3) m/s against the reference.
    Set :attr:`omega_c` (R, 3) rad/s before the next step; the attitude and velocity are in
    :attr:`sd` (``sd.state.C_bn``, ``sd.state.v_n``) and may be corrected between steps.

    The steps cover ``steps * m`` samples; :meth:`finish` integrates the samples after the last whole
    step (fewer than ``m``) with the command of the last step, so the loop's attitude reaches the last
    sample (the time rule of :mod:`fusionbench.methods.aligner`). ``records`` is the number of attitudes a history
    with one entry per step and one for that tail holds.
    """

    def __init__(self, imu, site, C0, step_s, vref=None):
        self.t, dth, dv = imu.increments()
        self.R = dth.shape[0]
        self.m = m = max(1, int(round(step_s / imu.dt)))
        self.step_s = m * imu.dt
        self.steps = steps = self.t.size // m
        # one contiguous block per control step: (steps, R, m, 3), so no step copies its slice
        self.dth = np.ascontiguousarray(dth[:, :steps * m].reshape(self.R, steps, m, 3).swapaxes(0, 1))
        self.dv = np.ascontiguousarray(dv[:, :steps * m].reshape(self.R, steps, m, 3).swapaxes(0, 1))
        self._tail = (dth[:, steps * m:], dv[:, steps * m:])
        self.records = steps + (self.t.size > steps * m)
        self.vref = None
        if vref is not None:
            vref = np.asarray(vref, dtype=float)
            self.vref = vref[:, :steps * m].reshape(self.R, steps, m, 3).mean(axis=2).swapaxes(0, 1).copy()
        state = NavState.broadcast(self.R, level_guess(imu) if C0 is None else C0, lat=site.lat, lon=site.lon, h=site.h)
        self.sd = Strapdown(state, imu.dt, position_fixed=True)
        self.omega_c = np.zeros((self.R, 3))

    def __iter__(self):
        m = self.m
        for j in range(self.steps):
            self.sd.run(self.dth[j], self.dv[j], omega_cmd=self.omega_c, record_every=m)
            dv = self.sd.state.v_n
            if self.vref is not None:  # the reference's samples of the step, averaged (static base)
                dv = dv - self.vref[j]
            yield j, self.t[(j + 1) * m - 1], dv

    def finish(self):
        """Integrate the samples after the last whole step with the last command.

        Returns
        -------
        float or None
            The time of the last sample, s, or None when the steps used every sample.
        """
        dth, dv = self._tail
        if dth.shape[1] == 0:
            return None
        self.sd.run(dth, dv, omega_cmd=self.omega_c, record_every=dth.shape[1])
        return float(self.t[-1])
