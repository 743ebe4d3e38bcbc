"""The IMU simulator: the exact increments of a trajectory through the error model of :mod:`fusionbench.simulation.imu`.

Every name here is also :mod:`fusionbench.simulation.imu`'s (``imu.simulate``, ``imu.simulate_chunks``, ...), where the
error model, the presets and the noise schedules are. Run k's errors depend only on the seed and k (its own
:func:`run_seed_sequence`), never on the batch or the chunking, so that batches and workers give the same numbers.
Arrays: body frame RFU, angle increments rad, velocity increments m/s, times s.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from fusionbench.simulation.imu_model import IMUSpec, SensorErrors, VelocityReferenceSpec, _psd_factor
from fusionbench.simulation.imudata import IMUData

# stream indices inside a run's SeedSequence
_CONST, _G_WHITE, _A_WHITE, _G_GM, _A_GM, _G_RW, _A_RW, _VREF = range(8)


def run_seed_sequence(seed, run):
    """The SeedSequence of Monte Carlo run ``run`` for ``seed`` (equal to ``SeedSequence(seed).spawn(n)[run]``)."""
    return np.random.SeedSequence(seed, spawn_key=(int(run),))


class _RunState:
    """Per-run random constants and the state of the correlated processes, carried across chunks."""

    def __init__(self, spec, seed, run, vref_spec=None):
        ss = run_seed_sequence(seed, run).spawn(8)
        self.rng = [np.random.default_rng(s) for s in ss]
        c = self.rng[_CONST]
        self.sensors = {}
        for name, e in (("gyro", spec.gyro), ("accel", spec.accel)):
            bias = np.array(e.bias) + np.array(e.bias_sigma) * c.standard_normal(3)
            scale = np.array(e.scale) + np.array(e.scale_sigma) * c.standard_normal(3)
            M = np.array(e.misalignment) * (1 - np.eye(3))
            M = M + e.misalignment_sigma * c.standard_normal((3, 3)) * (1 - np.eye(3))
            gm0 = np.array(e.instability) * c.standard_normal(3)
            self.sensors[name] = {"bias": bias, "T": np.eye(3) + np.diag(scale) + M, "gm": gm0,
                                  "rw": np.zeros(3), "residual": np.zeros(3)}


def _sensor_chunk(e: SensorErrors, st, u, t, dt, schedules, sensor, rng_white, rng_gm, rng_rw):
    n = u.shape[0]
    y = u @ st["T"].T + st["bias"] * dt
    if any(e.white):
        q = _psd_factor(t, schedules, sensor)
        y += rng_white.standard_normal((n, 3)) * (np.array(e.white) * np.sqrt(dt)) * np.sqrt(q)[:, None]
    if any(e.instability):
        a = np.exp(-dt / e.tau)
        w = rng_gm.standard_normal((n, 3)) * (np.array(e.instability) * np.sqrt(1 - a * a))
        gm, _ = lfilter([1.0], [1.0, -a], w, axis=0, zi=(a * st["gm"])[None, :])
        st["gm"] = gm[-1]
        y += gm * dt
    if any(e.random_walk):
        rw = st["rw"] + np.cumsum(rng_rw.standard_normal((n, 3)) * (np.array(e.random_walk) * np.sqrt(dt)), axis=0)
        st["rw"] = rw[-1]
        y += rw * dt
    if e.quantum > 0:
        acc = np.cumsum(y, axis=0) + st["residual"]
        counts = np.floor(acc / e.quantum + 0.5)
        prev = np.vstack([np.zeros((1, 3)), counts[:-1]])
        st["residual"] = acc[-1] - counts[-1] * e.quantum
        y = (counts - prev) * e.quantum
    return y


def chunk_grid(n_total, dt, chunk_s=600.0):
    """The chunks of :func:`simulate_chunks`, as pairs (first sample k0, samples n).

    ``n_total`` samples of ``dt`` s in chunks of ``chunk_s`` s; chunk k0 ends its samples at ``(k0 + 1) dt`` to
    ``(k0 + n) dt`` (s)."""
    per_chunk = max(1, int(round(chunk_s / dt)))
    return [(k0, min(per_chunk, n_total - k0)) for k0 in range(0, n_total, per_chunk)]


def simulate_chunks(trajectory, spec: IMUSpec, dt, runs=1, seed=0, first_run=0, chunk_s=600.0, duration=None):
    """Yield IMUData chunks (kind ``"increment"``) of the trajectory seen through the IMU ``spec``.

    Parameters
    ----------
    trajectory : fusionbench.simulation.trajectory.Trajectory
        The motion; its exact increments are computed once per chunk and shared by all runs.
    spec : IMUSpec
        Sensor errors.
    dt : float
        Sample interval, s.
    runs : int
        Number of Monte Carlo runs in the batch.
    seed : int
        Monte Carlo seed.
    first_run : int
        Index of the first run (runs ``first_run .. first_run + runs - 1`` are produced), so a
        batch can be split across workers without changing any run's numbers.
    chunk_s : float
        Chunk length, s (memory is proportional to it, not to the duration).
    duration : float, optional
        Length, s (default: the trajectory's).
    """
    duration = trajectory.duration if duration is None else duration
    if not (isinstance(dt, (int, float, np.floating)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"simulate dt: expected a positive sample interval in s, found {dt!r}")
    if not (isinstance(runs, (int, np.integer)) and runs >= 1):
        raise ValueError(f"simulate runs: expected a positive whole number of runs, found {runs!r}")
    if not (isinstance(first_run, (int, np.integer)) and first_run >= 0):
        raise ValueError(f"simulate first_run: expected a non-negative whole number, found {first_run!r}")
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"simulate duration: expected a positive length in s, found {duration!r}")
    n_total = int(round(duration / dt))
    if n_total < 1:
        raise ValueError(f"simulate duration: expected at least one sample of {dt} s, found {duration} s")
    states = [_RunState(spec, seed, first_run + r) for r in range(runs)]
    for k0, n in chunk_grid(n_total, dt, chunk_s):
        t, dth, dv = trajectory.increments(k0 * dt, dt, n)
        g = np.empty((runs, n, 3))
        a = np.empty((runs, n, 3))
        for r, st in enumerate(states):
            rng = st.rng
            g[r] = _sensor_chunk(spec.gyro, st.sensors["gyro"], dth, t, dt, spec.schedules, "gyro",
                                 rng[_G_WHITE], rng[_G_GM], rng[_G_RW])
            a[r] = _sensor_chunk(spec.accel, st.sensors["accel"], dv, t, dt, spec.schedules, "accel",
                                 rng[_A_WHITE], rng[_A_GM], rng[_A_RW])
        yield IMUData(t, g, a, "increment")


def simulate(trajectory, spec: IMUSpec, dt, runs=1, seed=0, first_run=0, duration=None, output="increment"):
    """Simulate a batch of IMU recordings of ``trajectory`` in one piece.

    Parameters are those of :func:`simulate_chunks`; ``output`` is ``"increment"`` (angle and
    velocity increments over each interval, rad and m/s) or ``"rate"`` (increments divided by dt:
    mean angular rate rad/s and specific force m/s^2 over each interval, reported as samples at
    the interval ends).

    Returns
    -------
    IMUData
        Shape ``(runs, N, 3)`` arrays, body frame RFU.
    """
    if output not in ("increment", "rate"):
        raise ValueError(f"output: expected 'increment' or 'rate', found {output!r}")
    t, g, a, k0 = [], None, None, 0
    for c in simulate_chunks(trajectory, spec, dt, runs, seed, first_run, duration=duration):
        if g is None:  # the whole batch allocated once and filled chunk by chunk: one copy of the samples
            n_total = int(round((trajectory.duration if duration is None else duration) / dt))
            g, a = np.empty((runs, n_total, 3)), np.empty((runs, n_total, 3))
        g[:, k0:k0 + c.t.size], a[:, k0:k0 + c.t.size] = c.gyro, c.accel
        t.append(c.t)
        k0 += c.t.size
    t = np.concatenate(t)
    if output == "rate":
        return IMUData(t, g / dt, a / dt, "rate")
    return IMUData(t, g, a, "increment")


def simulate_vref(trajectory, vspec: VelocityReferenceSpec, t, runs=1, seed=0, first_run=0):
    """Velocity-reference samples at times ``t``: the true velocity (ENU, m/s) plus white noise.

    On a static base the true velocity is zero (up to any base disturbance, which the reference
    does not see: it reports the nominal motion only).

    Returns
    -------
    ndarray, shape (runs, N, 3)
        Reference velocity, ENU, m/s.
    """
    return vref_stream(trajectory, vspec, runs, seed, first_run)(t)


def vref_stream(trajectory, vspec: VelocityReferenceSpec, runs=1, seed=0, first_run=0):
    """The velocity reference of :func:`simulate_vref` drawn chunk by chunk.

    Returns a function of the times ``t`` (n,) s of consecutive chunks that gives their samples (runs, n, 3), ENU,
    m/s; each run's noise continues from the previous call, so the chunks joined equal :func:`simulate_vref` on
    all their times, bit for bit."""
    sigma = np.array(vspec.sigma)
    rngs = [np.random.default_rng(run_seed_sequence(seed, first_run + r).spawn(8)[_VREF]) for r in range(runs)] \
        if np.any(sigma > 0) else []

    def samples(t):
        t = np.asarray(t, dtype=float)
        v_nom, _ = trajectory.translation.mean_velocity(t)
        out = np.broadcast_to(v_nom, (runs,) + v_nom.shape).copy()
        if rngs:
            q = np.ones_like(t)
            for s in vspec.schedules:
                q = np.where((t >= s.start) & (t < s.end), q * s.factor, q)
            for r, rng in enumerate(rngs):
                out[r] += rng.standard_normal((t.size, 3)) * sigma * np.sqrt(q)[:, None]
        return out

    return samples
