"""The Monte Carlo's memory: how many runs a batch holds (:func:`default_batch_size`), the C heap a unit of work
freed handed back to the system before the next (:func:`release_freed_heap`), large arrays kept out of that heap
(:func:`pin_mmap_threshold`), and the compiler's memory kept out of the workers that go on to the next scenario
(:func:`fresh_workers_after_compiling`) or to the next tasks of a long list (:func:`parallel_compiling_first`)."""

from __future__ import annotations

import contextlib
import os
import sys

import joblib

import fusionbench

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


_libc = None  # glibc once looked up (False: none here)


def _glibc():
    """glibc as a ctypes library, or None where there is none (macOS, musl, Windows, a Python without ctypes)."""
    global _libc
    if _libc is None:
        _libc = False
        if sys.platform.startswith("linux"):
            try:
                import ctypes
                for name in ("libc.so.6", None):  # glibc by its soname; else the symbols the process has
                    try:
                        lib = ctypes.CDLL(name)
                        lib.malloc_trim.argtypes, lib.malloc_trim.restype = [ctypes.c_size_t], ctypes.c_int
                        lib.mallopt.argtypes, lib.mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
                    except (OSError, AttributeError, TypeError):
                        continue
                    _libc = lib
                    break
            except ImportError:
                pass
    return _libc or None


def _malloc_trim():
    """glibc's ``malloc_trim`` (size_t -> int), or None where there is none."""
    lib = _glibc()
    return None if lib is None else lib.malloc_trim


#: Size from which glibc's malloc maps each block apart and unmaps it when it is freed, bytes
#: (:func:`pin_mmap_threshold`).
MMAP_THRESHOLD = 4 * 2**20
_M_MMAP_THRESHOLD = -3  # mallopt's parameter (malloc.h)
_pinned = False


def pin_mmap_threshold() -> bool:
    """Fix glibc's mmap threshold at :data:`MMAP_THRESHOLD` in this process (once; a no-op elsewhere).

    glibc maps a block above its threshold apart, and unmaps it when it is freed; but each such block freed raises the
    threshold to its own size, up to 32 MiB. After one batch's arrays (18 MB a run-axis array of 13 runs x 600 s at
    100 Hz) are freed, the next ones of that size come from the heap, where the pages of a freed array between live
    blocks stay in the process. A process that had run paper004-accel-0.005 peaked at 541 MB on 13 runs of
    static-q-jump, 480 MB fresh; with the threshold fixed at 4 MiB, 528 and 474 MB, in the same time
    (benchmarks/perf_heap.py). The runner calls this before each unit of work.

    Returns
    -------
    bool
        Whether the threshold is fixed (False where there is no glibc).
    """
    global _pinned
    if not _pinned:
        lib = _glibc()
        _pinned = lib is not None and lib.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
    return _pinned


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


def compiled_kernel_files() -> int:
    """The number of files in numba's cache folder for these sources (:func:`fusionbench.numba_cache_dir`); it grows
    when a process compiles a kernel that was not there.

    Returns
    -------
    int
        Files in the folder and its sub-folders (0 when there is no folder).
    """
    return sum(len(files) for _, _, files in os.walk(fusionbench.numba_cache_dir()))


def restart_workers():
    """Let joblib's local workers (loky's reusable executor) finish and exit; the next ``Parallel`` call starts new
    ones. A Dask cluster's workers are not touched."""
    from joblib.externals.loky import get_reusable_executor

    get_reusable_executor().shutdown(wait=True)


@contextlib.contextmanager
def fresh_workers_after_compiling(n_jobs):
    """Within the block, work on ``n_jobs`` workers; if numba compiled a kernel meanwhile (its cache folder grew), the
    local workers are restarted when the block ends.

    Compiling leaves LLVM's memory in the process that compiled, and a worker goes on from scenario to scenario. New
    workers load the kernels from the cache; that costs a few seconds after each scenario that compiled, and nothing
    once the cache is full. On a first `fusionbench run all --quick` with the cache empty the largest process went
    from 708 to 530 MB (benchmarks/README.md, "A first run, with numba's cache empty").

    Parameters
    ----------
    n_jobs : int
        The block's workers (joblib's count); with 1 the work runs in this process and nothing is restarted.
    """
    before = compiled_kernel_files()
    yield
    if n_jobs != 1 and compiled_kernel_files() != before:
        restart_workers()


def _local_workers():
    """Whether joblib's active backend is loky's local workers (the ones :func:`restart_workers` restarts)."""
    backend, _ = joblib.parallel.get_active_backend()
    return type(backend).__name__ == "LokyBackend"


def parallel_compiling_first(jobs, n_jobs, rehearsal=()):
    """Run ``jobs`` (joblib's delayed calls) on ``n_jobs`` workers and yield their results in order, with the tasks
    that compile kept apart from the others: on an empty cache folder the ``rehearsal`` first (smaller tasks that use
    the same kernels, their results dropped), then the first tasks, one a worker, on their own; when numba compiled a
    kernel meanwhile (its cache folder grew) the local workers are restarted before the next ones go, in the same way,
    until a group compiles nothing; the rest then run as one list.

    The first conditions of the conformance matrix compile every kernel its methods use (71 files in its cache folder,
    on an empty cache); the two workers that compiled them went on through the matrix's 28 conditions at 630 to
    680 MB, where workers that load the kernels stay near 420 MB; with the rehearsal the largest process of that first
    run went from 659 to 484 MB (benchmarks/README.md, "The conformance matrix compiles apart"): the compiling is done
    on the rehearsal's small arrays, not on the first tasks' whole batches.
    With the cache full only the first group is run apart, which costs the difference between its tasks' times. With
    one worker, or a backend other than loky's (a Dask cluster), the jobs run as one list and there is no rehearsal.

    Parameters
    ----------
    jobs : iterable of joblib.delayed calls
        The tasks, in order.
    n_jobs : int
        Workers (joblib's count; -1: the cores).
    rehearsal : iterable of joblib.delayed calls
        Tasks run first, when no kernel of these sources is in the cache folder yet, to compile the kernels on small
        data in workers that are then restarted.

    Yields
    ------
    Each task's result, in the order of ``jobs``.
    """
    jobs = list(jobs)
    width = joblib.effective_n_jobs(n_jobs)
    start = 0
    if width > 1 and _local_workers():
        rehearsal = list(rehearsal)
        if rehearsal and compiled_kernel_files() == 0:
            joblib.Parallel(n_jobs=n_jobs)(rehearsal)
            restart_workers()
        while start < len(jobs):
            before = compiled_kernel_files()
            yield from joblib.Parallel(n_jobs=n_jobs, return_as="generator")(jobs[start:start + width])
            start += width
            if compiled_kernel_files() == before:
                break
            restart_workers()
    if start < len(jobs):
        yield from joblib.Parallel(n_jobs=n_jobs, return_as="generator")(jobs[start:])
