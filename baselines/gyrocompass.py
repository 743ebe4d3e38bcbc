"""Classical (PID) strapdown gyrocompass alignment from any heading.

Level loops (third order, per channel; north shown, east alike with the signs of b = -g)::

    dvN' = g phiE + nabN - k1 dvN            (velocity damping, applied to the strapdown velocity)
    w_cE = -(1 + k2) dvN / R - J,  J' = k3 dvN

with the characteristic polynomial s^3 + k1 s^2 + ws^2 (1 + k2) s + g k3 = (s + sigma)(s^2 + 2 sigma s
+ sigma^2 / xi^2): ``k1 = 3 sigma``, ``k2 = sigma^2 (2 + 1/xi^2) / ws^2 - 1``, ``k3 = sigma^3 / (g xi^2)``.

Compass loop (the north channel, second order, drives the azimuth)::

    w_cE = -(1 + k2) dvN / R,  w_cU = k3 / (W cos L) x,  x' = -k4 x + dvN

with s^4 + (k1 + k4) s^3 + (k1 k4 + ws^2 (1 + k2)) s^2 + k4 ws^2 (1 + k2) s + g k3 = (s^2 + 2 f s + 2 f^2)
(s^2 + 2 sigma s + 2 sigma^2): a level pair (f, from the stage's level decay time) and an azimuth pair (sigma, from
its azimuth decay time); :func:`compass_gains` solves for k1..k4. In both loops ``sigma = 2 pi xi / (Td sqrt(1 -
xi^2))`` from a decay time Td and xi = sqrt(2)/2, ws the Schuler frequency and R the earth radius. The PSINS toolbox
puts both pairs at the azimuth's (``k1 = k4 = 2 sigma``, ``k2 = 4 sigma^2 / ws^2 - 1``, ``k3 = 4 sigma^4 / g``; a
stage with equal decay times); the east tilt then follows the gyro noise with the azimuth's narrow bandwidth
(docs/methods/pid.md).

Stages (all times configurable):

1. **level** (until the first compass stage): third-order level loops in both channels, no azimuth loop; fast
   (``level_td_s``) from the start, narrower from each of ``level_stages`` on.
   The compass loop cannot start from any heading: at 180 deg the compass effect sin(az) W cos L
   vanishes and its derivative has the wrong sign, so 180 deg is its unstable equilibrium (a
   PSINS-style schedule from exactly 180 deg under seed 000's (Zhou 2011, ADRC gyrocompass) sway did not settle in 600
   s). The level loops, however, settle at any azimuth with steady commands that hold sin(az) and cos(az)
   (eq. 19 of seed 000). From ``fit_from_s`` the least-squares form of eq. 19
   (:class:`fusionbench.methods.compass.AzimuthFit`) reads them, and at ``shot_s`` the attitude is turned
   once by the azimuth found; the level integrators are shifted by the known change of the
   earth-rate terms, which leaves the levels steady. The compass loop reads the east tilt at its closing as an
   azimuth error (hundreds of arcmin of azimuth per arcmin of tilt: the azimuth is seen only through the tilt's
   drift), so the narrower level loops quiet the tilt the reference noise gives the fast ones before it closes.
2. **compass stages** (``compass_stages``, from the shot on): the north channel becomes the compass loop, its
   azimuth gain rising from zero over ``closing_ramp_s`` (a soft closing), first fast to pull in the residual of the
   shot, then slower and slower so that the narrow bands filter the sway, the velocity noise and the gyro noise.

The reported attitude is the loop's own (the classical method); its limits are those of any
stationary alignment.
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.aligner import AlignmentResult, Site
from fusionbench.methods.aligner_base import AlignerBase, per_increment_velocity
from fusionbench.methods.claims import Supports
from fusionbench.methods.compass import MAX_LATITUDE_DEG, AzimuthFit, CommandLoop, correct_azimuth
from fusionbench.simulation import earth
from fusionbench.simulation.imu import load_spec

from .gyrocompass_compiled import run_compiled


def sigma_of(td, xi):
    """Decay rate sigma (1/s) of a loop with decay time td (s) and damping ratio xi."""
    return 2 * np.pi * xi / (td * np.sqrt(1 - xi**2))


def level_gains(td, xi, ws2, g):
    """Third-order level-loop gains (k1 1/s, k2 dimensionless, k3 rad/s per m/s per s)."""
    s = sigma_of(td, xi)
    return 3 * s, s**2 * (2 + 1 / xi**2) / ws2 - 1, s**3 / (g * xi**2)


def compass_gains(td, xi, ws2, g, level_td=None):
    """Compass-loop gains (k1, k2, k3, k4) for the pole pairs s^2 + 2 sigma s + 2 sigma^2 of decay time ``td`` (s)
    and of ``level_td`` (s; default ``td``: the double pair).

    ``xi`` only sets sigma: each pole pair itself has damping sqrt(2)/2. With the characteristic polynomial
    s^4 + a3 s^3 + a2 s^2 + a1 s + a0 of the loop (module docstring), k1 + k4 = a3, k1 k4 + W = a2, k4 W = a1 and
    g k3 = a0, W = ws^2 (1 + k2): k4 is the positive real root of k4^3 - a3 k4^2 + a2 k4 - a1 (one for any two
    pairs with positive sigma).
    """
    s = sigma_of(td, xi)
    if level_td is None or level_td == td:
        return 2 * s, 4 * s**2 / ws2 - 1, 4 * s**4 / g, 2 * s
    f = sigma_of(level_td, xi)
    a3, a2, a1, a0 = np.poly([-f + 1j * f, -f - 1j * f, -s + 1j * s, -s - 1j * s]).real[1:]
    roots = np.roots([1.0, -a3, a2, -a1])
    k4 = float(max(r.real for r in roots if abs(r.imag) <= 1e-9 * abs(r)))
    w = a1 / k4
    return a3 - k4, w / ws2 - 1, a0 / g, k4


def _stages(value, name, shape):
    """``value`` as a tuple of tuples of finite floats, each of the ``shape`` named (as many numbers as its commas + 1),
    or a one-line ValueError naming ``name``."""
    width = shape.count(",") + 1
    try:
        stages = tuple(tuple(float(x) for x in st) for st in value)
    except (TypeError, ValueError):
        stages = None
    if stages is None or any(len(st) != width or not np.all(np.isfinite(st)) for st in stages):
        raise ValueError(f"{name}: expected a sequence of {shape}, found {value!r}")
    return stages


class PIDLoops:
    """The states of the PID gyrocompass's loops over R runs (the module docstring's names) and its azimuth shot.

    The compiled control loop (:func:`baselines.gyrocompass_compiled.pid_steps`; its NumPy oracle is
    ``tests/oracles/pid_gyrocompass.py``) steps them once per control step in place: each step takes the level
    velocity errors [vE, vN] and gives the commanded rate and the velocity the damping terms remove. The east
    channel is always a third-order level loop (gains k1, k2, k3); the north channel is one too, or, from the first
    compass stage on (the compass gains c1..c4 of :func:`compass_gains`), the compass loop.

    Parameters
    ----------
    runs : int
        R.
    h : float
        Control step, s (the aligner's ``step_s`` in whole samples).
    radius : float
        Earth radius at the site, m (the ``v / R`` of the proportional terms).
    wN : float
        Horizontal earth rate OMEGA_IE cos L, rad/s.

    Attributes
    ----------
    J : ndarray, shape (R, 2)
        Integral terms [of w_cE (north channel), of w_cN (east channel)], rad/s.
    x : ndarray, shape (R,)
        Compass-loop filter state, m/s s.
    damp : ndarray, shape (R, 2)
        Velocity removed by the damping terms so far, [E, N], m/s.
    omega_c : ndarray, shape (R, 3)
        Commanded rate [w_cE, w_cN, w_cU] of the last step, rad/s, ENU.
    """

    def __init__(self, runs, h, radius, wN):
        self.h, self.radius, self.wN = h, radius, wN
        self.J = np.zeros((runs, 2))
        self.x = np.zeros(runs)
        self.damp = np.zeros((runs, 2))
        self.omega_c = np.zeros((runs, 3))

    def shot(self, loop, fit):
        """The one-shot azimuth correction (eqs. 17-18): turn the attitude of ``loop``
        (:class:`fusionbench.methods.compass.CommandLoop`) by the azimuth of ``fit``
        (:class:`fusionbench.methods.compass.AzimuthFit`) and shift the level integrators (:meth:`frame_turned`);
        returns that azimuth (R,), rad."""
        az = fit.azimuth()
        loop.sd.state.C_bn[:] = correct_azimuth(loop.sd.state.C_bn, az)
        self.frame_turned(az)
        return az

    def frame_turned(self, az):
        """The computed frame was turned by the azimuth ``az`` (R,) rad: shift the level integrators by the known
        change of the earth-rate terms (eq. 19), so the level channels stay steady."""
        self.J[:, 0] += self.wN * np.sin(az)
        self.J[:, 1] += self.wN * (1.0 - np.cos(az))


class PIDGyrocompass(AlignerBase):
    """Classical gyrocompass (method ``pid``): third-order level loops and a compass loop, staged.

    The whole control loop (strapdown, azimuth fit, level and compass loops) is compiled, all runs in one call
    (:mod:`baselines.gyrocompass_compiled`); its NumPy oracle is ``tests/oracles/pid_gyrocompass.py``.

    Parameters
    ----------
    step_s : float
        Control step of the loops, s (rounded to a whole number of IMU samples).
    xi : float
        Damping ratio of the design (sqrt(2)/2).
    fit_from_s, shot_s : float
        Start of the azimuth fit and time of the one-shot azimuth correction, s.
    level_td_s : float
        Level-loop decay time of the level stage (until the first of ``level_stages``), s.
    level_stages : sequence of (start_s, level_td_s)
        Before the first compass stage: from each start time (s) on, the level loops' decay time (s). Narrower loops
        quiet the east tilt the compass loop would read as azimuth at its closing.
    compass_stages : sequence of (start_s, level_td_s, azimuth_td_s)
        The compass stages: from each start time (s, after the shot) on, the level decay time (s; the east
        channel's level loop and the compass loop's level pair) and the azimuth decay time (s; the compass
        loop's azimuth pair). Narrower loops later filter more noise; switching keeps the loop states.
    closing_ramp_s : float
        The compass loop's azimuth gain rises linearly from zero at its closing (the first compass stage) to its
        full value this long after, s; 0: at once.
    imu : str, path or IMUSpec, optional
        The IMU (:func:`fusionbench.simulation.imu.load_spec`), used only to refuse when its gyro bias hides the earth
        rate (:func:`fusionbench.methods.claims.check_azimuth_observable`); None: not checked.
    """

    positive_options = ("step_s", "shot_s", "level_td_s")

    name = "pid"
    # tactical gyros (the matrix tests to 0.149 of the horizontal earth rate) and 80 deg since the compass loop has its
    # own level pair: with PSINS's double pair the levels ended 0.66-0.74 arcmin from the limit with a tactical IMU and
    # the azimuth 6.0 and 10.4 bounds off at 75 and 80 deg under seed 000's sway (docs/methods/pid.md)
    supports = Supports(bases=("static", "sway"), max_abs_lat_deg=80.0, max_bias_ratio=0.15)
    max_latitude_deg = MAX_LATITUDE_DEG
    description = ("classical gyrocompass: 3rd-order level loops and a compass loop with its own level pair, staged "
                   "from any heading")

    def __init__(self, step_s=0.1, xi=np.sqrt(2) / 2, fit_from_s=15.0, shot_s=70.0, level_td_s=20.0,
                 level_stages=((30.0, 60.0),),
                 compass_stages=((70.0, 60.0, 190.0), (120.0, 60.0, 500.0), (260.0, 60.0, 800.0)),
                 closing_ramp_s=30.0, imu=None):
        self.spec = None if imu is None else load_spec(imu)
        self.step_s, self.xi = float(step_s), float(xi)
        self.fit_from_s, self.shot_s, self.level_td_s = fit_from_s, shot_s, level_td_s
        self.level_stages = _stages(level_stages, "level_stages", "(start_s, level_td_s)")
        self.compass_stages = _stages(compass_stages, "compass_stages", "(start_s, level_td_s, azimuth_td_s)")
        self.closing_ramp_s = float(closing_ramp_s)  # a number >= 0: checked with every option (AlignerBase)
        self.min_duration_s = float(shot_s) + 10.0  # the azimuth is only known after the shot
        if not self.compass_stages:
            raise ValueError("compass_stages: expected at least one (start_s, level_td_s, azimuth_td_s), found none")
        starts = [st[0] for st in self.level_stages + self.compass_stages]
        if starts != sorted(starts):
            raise ValueError(f"level_stages, compass_stages: expected start times in increasing order, the level "
                             f"stages before the compass stages, found {starts}")

    def events(self, init_given):
        """Stages for the figures (:mod:`fusionbench.reports.figures`), s: the narrower level loops, the azimuth shot
        (the attitude turned by the fitted azimuth) and the closing of the compass loop (one event when they
        coincide)."""
        shot, close = float(self.shot_s), max(self.compass_stages[0][0], float(self.shot_s))
        ev = [(t, f"level loops narrowed ({td:g} s)") for t, td in self.level_stages]
        if close == shot:
            return ev + [(shot, "azimuth shot, compass loop closed")]
        return ev + [(shot, "azimuth shot"), (close, "compass loop closed")]

    def _align(self, imu, site: Site, aiding, init) -> AlignmentResult:
        """Align R recordings on a stationary or swaying base (body RFU, ENU); see the module docstring. Without
        ``init`` the loop starts levelled with yaw 0."""
        loop = CommandLoop(imu, site, init, self.step_s, per_increment_velocity(aiding, imu, self.name))
        h, R, g = loop.step_s, loop.R, site.g  # h: the step of the loops' Euler integration
        rm, rn = earth.radii(site.lat)
        radius = np.sqrt(rm * rn) + site.h
        ws2 = g / radius
        wN = earth.OMEGA_IE * np.cos(site.lat)
        fit = AzimuthFit(R, h, site.lat, g)
        fit_from = int(round(self.fit_from_s / h))
        shot_step = max(int(round(self.shot_s / h)), fit_from + 4)
        # per stage (0: levelling, then the level stages, then the compass stages): the level gains and, in the
        # compass stages, the compass gains; the compass stages start after the shot
        stage_steps = [int(round(st[0] / h)) for st in self.level_stages]
        stage_steps += [max(shot_step + 1, int(round(st[0] / h))) for st in self.compass_stages]
        close_step = stage_steps[len(self.level_stages)]
        loops = PIDLoops(R, h, radius, wN)
        hist_t = np.empty(loop.records)
        hist_t[:loop.steps] = loop.t[loop.m - 1::loop.m][:loop.steps]  # the ends of the steps
        hist_C = np.empty((R, loop.records, 3, 3))
        gains = [level_gains(td, self.xi, ws2, g) + (0.0,) * 4 for td in
                 [self.level_td_s] + [st[1] for st in self.level_stages]]
        gains += [level_gains(lv, self.xi, ws2, g) + compass_gains(az, self.xi, ws2, g, level_td=lv)
                  for _, lv, az in self.compass_stages]
        closing = (close_step, self.closing_ramp_s / h)  # the compass loop's first step; its gain's ramp, steps
        az_shot = run_compiled(loop, fit, loops, fit_from, shot_step, stage_steps, closing, gains, hist_C)
        t_last = loop.finish()  # the samples after the last control step: the result ends at the last sample
        if t_last is not None:
            hist_t[-1], hist_C[:, -1] = t_last, loop.sd.state.C_bn
        return AlignmentResult(self.name, hist_t, hist_C, {"azimuth_shot_rad": az_shot})
