"""Long records as a stream: the runner feeds a method that takes chunks one chunk at a time.

A 20-hour record held whole costs every run's samples (and a copy while it is checked): 830 MB at 8 runs of seed
004's scenarios at 5 Hz. A method that can work through consecutive pieces of its record (``damped-nav``'s
:meth:`~damping.navigator.DampedNavigator.navigate_chunks`) declares it with ``_align_chunks`` and is given a
:class:`SimulatedStream` instead: chunks of :data:`CHUNK_S` seconds of all the batch's runs, simulated as they are
read (:func:`fusionbench.simulation.imu.simulate_chunks`, :func:`fusionbench.simulation.imu.vref_stream`), so the
samples in memory are one chunk's, whatever the duration. The chunks are the very samples
:func:`fusionbench.simulation.imu.simulate` would have joined, so a streamed run gives the numbers of the whole record
bit for bit (tests/test_streaming.py).

Methods that cannot take chunks still get the whole batch. The runner keeps only a decimated history of every method
(:data:`fusionbench.bench.runner.HISTORY_POINTS`) once a batch is scored and sizes its batches by a memory budget (at
most :data:`STREAM_BATCH_RUNS` runs on a streamed record), so memory does not grow with the number of runs either way.
"""

from __future__ import annotations

from fusionbench.simulation import imu as imu_mod

#: Chunk length of a streamed record, s (the IMU simulator's own chunk, so streamed and whole records agree).
CHUNK_S = 600.0
#: Records at least this long are streamed to the methods that take chunks, s.
STREAM_MIN_S = 2 * 3600.0
#: Most runs in one batch of a streamed record: the batch's histories are held whole (``damped-nav`` over 20 h keeps
#: an attitude a second, about 10 MB a run with its errors against truth), so memory is bounded by this batch,
#: not by the number of runs.
STREAM_BATCH_RUNS = 4


def takes_chunks(method) -> bool:
    """Whether ``method`` can align a record given as consecutive chunks (it defines ``_align_chunks``)."""
    return callable(getattr(method, "_align_chunks", None)) and callable(getattr(method, "align_chunks", None))


def needs_vref(scn, traj) -> bool:
    """Whether a scenario's runs carry a velocity reference: a moving base, or a reference with noise (a fixed base
    without one is the zero-velocity assumption, as a user's ``align`` makes it)."""
    return not traj.translation.is_static() or any(scn.vref_spec.sigma)


class SimulatedStream:
    """Runs ``first_run`` to ``first_run + runs - 1`` of a scenario as consecutive ``(IMUData, vref)`` chunks.

    Iterating simulates each chunk as it is read (IMUData of kind ``"increment"``, body RFU, rad and m/s; ``vref``
    (runs, n, 3) ENU m/s at its samples, or None); it can be iterated again (the same numbers). The attributes give
    the record's time grid without holding it, as the time rule needs
    (:func:`fusionbench.methods.aligner.check_time_rule`).

    Attributes
    ----------
    runs : int
    dt : float
        Sample interval, s, as :attr:`fusionbench.simulation.imudata.IMUData.dt` of the whole record computes it.
    t0, t_last : float
        Time of the initial state and of the last sample, s.
    duration : float
        ``t_last - t0``, s.
    """

    def __init__(self, scn, traj, first_run, runs, seed, duration, chunk_s=None):
        chunk_s = CHUNK_S if chunk_s is None else chunk_s
        self._scn, self._traj, self._seed, self._chunk_s = scn, traj, seed, chunk_s
        self.first_run, self.runs, self._duration = first_run, runs, duration
        n_total = int(round(duration / scn.dt))
        grid = imu_mod.chunk_grid(n_total, scn.dt, chunk_s)
        t_first = 0.0 + 1 * scn.dt  # the first chunk's first end time, as Trajectory.increments computes it
        k0, n = grid[-1]
        self.t_last = float(k0 * scn.dt + n * scn.dt)
        self.dt = float((self.t_last - t_first) / (n_total - 1)) if n_total > 1 else float(scn.dt)
        self.t0 = t_first - self.dt
        self.duration = self.t_last - self.t0
        self.samples = n_total

    def __iter__(self):
        scn, traj = self._scn, self._traj
        vref = imu_mod.vref_stream(traj, scn.vref_spec, self.runs, self._seed, self.first_run) \
            if needs_vref(scn, traj) else None
        for ch in imu_mod.simulate_chunks(traj, scn.imu_spec, scn.dt, self.runs, self._seed, self.first_run,
                                          chunk_s=self._chunk_s, duration=self._duration):
            yield ch, None if vref is None else vref(ch.t)
