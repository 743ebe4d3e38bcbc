"""The receiver simulator: the :class:`fusionbench.simulation.aiding.Aiding` a receiver beside the IMU would deliver
on a trajectory, at its own rate, from an antenna on a lever arm, late by its latency, with noise and outages.

Run k's noise depends only on the seed and k (its own :func:`fusionbench.simulation.imusim.run_seed_sequence`: the
velocity's stream is the per-increment reference's, so a receiver at the IMU's rate on its grid gives that reference's
numbers), never on the batch. Frames and units as in :mod:`fusionbench.simulation.aiding`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusionbench.simulation.aiding import Aiding
from fusionbench.simulation.aiding_geometry import displace, lever_offset, lever_velocity
from fusionbench.simulation.imusim import run_seed_sequence

#: Noise streams of a run's SeedSequence (``spawn(9)``): the velocity's is the per-increment reference's.
_VELOCITY, _POSITION = 7, 8


@dataclass(frozen=True)
class AidingSpec:
    """What a simulated receiver delivers (a scenario's ``[aiding]`` table).

    Parameters
    ----------
    rate_hz : float
        Rows per second; the rows are valid at ``j / rate_hz`` (j = 1, 2, ...) from the trajectory's start.
    velocity_sigma : (3,) float or None
        White noise of each velocity row, ENU, m/s; None: no velocity measured.
    position_sigma : (3,) float or None
        White noise of each position row, ENU, m; None: no position measured.
    lever_arm : (3,) float
        IMU to antenna, body RFU, m.
    delay : float
        Latency, s: each row is stamped this much after the instant it measures.
    outages : tuple of (float, float)
        Windows of valid time [start, end) s without rows.
    schedules : tuple of fusionbench.simulation.imu.NoiseSchedule
        Variance multiplied by ``factor`` inside each window (the ``sensors`` field is ignored); the rows' reported
        sigmas stay the nominal ones, as a receiver's would.
    """

    rate_hz: float
    velocity_sigma: tuple | None = (0.0, 0.0, 0.0)
    position_sigma: tuple | None = None
    lever_arm: tuple = (0.0, 0.0, 0.0)
    delay: float = 0.0
    outages: tuple = ()
    schedules: tuple = ()

    def __post_init__(self):
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"aiding rate: expected a positive rate in Hz, found {self.rate_hz!r}")
        if self.velocity_sigma is None and self.position_sigma is None:
            raise ValueError("aiding: expected a velocity, a position or both, found neither")

    @property
    def kinds(self):
        """What the rows measure: ``("velocity",)``, ``("position",)`` or both."""
        return tuple(k for k, s in (("velocity", self.velocity_sigma), ("position", self.position_sigma))
                     if s is not None)


def epochs(rate_hz, duration, grid=None):
    """Valid times (K,) s of a receiver at ``rate_hz`` over ``(0, duration]``; a time within 1e-9 s of one of
    ``grid`` (the IMU's increment ends) is that time exactly."""
    t = np.arange(1, int(np.floor(duration * rate_hz + 1e-9)) + 1) / rate_hz
    if grid is not None and t.size:
        grid = np.asarray(grid, dtype=float)
        k = np.clip(np.searchsorted(grid, t), 1, grid.size - 1)
        near = np.where(np.abs(grid[k - 1] - t) < np.abs(grid[k] - t), k - 1, k)
        snap = np.abs(grid[near] - t) < 1e-9
        t[snap] = grid[near[snap]]
    return t


def simulate_aiding(trajectory, spec: AidingSpec, duration=None, runs=1, seed=0, first_run=0, grid=None) -> Aiding:
    """The rows a receiver ``spec`` delivers on ``trajectory`` for runs ``first_run`` to ``first_run + runs - 1``.

    On a fixed base (a static, swaying or moored trajectory: no translation but a disturbance) the receiver reports
    the nominal motion (zero velocity, the site) and the rows are marked at rest when they measure no position;
    otherwise the antenna's true velocity (``v + C_bn (omega_nb^b x l)``) and position (``p + C_bn l``), plus noise.

    Parameters
    ----------
    trajectory : fusionbench.simulation.trajectory.Trajectory
    spec : AidingSpec
    duration : float, optional
        Record length, s (default the trajectory's).
    runs, seed, first_run : int
        The Monte Carlo runs (as :func:`fusionbench.simulation.imusim.simulate`).
    grid : ndarray, optional
        The IMU's increment ends (s): rows that fall on them are put exactly there.

    Returns
    -------
    Aiding
        ``velocity`` and/or ``position`` (runs, K, 3) at the stamps ``t = valid time + delay``.
    """
    duration = trajectory.duration if duration is None else float(duration)
    tv = epochs(spec.rate_hz, duration, grid)
    if tv.size == 0:
        raise ValueError(f"aiding: no row at {spec.rate_hz:g} Hz in {duration:g} s")
    q = np.ones_like(tv)
    for s in spec.schedules:
        q = np.where((tv >= s.start) & (tv < s.end), q * s.factor, q)
    keep = np.ones(tv.size, bool)
    for a, b in spec.outages:
        keep &= ~((tv >= a) & (tv < b))
    fixed = trajectory.translation.is_static()
    truth = trajectory.truth(tv)
    lever = np.asarray(spec.lever_arm, dtype=float)
    streams = [run_seed_sequence(seed, first_run + r).spawn(9) for r in range(runs)]
    out = {}
    if spec.velocity_sigma is not None:
        if fixed:
            v = np.zeros((tv.size, 3))
        else:
            _, w_nb = trajectory.attitude.attitude(tv)
            v = truth.v_n + lever_velocity(truth.C_bn, w_nb, lever)
        out["velocity"] = _noisy(v, spec.velocity_sigma, q, streams, _VELOCITY)
    if spec.position_sigma is not None:
        if fixed:
            truth = trajectory.truth(np.zeros_like(tv))
        p = displace(np.stack([truth.lat, truth.lon, truth.h], axis=-1), lever_offset(truth.C_bn, lever))
        n = _noisy(np.zeros_like(p), spec.position_sigma, q, streams, _POSITION)
        out["position"] = displace(np.broadcast_to(p, n.shape), n)
    sig = {name: (None if np.all(np.asarray(s) == 0) else np.broadcast_to(np.asarray(s, dtype=float), (keep.sum(), 3)))
           for name, s in (("sigma_v", spec.velocity_sigma), ("sigma_p", spec.position_sigma)) if s is not None}
    at_rest = np.ones(keep.sum(), bool) if fixed and spec.position_sigma is None else None
    return Aiding(tv[keep] + spec.delay, **{k: v[:, keep] for k, v in out.items()}, **sig, lever_arm=lever,
                  delay=spec.delay, at_rest=at_rest, source="the simulated receiver")


def _noisy(x, sigma, q, streams, stream):
    """``x`` (K, 3) plus white noise of ``sigma`` (3,) scaled by ``sqrt(q)`` (K,) for each run's ``stream``."""
    sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (3,))
    out = np.broadcast_to(x, (len(streams),) + x.shape).copy()
    if np.any(sigma > 0):
        for r, ss in enumerate(streams):
            out[r] += np.random.default_rng(ss[stream]).standard_normal(x.shape) * sigma * np.sqrt(q)[:, None]
    return out
