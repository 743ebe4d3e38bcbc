"""IMUData: the container every aligner takes (the simulator of :mod:`fusionbench.simulation.imu` makes it).

Samples come in one of two kinds:

``"increment"``
    ``gyro`` holds angle increments (rad) and ``accel`` velocity increments (m/s), each the
    integral over the interval ``(t[k] - dt, t[k]]``: what a rate-integrating IMU outputs and
    what the simulator produces by default. The initial state belongs to ``t[0] - dt``.
``"rate"``
    ``gyro`` holds angular rate (rad/s) and ``accel`` specific force (m/s^2) sampled at the
    instants ``t[k]``, as in most CSV logs. :meth:`IMUData.increments` integrates them between
    consecutive samples with the trapezoid rule, so the initial state belongs to ``t[0]``.

Arrays are body frame RFU (x right, y forward, z up), shape ``(runs, samples, 3)``; a single
recording has ``runs = 1``. The times are one uniform grid (to :data:`STEP_TOLERANCE`) for every
method: samples at jittered times go through :func:`fusionbench.files.resample.uniform_imu` first (the
file readers do it), which reads them at their actual times and puts them on a uniform grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SAMPLE_KINDS = ("increment", "rate")
#: Largest angular rate any IMU measures, rad/s (about 5700 deg/s; MEMS gyros reach 2000-4000 deg/s): a sample
#: beyond it is a unit or scaling error (deg/s read as rad/s, raw counts), not motion.
MAX_RATE_RADPS = 100.0
#: Largest specific force a navigation IMU measures, m/s^2 (50 g).
MAX_SPECIFIC_FORCE_MPS2 = 50 * 9.80665
#: Relative tolerance on the uniformity of the time step (times within it are uniform; the readers resample others).
STEP_TOLERANCE = 1e-3


def time_defect(t):
    """The first defect of a time column ``t`` (N,) s: ``(k, what, detail)`` for sample k, or None when the times
    are finite, strictly increasing and uniform (to :data:`STEP_TOLERANCE`)."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        return int(bad[0]), f"non-finite value {t[bad[0]]}", ""
    step = np.diff(t)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        return k, "time not strictly increasing", f"t={t[k]:.10g} after {t[k - 1]:.10g}"
    med = float(np.median(step)) if step.size else 0.0
    bad = np.flatnonzero(np.abs(step - med) > STEP_TOLERANCE * med)
    if bad.size:
        k = int(bad[0]) + 1
        return k, "non-uniform time step", (f"step {step[k - 1]:.10g} s, median step {med:.10g} s (relative "
                                            f"tolerance {STEP_TOLERANCE:g}; fusionbench.files.resample.uniform_imu "
                                            f"puts jittered times on a uniform grid)")
    return None


def sample_defect(values, limit, unit):
    """The first defect of samples ``values`` (R, N, 3): ``((r, k, axis), text)`` for a non-finite value or one
    beyond ``limit`` (in ``unit``), or None."""
    finite = np.isfinite(values)
    if not finite.all():
        r, k, j = np.argwhere(~finite)[0]
        return (int(r), int(k), "xyz"[j]), f"non-finite value {values[r, k, j]}"
    big = np.abs(values) > limit
    if big.any():
        r, k, j = np.argwhere(big)[0]
        return (int(r), int(k), "xyz"[j]), (f"{values[r, k, j]:.6g} {unit}, beyond the {limit:g} {unit} any IMU of its "
                                            f"kind measures (a unit or scaling error?)")
    return None


