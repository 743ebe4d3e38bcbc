"""The Monte Carlo's memory: how many runs a batch holds (:func:`default_batch_size`), and the C heap a unit of work
freed handed back to the system before the next (:func:`release_freed_heap`)."""

from __future__ import annotations

import sys

import joblib

from fusionbench.bench import streaming

#: Memory budget of one batch, bytes: its simulated samples and what a method holds while it aligns them.
BATCH_BYTES = 200e6
#: Bytes per sample of one run in a batch: its IMU increments, reference rows and truth as simulated (5.3 MB a run
#: of static-q-jump, 600 s at 100 Hz with a velocity row on every sample) and a method's arrays over them (up to
#: 5.8 MB more in coarse-i0's fit on the rows); benchmarks/README.md has the measurements.
SAMPLE_BYTES = 200


def default_batch_size(runs, n_samples, streamed, n_jobs):
    """Runs per batch when the caller gives none: as many as fit in :data:`BATCH_BYTES` at :data:`SAMPLE_BYTES` a
    sample (at most :data:`fusionbench.bench.streaming.STREAM_BATCH_RUNS` on a ``streamed`` record), then evened out
    over the workers (``n_jobs``, -1: the cores): the batches of about the same size, at least one a worker when there
    are runs enough, and as many a worker as the rounding to whole runs allows.

    Parameters
    ----------
    runs, n_samples : int
        Monte Carlo runs, and samples of one run's record.
    streamed : bool
        Whether the record goes to the methods as a stream of chunks.
    n_jobs : int
        Workers, as joblib counts them (-1: every core this process may run on, -2: all but one, ...; on a
        Dask cluster its workers).

    Returns
    -------
    int
        Runs per batch.
    """
    fit = int(max(1, min(runs, BATCH_BYTES // (max(n_samples, 1) * SAMPLE_BYTES))))
    if streamed:  # a streamed batch still holds its runs' whole histories
        fit = min(fit, streaming.STREAM_BATCH_RUNS)
    workers = 1 if n_jobs == 1 else joblib.effective_n_jobs(n_jobs)  # the cores allowed, not the machine's
    batches = -(-runs // fit)
    batches = min(runs, -(-batches // workers) * workers)
    return -(-runs // batches)


_trim = None  # glibc's malloc_trim once looked up (False: none here)


def _malloc_trim():
    """glibc's ``malloc_trim`` (size_t -> int), or None where there is none (macOS, musl, Windows)."""
    global _trim
    if _trim is None:
        _trim = False
        if sys.platform.startswith("linux"):
            try:
                import ctypes
                for name in ("libc.so.6", None):  # glibc by its soname; else the symbols the process has
                    try:
                        trim = ctypes.CDLL(name).malloc_trim
                    except (OSError, AttributeError, TypeError):
                        continue
                    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
                    _trim = trim
                    break
            except ImportError:  # a Python built without ctypes
                pass
    return _trim or None


def release_freed_heap() -> bool:
    """Return the C heap's free pages to the system (glibc's ``malloc_trim``); a no-op elsewhere.

    gtsam's solves allocate many small C++ objects; once freed, their pages stay in the process (about 100 MB after a
    graph's record of 600 s at 100 Hz) and the next unit's arrays come on top of them. The runner calls this after
    each method's batch.

    Returns
    -------
    bool
        Whether memory was returned (False also where there is no ``malloc_trim``).
    """
    trim = _malloc_trim()
    return bool(trim(0)) if trim is not None else False


def trims_heap() -> bool:
    """Whether :func:`release_freed_heap` can return memory here (glibc's ``malloc_trim`` found)."""
    return _malloc_trim() is not None
