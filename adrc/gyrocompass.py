"""ADRC strapdown gyrocompass alignment from any heading (seed 000: Zhou, Yang and Qin, "Active disturbance rejection
control technique to gyrocompass alignment of SINS", Control and Decision 26(9), 2011, sections 3-4).

Two level channels, each a second-order plant in the level velocity error (eqs. 4-6)::

    east:  dvE'' = f_E + b u,  b = -g,  u = w_cN   (north command rate)
    north: dvN'' = f_N + b u,  b = +g,  u = w_cE   (east command rate)

are each closed by Han's ADRC (third-order ESO eq. 9, NLSEF eq. 11 with the sign of b0 carried to u0,
see :func:`adrc.primitives.nlsef`). The TD (eq. 7) is not evaluated: its reference is zero and it
starts at rest on it, so v1 = v2 = 0 for all time (fhan(0, 0) = 0) and the NLSEF sees -z1, -z2. The
commanded rates turn the computed frame inside the shared strapdown
(:class:`fusionbench.methods.compass.CommandLoop`); no azimuth command is given while levelling.

Why the printed gains pass the velocity disturbance into the levels
-------------------------------------------------------------------
Inside the linear zones of fal (delta = 20000 m/s) and fhan (r1 h1^2 = 2 m/s) the ADRC is a linear
compensator; :func:`level_loop_model` is the closed loop, :func:`level_noise` its noise gains. With the
printed parameters (:data:`PAPER_PARAMETERS`, 100-Hz IMU):

* the ESO's linear-zone gains are 1/h = 50 1/s, beta02 / delta^0.5 = 5.9 1/s^2 and
  beta03 / delta^0.75 = 0.23 1/s^3: poles at -50 and -0.059 +/- 0.034j 1/s, so z2 and z3 settle with
  a 17-s time constant while z1 follows the measurement within 20 ms;
* eq. 11 adds u0 to the command without dividing it by b0, so the loop obeys
  v'' = -(g / h1^2)(v + 2 c1 h1 v'): natural frequency sqrt(g) / h1 = 15.7 rad/s, damping
  c1 sqrt(g) = 2.5. The discrete closed loop at h = 0.02 s has its dominant pole at -3.0 1/s and a
  lightly damped mode at -56 +/- 130j 1/s (21 Hz, by the 25-Hz Nyquist frequency);
* the reported attitude is the loop's own, and to hold the measured velocity on the noisy zero
  reference the loop tilts the computed frame by (velocity noise)'' / g within that bandwidth:
  1507 arcmin of tilt per m/s of white reference noise, 75 arcmin rms at Table 1's 0.05 m/s
  (measured 75.3 and 75.0 arcmin, 95 % of the power above 5 Hz, peaks at 22-24 Hz). Real base motion
  goes the same way: a moored base moving 0.01 m/s rms in 0.1-2 Hz gives 9.5 arcmin rms of level
  wander, the size the comparisons on recordings found. The sway itself adds nothing to an exact
  strapdown (0.03 arcmin rms on the seed-000 sway without a disturbance);
* h1 = 4 s moves the loop to 0.16 and 3.9 1/s: 14 arcmin per m/s, 0.69 arcmin rms at 0.05 m/s
  (measured 0.70, mostly at 0.07-0.15 Hz), still four times the 0.15 arcmin (1 sigma) that keeps
  every run within half an arcminute of the limit. The printed ESO's own tilt estimate z2 / g is no
  better (29 arcmin per m/s: the 50-1/s z1 pole lets the noise into z2).

The level, the default way: estimated, not commanded
----------------------------------------------------
* The reported level is the loop's attitude corrected by the ESO's tilt estimate (``level="observer"``):
  z2 estimates dvN' = g ax + nabN in the north channel and dvE' = -g ay + nabE in the east one, so the
  computed frame is turned back by [ax, ay, 0] = [z2N / g, -z2E / g, 0] about its own axes, which leaves
  the limit [-nabN / g, nabE / g] (the paper's section 3.2 reads the level off z2 the same way). The
  ESO is told the commands (b0 u), so the tilt they impose cancels in the corrected attitude: its
  error is the ESO's estimation error alone, set by the ESO's bandwidth whatever the NLSEF does.
  ``level="loop"`` reports the loop's attitude, as the paper.
* The ESO's linear zone has a triple pole at ``eso_bandwidth`` = 0.13 rad/s (beta01 = 3 w,
  beta02 = 3 w^2 delta^0.5, beta03 = w^3 delta^0.75), a decade below the sway (1.3-3.1 rad/s at
  0.2-0.5 Hz). Its extended state z3 carries the steady earth-rate, gyro-bias and coupling terms of
  the drift, so the estimate has no lag in steady state. The bandwidth trades the reference noise
  (its share grows as w^1.5) against the gyro's angle random walk (falls as w^-0.5); per channel,
  1 sigma, from :func:`level_noise`: 0.014 arcmin (seed 000, no reference noise), 0.11 (seed 000 or
  navigation grade, 0.05 m/s), 0.25-0.27 (tactical grade, 0-0.05 m/s), where a Kalman filter told
  the noise levels reaches 0.010, 0.026 and 0.13-0.25. No fixed bandwidth serves both ends: 0.5
  rad/s would give 0.16 on a tactical IMU without reference noise and 0.85 with 0.05 m/s.
* The NLSEF (h1 = 4 s, c1 = 0.8; the velocity loop at 0.27 and 4.7 1/s with this ESO) keeps the
  computed frame within about an arcminute of level, which is all the azimuth fit needs.
* h = ``step_s`` = 0.1 s: ten 100-Hz samples per step, the reference averaged over them (nothing is lost at
  these bandwidths), five times fewer control steps than h = 0.02 s.

Checked on 100-Hz simulations, 300 and 600 s (static, 1-2 deg and seed-000 sways; latitudes 0, 34,
-45, 60, 75 deg; headings 0, 90, 179, -179 deg; seed000, navigation and tactical grade; 0, 0.01 and
0.05 m/s of reference noise; from a levelled guess and from [3, 3, 180] deg): seed 000 and navigation
grade end within 0.35 arcmin of the level limit in every run, with the azimuth 1.0-1.4 times
ARW / (OMEGA_IE cos L sqrt T) rms about its limit; a tactical IMU ends beyond 0.5 arcmin in 5-22 % of
the runs. Its gyro noise alone puts a Kalman filter there in up to 9 %, and its azimuth error (9-13 deg
rms at 75 deg) turns the 1.5-arcmin tilt of its horizontal bias by as much, 0.2-0.3 arcmin for any
method. From 180 deg on paper000 (0.05 m/s) the azimuth stays within 30 arcmin of its limit after 79 s
on average (125 s at most).

Azimuth, beside the levelling:

1. **one-shot**: from ``fit_from_s`` the level channels feed
   :class:`fusionbench.methods.compass.AzimuthFit`, the least-squares form of eq. 19 (the steady commands
   are the curvature of the level velocity errors once the known commands are taken out, so the fit
   does not wait for the slow ESO to settle, and the level coupling terms come from the measured
   velocities); at ``shot_s`` its azimuth turns the reported attitude (eqs. 17-18).
2. **refinement** (so that the attitude at the last sample is the best the data allow): the fit
   goes on over the whole record and the reported attitude is the loop's attitude turned by its
   current estimate. The loops themselves are never turned: turning the computed frame would flip
   the level errors and the projected biases in the middle of the fit, while the ADRC levels just as
   well with any azimuth error (the ESO absorbs the earth-rate terms). With ``refine=False`` the
   azimuth of the shot is kept.

The history is the reported attitude after every control step.

The limits are those of any stationary alignment: level = accelerometer bias / g, azimuth
-epsE / (OMEGA_IE cos L).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from fusionbench.methods.aligner import AlignmentResult, Site, variant
from fusionbench.methods.aligner_base import AlignerBase, per_increment_velocity
from fusionbench.methods.claims import Supports
from fusionbench.methods.compass import MAX_LATITUDE_DEG, AzimuthFit, CommandLoop, correct_azimuth
from fusionbench.simulation.imu import load_spec
from fusionbench.simulation.strapdown import rodrigues

from .gyrocompass_compiled import run_compiled

_H = 0.02  # the printed step, s

#: Seed 000's printed configuration (section 5), the values of its formulas at the printed step
#: h = 0.02 s: ``ADRCGyrocompass(**PAPER_PARAMETERS)`` is the paper's gyrocompass. The reported level is
#: the loop's own attitude, as in the paper; the azimuth is refined continuously (eq. 19 read over the
#: record), since the paper's Figs. 3-4 show an azimuth that converges over 250 s, which a single
#: correction at one instant cannot draw (its text describes the correction as one-shot).
PAPER_PARAMETERS = {
    "step_s": _H, "c0": 1.0, "r0": 1 / _H**2, "h0": _H,
    "beta01": 1 / _H, "beta02": 1 / (3 * _H**2), "beta03": 1 / (18**2 * _H**3), "delta": 20000.0,
    "r1": 1 / _H, "c1": 0.8, "h1": 10 * _H,
    "level": "loop", "refine": True,
}


def level_loop_model(method, dt, g=9.8):
    """Linear model of one level channel (north: b = +g) closed by ``method`` on an IMU sampled at ``dt`` (s).

    Inside the linear zones of fal and fhan (every velocity error of a levelled gyrocompass is) the loop
    is linear: per control step h = m dt (the method's ``step_s`` in m whole samples) with state x = [v, th, z1, z2, z3] (velocity
    error m/s, tilt rad, ESO states), the command u = -(z1 + 2 c1 h1 z2) / h1^2 - z3 / g held over the
    step, the measurement y = v + n at its end (n: the reference's noise averaged over the step)::

        x(k+1) = A x(k) + B [w_g, w_a, n](k+1)

    with w_g the gyro's angle noise (rad) and w_a the accelerometer's velocity noise (m/s) over the step.

    Returns
    -------
    A : ndarray, shape (5, 5)
    B : ndarray, shape (5, 3)
    h : float
        Control step, s.
    m : int
        IMU samples per step.
    """
    m = max(1, int(round(method.step_s / dt)))
    h = m * dt
    k = method.gains(h)
    b2, b3 = k["beta02"] / method.delta**0.5, k["beta03"] / method.delta**0.75  # fal's linear zone
    h1, c1 = k["h1"], method.c1
    Kz = np.array([-1.0 / h1**2, -2.0 * c1 / h1, -1.0 / g])  # u = Kz [z1, z2, z3] (fhan's linear zone)
    A = np.zeros((5, 5))
    B = np.zeros((5, 3))
    A[0, :2] = 1.0, g * h
    A[0, 2:] = g * h * h / 2 * Kz
    A[1, 1] = 1.0
    A[1, 2:] = h * Kz
    B[0, 1] = B[1, 0] = 1.0
    E = -A[0].copy()  # innovation e = z1 - y(k+1) = E x + Eb w
    E[2] += 1.0
    Eb = np.array([0.0, -1.0, -1.0])
    A[2] = h * (np.eye(5)[3] - k["beta01"] * E)
    A[2, 2] += 1.0
    A[3] = h * (np.eye(5)[4] - b2 * E)
    A[3, 3] += 1.0
    A[3, 2:] += h * g * Kz
    A[4] = -h * b3 * E
    A[4, 4] += 1.0
    B[2], B[3], B[4] = -h * k["beta01"] * Eb, -h * b2 * Eb, -h * b3 * Eb
    return A, B, h, m


def level_noise(method, dt, sigma_v=0.0, arw=0.0, vrw=0.0, g=9.8):
    """Stationary level error (rad, 1 sigma) of one channel from white noises, from :func:`level_loop_model`.

    Parameters
    ----------
    method : ADRCGyrocompass
    dt : float
        IMU sample interval, s.
    sigma_v : float
        White noise of the velocity reference, m/s per sample.
    arw, vrw : float
        Gyro angle random walk (rad/sqrt(s)) and accelerometer velocity random walk (m/s/sqrt(s)).

    Returns
    -------
    loop, observer : float
        Tilt of the loop's own attitude, and of that attitude corrected by the ESO (th - z2 / g), rad;
        NaN when the discrete loop is unstable.
    """
    A, B, h, m = level_loop_model(method, dt, g)
    if np.max(np.abs(np.linalg.eigvals(A))) >= 1.0:
        return np.nan, np.nan
    P = scipy.linalg.solve_discrete_lyapunov(A, B @ np.diag([arw**2 * h, vrw**2 * h, sigma_v**2 / m]) @ B.T)
    c_loop = np.array([0.0, 1.0, 0.0, 0.0, 0.0])
    c_obs = np.array([0.0, 1.0, 0.0, -1.0 / g, 0.0])
    return float(np.sqrt(c_loop @ P @ c_loop)), float(np.sqrt(c_obs @ P @ c_obs))


class ADRCGyrocompass(AlignerBase):
    """ADRC gyrocompass (method ``adrc``): the levels read off the ESO, the azimuth off the commands.

    The defaults are this project's working configuration (see the module docstring);
    ``ADRCGyrocompass(**PAPER_PARAMETERS)`` is seed 000's printed one. The whole control loop (strapdown, ESO,
    NLSEF, azimuth fit) is compiled, all runs in one call (:mod:`adrc.gyrocompass_compiled`); its NumPy oracle is
    ``tests/oracles/adrc_gyrocompass.py``.

    Parameters
    ----------
    step_s : float
        ADRC step, s (0.1): the step h of Han's discrete formulas (ESO, TD, NLSEF and the gains below that
        default to expressions in h; :mod:`adrc.primitives` keeps the symbol h). Rounded to a whole number of
        IMU samples; a recording sampled more slowly runs the ADRC at its own sample interval, and gains that
        are unstable at that step (in the linear zone, :func:`level_loop_model`) are refused with a ValueError.
    c0, r0, h0 : float, optional
        TD damping, acceleration bound (default 1/h^2, 1/s^2 x m/s) and step (default h, s). The TD is
        not evaluated (its reference and initial state are zero, so its output is zero); they are
        accepted so that the printed parameter set is.
    beta01, beta02, beta03 : float, optional
        ESO gains of eq. 9 (1/s and fal-scaled). Default: from ``eso_bandwidth``, or the printed
        1/h, 1/(3 h^2), 1/(18^2 h^3) when that is None.
    delta : float
        fal's linear zone, m/s (20000: every velocity error lies inside it, so the ESO is linear).
    eso_bandwidth : float or None
        Triple pole of the ESO's linear zone, rad/s (0.13): beta01 = 3 w, beta02 = 3 w^2 delta^0.5,
        beta03 = w^3 delta^0.75, whatever the step; for the betas not given. Unused (None) when all
        three are given.
    r1, c1, h1 : float, optional
        NLSEF bound (default 1/h), damping (0.8) and step (4 s; the printed 10 h when None).
    level : {"observer", "loop"}
        Reported level: the loop's attitude corrected by the ESO's tilt estimate z2 / b0 ("observer",
        default), or the loop's attitude itself ("loop", the paper).
    fit_from_s, shot_s : float
        Start of the azimuth fit (the level loops have pulled a large tilt in by then) and time of
        the one-shot azimuth correction, s.
    refine : bool
        Keep refining after the shot (default); False keeps the shot's azimuth.
    imu : str, path or IMUSpec, optional
        The IMU (:func:`fusionbench.simulation.imu.load_spec`), used only to refuse when its gyro bias hides the earth
        rate (:func:`fusionbench.methods.claims.check_azimuth_observable`); None: not checked.
    """

    positive_options = ("step_s", "h1", "c0", "c1", "delta", "eso_bandwidth", "shot_s")

    name = "adrc"
    description = ("ADRC gyrocompass (seed 000): ESO/NLSEF level loops with the level read off the ESO, azimuth "
                   "from the steady commands (eq. 19, least squares)")
    supports = Supports(bases=("static", "sway"), max_abs_lat_deg=80.0)
    max_latitude_deg = MAX_LATITUDE_DEG

    def __init__(self, step_s=0.1, c0=1.0, r0=None, h0=None, beta01=None, beta02=None, beta03=None, delta=20000.0,
                 eso_bandwidth=0.13, r1=None, c1=0.8, h1=4.0, level="observer", fit_from_s=10.0, shot_s=40.0,
                 refine=True, imu=None):
        self.spec = None if imu is None else load_spec(imu)
        self.step_s = float(step_s)
        self.c0, self.c1, self.delta = c0, c1, float(delta)
        given = (beta01, beta02, beta03)
        # explicit gains (the printed ones) leave no role to the bandwidth
        self.eso_bandwidth = None if eso_bandwidth is None or None not in given else float(eso_bandwidth)
        if level not in ("observer", "loop"):
            raise ValueError(f"level: expected 'observer' or 'loop', found {level!r}")
        self.level = level
        self._given = {"r0": r0, "h0": h0, "beta01": beta01, "beta02": beta02, "beta03": beta03, "r1": r1, "h1": h1}
        for name, value in self.gains(self.step_s).items():
            setattr(self, name, value)
        self.fit_from_s, self.shot_s, self.refine = fit_from_s, shot_s, refine
        self.min_duration_s = float(shot_s) + 10.0  # the azimuth is only known after the shot

    def gains(self, h):
        """The step-dependent parameters for step ``h`` (s, ``step_s`` rounded to whole samples) where not given:
        the ESO's from ``eso_bandwidth`` (independent of h), else the paper's formulas in h.

        A recording sampled more slowly than ``step_s`` runs the ADRC at its own sample interval."""
        defaults = {"r0": 1.0 / h**2, "h0": h, "beta01": 1.0 / h, "beta02": 1.0 / (3 * h**2),
                    "beta03": 1.0 / (18**2 * h**3), "r1": 1.0 / h, "h1": 10 * h}
        w = self.eso_bandwidth
        if w is not None:
            defaults.update(beta01=3 * w, beta02=3 * w**2 * self.delta**0.5, beta03=w**3 * self.delta**0.75)
        return {k: (defaults[k] if v is None else v) for k, v in self._given.items()}

    def events(self, init_given):
        """Stages for the figures (:mod:`fusionbench.reports.figures`), s: the azimuth shot (eqs. 17-18)."""
        return [(float(self.shot_s), "azimuth shot")]

    def _align(self, imu, site: Site, aiding, init) -> AlignmentResult:
        """Align R recordings on a stationary or swaying base (body RFU, ENU); see the module docstring. Without
        ``init`` the loop starts levelled with yaw 0."""
        loop = CommandLoop(imu, site, init, self.step_s, per_increment_velocity(aiding, imu, self.name))
        h, R, g = loop.step_s, loop.R, site.g  # h: Han's step, step_s in whole samples
        A, _, _, _ = level_loop_model(self, imu.dt, g)
        rho = float(np.max(np.abs(np.linalg.eigvals(A))))
        if rho >= 1.0:
            raise ValueError(f"{self.name}: step_s: the level loop is unstable at the {h:g} s step of this recording "
                             f"(spectral radius {rho:.3g} in the linear zone); its gains are for a {self.step_s:g} s step")
        k = self.gains(h)
        b0 = np.array([-g, g])  # channels: [east (drives w_cN), north (drives w_cE)]
        fit = AzimuthFit(R, h, site.lat, g)
        fit_from = int(round(self.fit_from_s / h))
        shot_step = max(int(round(self.shot_s / h)), fit_from + 4)
        hist_t = np.empty(loop.records)
        hist_t[:loop.steps] = loop.t[loop.m - 1::loop.m][:loop.steps]  # the ends of the steps
        hist_C = np.empty((R, loop.records, 3, 3))
        hist_az = np.full((R, loop.records), np.nan)
        every = max(1, int(round(0.1 / h)))  # the azimuth estimate is refreshed at 10 Hz
        tilt = np.zeros((R, loop.records, 2))  # the ESO's tilt estimate z2 / b0 = [ay, ax], rad
        az_shot = run_compiled(loop, fit, {**k, "delta": self.delta, "c1": self.c1}, b0, fit_from, shot_step, every,
                               hist_C, hist_az, tilt)
        t_last = loop.finish()  # the samples after the last ADRC step: the result ends at the last sample
        if t_last is not None:
            hist_t[-1], hist_C[:, -1] = t_last, loop.sd.state.C_bn
            hist_az[:, -1], tilt[:, -1] = hist_az[:, -2], tilt[:, -2]
        # the reported attitude at each step, from that step's loop attitude and estimates
        if self.level == "observer":  # turn the computed frame back by [ax, ay, 0] about its own axes
            hist_C = rodrigues(np.stack([tilt[..., 1], tilt[..., 0], np.zeros(tilt.shape[:2])], axis=-1)) @ hist_C
        az_used = hist_az if self.refine else np.broadcast_to(az_shot[:, None], hist_az.shape)
        hist_C[:, shot_step:] = correct_azimuth(hist_C[:, shot_step:], az_used[:, shot_step:])  # eqs. 17-18
        return AlignmentResult(self.name, hist_t, hist_C, {"azimuth_shot_rad": az_shot, "azimuth_estimate_rad": hist_az})


#: ``adrc-paper``: seed 000's printed parameters (h = 0.02 s, h1 = 10 h, the ESO of eq. 9 as printed, the level
#: read off the loop). Under a velocity disturbance its level loop turns the reference noise into tilt (1507 arcmin
#: per m/s) and the azimuth fails; see the module docstring and the paper000 reproduction note.
ADRCPaper = variant(ADRCGyrocompass, "ADRCPaper", "adrc-paper",
                    "ADRC gyrocompass with seed 000's printed parameters (h = 0.02 s, h1 = 10 h, level from the loop)",
                    **PAPER_PARAMETERS)
ADRCPaper.supports = Supports(bases=())  # the printed parameters claim no condition: they reproduce the paper