@dataclass
class IMUData:
    """A batch of IMU recordings on one uniform time grid.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing with a uniform step.
    gyro : ndarray, shape (R, N, 3)
        Angle increments (rad) or angular rates (rad/s), body frame, per ``kind``.
    accel : ndarray, shape (R, N, 3)
        Velocity increments (m/s) or specific force (m/s^2), body frame, per ``kind``.
    kind : {"increment", "rate"}
    """

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    kind: str = "increment"

    def __post_init__(self):
        for name in ("t", "gyro", "accel"):
            raw = np.asarray(getattr(self, name))
            if raw.dtype.kind not in "iuf":
                raise ValueError(f"IMUData {name}: expected real numbers, found {raw.dtype} values")
            setattr(self, name, raw.astype(float, copy=False))
        if self.gyro.ndim == 2:
            self.gyro = self.gyro[None]
        if self.accel.ndim == 2:
            self.accel = self.accel[None]
        if self.kind not in SAMPLE_KINDS:
            raise ValueError(f"IMUData kind: expected one of {SAMPLE_KINDS}, found {self.kind!r}")
        if self.t.ndim != 1 or self.t.size < 2:
            raise ValueError(f"IMUData t: expected a 1-D array of at least 2 times, found shape {self.t.shape}")
        n = self.t.size
        for name, a in (("gyro", self.gyro), ("accel", self.accel)):
            if a.ndim != 3 or a.shape[1:] != (n, 3):
                raise ValueError(f"IMUData {name}: expected shape (runs, {n}, 3), found {a.shape}")
        if self.gyro.shape != self.accel.shape:
            raise ValueError(f"IMUData accel: expected shape {self.gyro.shape}, found {self.accel.shape}")
        bad = time_defect(self.t)
        if bad:
            k, what, detail = bad
            raise ValueError(f"IMUData t: {what} at sample {k}" + (f": {detail}" if detail else ""))
        scale = 1.0 if self.kind == "rate" else self.dt  # an increment's limit is the rate's over one interval
        for name, limit, unit in (("gyro", MAX_RATE_RADPS, "rad/s"), ("accel", MAX_SPECIFIC_FORCE_MPS2, "m/s^2")):
            bad = sample_defect(getattr(self, name) / scale, limit, unit)
            if bad:
                (r, k, axis), text = bad
                raise ValueError(f"IMUData {name}: {text} at run {r}, sample {k}, axis {axis}"
                                 + (" (increment over dt, as a rate)" if self.kind == "increment" else ""))

    @property
    def dt(self) -> float:
        """Sample interval, s."""
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))

    @property
    def runs(self) -> int:
        return self.gyro.shape[0]

    @property
    def samples(self) -> int:
        return self.t.size

    @property
    def t0(self) -> float:
        """Time of the initial state, s: ``t[0] - dt`` for increments, ``t[0]`` for rates."""
        return float(self.t[0] - self.dt) if self.kind == "increment" else float(self.t[0])

    @property
    def t_last(self) -> float:
        """Time of the last sample (the end of the last increment), s: where a result's history ends."""
        return float(self.t[-1])

    @property
    def duration(self) -> float:
        """Time from the initial state to the last sample, s."""
        return float(self.t[-1] - self.t0)

    def increments(self):
        """Angle and velocity increments over consecutive intervals.

        Returns
        -------
        t_end : ndarray, shape (M,)
            End of each interval, s.
        dtheta, dvel : ndarray, shape (R, M, 3)
            Increments, rad and m/s, body frame. ``M = N`` for increments, ``N - 1`` for rates.
        """
        if self.kind == "increment":
            return self.t, self.gyro, self.accel
        h = 0.5 * np.diff(self.t)[None, :, None]
        return self.t[1:], h * (self.gyro[:, 1:] + self.gyro[:, :-1]), h * (self.accel[:, 1:] + self.accel[:, :-1])

    def rates(self):
        """Angular rate (rad/s) and specific force (m/s^2), each (R, N, 3); increments over dt as averages."""
        if self.kind == "rate":
            return self.gyro, self.accel
        return self.gyro / self.dt, self.accel / self.dt

    def mean_rates(self, t_from=None, t_to=None):
        """Mean angular rate and specific force over ``[t_from, t_to]`` (s), each (R, 3)."""
        t, dth, dv = self.increments()
        lo = t[0] if t_from is None else t_from
        hi = t[-1] if t_to is None else t_to
        sel = (t >= lo) & (t <= hi)
        if not np.any(sel):
            raise ValueError(f"IMUData: no sample between {lo} s and {hi} s")
        span = np.count_nonzero(sel) * self.dt
        return dth[:, sel].sum(axis=1) / span, dv[:, sel].sum(axis=1) / span

    def select_runs(self, idx):
        """The recordings ``idx`` (an index, slice or index array) as a new IMUData."""
        idx = np.atleast_1d(np.arange(self.runs)[idx])
        return IMUData(self.t, self.gyro[idx], self.accel[idx], self.kind)
