"""ADRC strapdown gyrocompass alignment from any heading (seed 000, sections 3-4).

Two level channels, each a second-order plant in the level velocity error (eqs. 4-6)::

    east:  dvE'' = f_E + b u,  b = -g,  u = w_cN   (north command rate)
    north: dvN'' = f_N + b u,  b = +g,  u = w_cE   (east command rate)

are each closed by Han's ADRC (TD eq. 7, third-order ESO eq. 9, NLSEF eq. 11 with the sign of b0
carried to u0, see :func:`adrc.primitives.nlsef`). The commanded rates turn the computed frame
inside the shared strapdown (:class:`fusionbench.compass.CommandLoop`); no azimuth command is given
while levelling.

Azimuth, beside the levelling:

1. **one-shot** (the paper): from ``fit_from_s`` the level channels feed
   :class:`fusionbench.compass.AzimuthFit`, the least-squares form of eq. 19 (the steady commands
   are the curvature of the level velocity errors once the known commands are taken out, so the fit
   does not wait for the slow ESO to settle, and the level coupling terms come from the measured
   velocities); at ``shot_s`` its azimuth turns the reported attitude (eqs. 17-18).
2. **refinement** (beyond the paper, so that the attitude at the last sample is the best the data
   allow): the fit goes on over the whole record and the reported attitude is the loop's attitude
   turned by its current estimate. The loops themselves are never turned: turning the computed
   frame would flip the level errors and the projected biases in the middle of the fit, while the
   ADRC levels just as well with any azimuth error (the ESO absorbs the earth-rate terms). With
   ``refine=False`` the azimuth of the shot is kept (the paper's one-shot alignment).

The history is the reported attitude after every control step.

The limits are those of any stationary alignment: level = accelerometer bias / g, azimuth
-epsE / (OMEGA_IE cos L).
"""

from __future__ import annotations

import numpy as np

from fusionbench.aligner import AlignmentResult, Site
from fusionbench.compass import AzimuthFit, correct_azimuth, start_loop

from .primitives import ExtendedStateObserver, TrackingDifferentiator, nlsef


class ADRCGyrocompass:
    """ADRC gyrocompass (method ``adrc``). Defaults are seed 000's parameters.

    Parameters
    ----------
    h : float
        ADRC step, s (0.02). Rounded to a whole number of IMU samples.
    c0, r0, h0 : float, optional
        TD damping, acceleration bound (default 1/h^2) and step (default h).
    beta01, beta02, beta03 : float, optional
        ESO gains (defaults 1/h, 1/(3 h^2), 1/(18^2 h^3)).
    delta : float
        fal linear zone (20000 as printed: every velocity error lies inside it, so the ESO is linear).
    r1, c1, h1 : float, optional
        NLSEF bound (default 1/h), damping (0.8) and step (default 10 h).
    fit_from_s, shot_s : float
        Start of the azimuth fit (the level loops have pulled a large tilt in by then) and time of
        the one-shot azimuth correction, s.
    refine : bool
        Keep refining after the shot (default); False gives the paper's one-shot alignment only.
    """

    name = "adrc"
    description = "ADRC gyrocompass (seed 000): TD/ESO/NLSEF level loops, azimuth from steady commands (eq. 19)"

    def __init__(self, h=0.02, c0=1.0, r0=None, h0=None, beta01=None, beta02=None, beta03=None, delta=20000.0,
                 r1=None, c1=0.8, h1=None, fit_from_s=10.0, shot_s=40.0, refine=True):
        self.h = float(h)
        self.c0, self.c1, self.delta = c0, c1, delta
        self._given = {"r0": r0, "h0": h0, "beta01": beta01, "beta02": beta02, "beta03": beta03, "r1": r1, "h1": h1}
        for name, value in self.gains(self.h).items():
            setattr(self, name, value)
        self.fit_from_s, self.shot_s, self.refine = fit_from_s, shot_s, refine
        self.min_duration_s = float(shot_s) + 10.0  # the azimuth is only known after the shot

    def gains(self, h):
        """The step-dependent parameters for step ``h`` (s): the paper's formulas in h where not given.

        A recording sampled more slowly than ``self.h`` runs the ADRC at its own sample interval,
        and the defaults follow that step (1/h, 1/(3 h^2), ... are stable only for the step used)."""
        defaults = {"r0": 1.0 / h**2, "h0": h, "beta01": 1.0 / h, "beta02": 1.0 / (3 * h**2),
                    "beta03": 1.0 / (18**2 * h**3), "r1": 1.0 / h, "h1": 10 * h}
        return {k: (defaults[k] if v is None else v) for k, v in self._given.items()}

    def align(self, imu, site: Site, vref=None, init=None) -> AlignmentResult:
        """Align R recordings on a stationary or swaying base (body RFU, ENU); see the module docstring."""
        loop = start_loop(self, imu, site, vref, init, self.h)
        h, R, g = loop.period, loop.R, site.g
        k = self.gains(h)
        b0 = np.array([-g, g])  # channels: [east (drives w_cN), north (drives w_cE)]
        td = TrackingDifferentiator((R, 2), h, k["r0"], k["h0"], self.c0)
        eso = ExtendedStateObserver((R, 2), h, k["beta01"], k["beta02"], k["beta03"], self.delta, b0)
        u = np.zeros((R, 2))
        fit = AzimuthFit(R, h, site.lat, g)
        fit_from = int(round(self.fit_from_s / h))
        shot_step = max(int(round(self.shot_s / h)), fit_from + 4)
        hist_t = np.empty(loop.records)
        hist_C = np.empty((R, loop.records, 3, 3))
        hist_az = np.full((R, loop.records), np.nan)
        az_shot = np.full(R, np.nan)
        az = np.full(R, np.nan)
        every = max(1, int(round(0.1 / h)))  # the azimuth estimate is refreshed at 10 Hz
        for j, t, dv in loop:
            applied = np.stack([u[:, 1], u[:, 0]], axis=-1)  # [w_cE, w_cN] used during this period
            v1, v2 = td.update(0.0)
            z1, z2, z3 = eso.update(dv[:, :2], u)
            u = nlsef(v1 - z1, v2 - z2, z3, b0, k["r1"], k["h1"], self.c1)
            C_out = loop.sd.state.C_bn
            if j >= fit_from:
                fit.add(dv[:, :2], applied)
                if j == shot_step or (j - fit_from) % every == 0:
                    az = fit.azimuth()
                hist_az[:, j] = az
                if j == shot_step:
                    az_shot = az
                if j >= shot_step:  # eqs. 17-18 on the reported attitude
                    C_out = correct_azimuth(C_out, az if self.refine else az_shot)
            loop.omega_c = np.stack([u[:, 1], u[:, 0], np.zeros(R)], axis=-1)
            hist_t[j] = t
            hist_C[:, j] = C_out
        t_last = loop.finish()  # the samples after the last ADRC step: the result ends at the last sample
        if t_last is not None:
            C_out = loop.sd.state.C_bn
            if loop.steps > shot_step:
                C_out = correct_azimuth(C_out, az if self.refine else az_shot)
            hist_t[-1], hist_C[:, -1], hist_az[:, -1] = t_last, C_out, hist_az[:, -2]
        return AlignmentResult(self.name, hist_t, hist_C, {"azimuth_shot_rad": az_shot, "azimuth_estimate_rad": hist_az})
