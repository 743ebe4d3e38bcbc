"""The Monte Carlo's memory (fusionbench.bench.memory): the default batches' size and the freed heap handed back."""

import ctypes
import os
import subprocess
import sys
import time

import joblib
import numba
import pytest

from fusionbench.bench import memory, runner, scenarios
from fusionbench.bench.experiment import run_scenario


@pytest.mark.parametrize("runs, n, streamed, jobs, expected", [
    (50, 60000, False, 2, 13),  # static-q-jump: 16 runs fit the budget, 4 batches (2 a worker) of 13, 13, 13, 11
    (50, 60000, False, 1, 13),  # one process: the same 4 batches, evened out
    (50, 5000, False, 2, 25),  # paper001 at 10 Hz: all 50 fit; one batch a worker
    (3, 60000, False, 2, 2),  # --quick: all 3 fit; one batch a worker, of 2 and 1
    (4, 360000, True, 2, 2),  # paper004's 20-h stream at 5 Hz: 2 runs fit the budget (a stream holds 4 at most)
    (1, 60000, False, 2, 1),  # one run: one batch whatever the workers
])
def test_default_batches_fit_the_memory_budget_and_share_the_workers(runs, n, streamed, jobs, expected):
    size = memory.default_batch_size(runs, n, streamed, jobs)
    assert size == expected
    batches = -(-runs // size)
    assert size == 1 or size * n * memory.SAMPLE_BYTES <= memory.BATCH_BYTES
    assert batches % jobs == 0 or batches == runs  # each worker as many batches, unless there are fewer runs


@pytest.mark.skipif(not memory.trims_heap(),
                    reason="handing the heap back needs glibc's malloc_trim (Linux with glibc); elsewhere "
                           "release_freed_heap does nothing and has nothing to test")
def test_the_heap_a_unit_freed_goes_back_to_the_system():
    # 20 MB of small blocks from the C heap (what gtsam's factors are), freed: the pages stay in the process until
    # they are handed back, which malloc_trim reports
    libc = ctypes.CDLL("libc.so.6")
    libc.malloc.restype, libc.free.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
    blocks = [libc.malloc(1000) for _ in range(20000)]
    for b in blocks:
        libc.free(b)
    assert memory.release_freed_heap() is True


def test_the_runner_hands_the_heap_back_after_each_methods_batch(monkeypatch):
    # in this process as in a worker: once per method and batch, whatever the platform does with it
    calls = []
    monkeypatch.setattr(runner, "release_freed_heap", lambda: calls.append(1))
    run_scenario(scenarios.get("static-34n"), methods=["coarse", "coarse-i0"], runs=2, seed=1, quick=True,
                 batch_size=1, progress=False)
    assert len(calls) == 4  # 2 methods x 2 batches


def test_all_cores_means_the_cores_this_process_may_use(monkeypatch):
    # n_jobs=-1 is as many workers as joblib starts: the cores the process is allowed (affinity, a container's
    # quota), not the machine's; a machine of 64 cores whose process may use fewer gets the batches of those few
    allowed = joblib.effective_n_jobs(-1)
    expected = memory.default_batch_size(50, 60000, False, allowed)
    monkeypatch.setattr(os, "cpu_count", lambda: 64)
    assert joblib.effective_n_jobs(-1) == allowed
    assert memory.default_batch_size(50, 60000, False, -1) == expected
    assert memory.default_batch_size(50, 60000, False, 64) != expected  # what -1 meant when it read the machine's
    if allowed > 1:  # -2: all but one
        assert memory.default_batch_size(50, 60000, False, -2) == memory.default_batch_size(50, 60000, False,
                                                                                             allowed - 1)


# a block of 20 MB freed, then one of 8 MB: is the second mapped apart? glibc marks a chunk it mapped by itself with
# the IS_MMAPPED bit (2) of the size word just before the block; a chunk of the heap has it clear, wherever the heap's
# top was and whether the heap grew by the break or by a mapping of its own
_MAPPED_PROBE = """
import ctypes, sys
if sys.argv[1] == "pinned":  # glibc's own rule is probed in a process that imports nothing else
    from fusionbench.bench import memory
    assert memory.pin_mmap_threshold()
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
libc.free(libc.malloc(20 * 2**20))
block = libc.malloc(8 * 2**20)
print(ctypes.c_size_t.from_address(block - ctypes.sizeof(ctypes.c_size_t)).value & 2)
"""


@pytest.mark.skipif(not memory.trims_heap(),
                    reason="the mmap threshold is glibc's (mallopt, Linux with glibc); elsewhere pin_mmap_threshold "
                           "does nothing and has nothing to test")
@pytest.mark.parametrize("mode", ["dynamic", "pinned"])
def test_a_large_block_is_mapped_apart_even_after_a_larger_one_was_freed(mode):
    # glibc's own rule raises the threshold to the 20 MB freed, so the 8 MB come from the heap; pinned at 4 MiB they
    # are mapped apart and go back to the system when freed. Without glibc's malloc variables: any of them (dask's
    # nannies set MALLOC_TRIM_THRESHOLD_ in the process that starts a LocalCluster) fixes the threshold as well
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"}
    out = subprocess.run([sys.executable, "-c", _MAPPED_PROBE, mode], capture_output=True, text=True, check=True,
                         env=env)
    mapped = int(out.stdout) == 2
    assert memory.MMAP_THRESHOLD < 8 * 2**20
    assert mapped == (mode == "pinned")


def test_the_runner_pins_the_threshold_before_its_units(monkeypatch):
    calls = []
    monkeypatch.setattr(runner, "pin_mmap_threshold", lambda: calls.append(1))
    run_scenario(scenarios.get("static-34n"), methods=["coarse"], runs=2, seed=1, quick=True, batch_size=1,
                 progress=False)
    assert len(calls) == 2  # once a unit (each is idempotent): a worker's first unit is pinned like the main's


@numba.njit(cache=True)
def _tiny_kernel(x):
    return x + 1.0


def _pid(compile_kernel):
    """This worker's pid, after compiling (or loading) a kernel into numba's cache folder if asked; a task long enough
    that each of two workers gets some of four."""
    if compile_kernel:
        _tiny_kernel(0.0)
    time.sleep(0.3)
    return os.getpid()


def _worker_pids(compile_kernel=False):
    return set(joblib.Parallel(n_jobs=2)(joblib.delayed(_pid)(compile_kernel) for _ in range(4)))


def test_workers_that_compiled_a_kernel_are_restarted_and_the_others_kept(tmp_path, monkeypatch):
    """A block in which a worker compiled a kernel (numba's cache folder grew) ends with new workers; a block in which
    none did keeps them, and so does one of a single process."""
    memory.restart_workers()  # workers started from here on see the test's cache folder
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    try:
        with memory.fresh_workers_after_compiling(2):
            first = _worker_pids()
        assert len(first) == 2 and memory.compiled_kernel_files() == 0
        with memory.fresh_workers_after_compiling(2):
            assert _worker_pids(compile_kernel=True) == first  # the same workers did the compiling ...
        assert memory.compiled_kernel_files() > 0, "the workers should have cached the kernel in the test's folder"
        after = _worker_pids()
        assert len(after) == 2 and not after & first  # ... and have been replaced
        with memory.fresh_workers_after_compiling(2):  # loaded from the cache this time: nothing compiled
            assert _worker_pids(compile_kernel=True) == after
        assert _worker_pids() == after
        files = memory.compiled_kernel_files()
        with memory.fresh_workers_after_compiling(1):
            (tmp_path / "numba" / "new.nbi").write_bytes(b"")  # compiled in this process: no workers to restart
        assert memory.compiled_kernel_files() == files + 1 and _worker_pids() == after
    finally:
        memory.restart_workers()  # the next tests' workers use the user's cache folder again


def _task(k, compile_kernel):
    """``(k, this worker's pid)`` after compiling (or loading) the tiny kernel if asked."""
    return k, _pid(compile_kernel)


def test_tasks_that_compile_go_first_and_the_workers_are_restarted_after_them(tmp_path, monkeypatch):
    """The first tasks, one a worker, run apart; when they compiled (the cache folder grew) the next tasks run on new
    workers, and once a group compiled nothing the rest run on the same workers. The results come in order."""
    memory.restart_workers()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    try:
        jobs = [joblib.delayed(_task)(k, k < 2) for k in range(8)]  # the first two compile, the others do not
        out = list(memory.parallel_compiling_first(jobs, 2))
        assert [k for k, _ in out] == list(range(8))
        first, second, rest = ({pid for _, pid in out[a:b]} for a, b in ((0, 2), (2, 4), (4, 8)))
        assert memory.compiled_kernel_files() > 0
        assert not first & (second | rest)  # restarted after the group that compiled ...
        assert len(second | rest) <= 2  # ... not after the one that did not (two workers throughout)
        again = list(memory.parallel_compiling_first([joblib.delayed(_task)(k, True) for k in range(6)], 2))
        assert [k for k, _ in again] == list(range(6))
        assert {pid for _, pid in again} <= second | rest  # the kernel loaded from the cache: nobody restarted
        assert [k for k, _ in memory.parallel_compiling_first(jobs[:3], 1)] == [0, 1, 2]  # one process
        assert {pid for _, pid in memory.parallel_compiling_first(jobs[:3], 1)} == {os.getpid()}
    finally:
        memory.restart_workers()


def _cache_file(k, folder):
    """Task ``k``: a new file in the cache folder (what a compile leaves), then ``k``."""
    (folder / f"{k}.nbi").write_bytes(b"")
    return k


def test_tasks_on_another_backend_run_as_one_list(tmp_path, monkeypatch):
    """Under a backend other than loky's (threads here, a Dask cluster in use) nothing is restarted or grouped, even
    while the cache folder grows."""
    folder = tmp_path / "numba"
    folder.mkdir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(folder))
    monkeypatch.setattr(memory, "restart_workers", lambda: pytest.fail("restarted under another backend"))
    with joblib.parallel_config(backend="threading"):
        out = list(memory.parallel_compiling_first([joblib.delayed(_cache_file)(k, folder) for k in range(5)], 2))
    assert out == [0, 1, 2, 3, 4] and memory.compiled_kernel_files() == 5


def _rehearse(k, folder):
    """A rehearsal task: compiles the tiny kernel and leaves its pid in ``folder``."""
    (folder / f"rehearsal-{k}-{_pid(True)}").write_bytes(b"")


def test_a_rehearsal_compiles_on_an_empty_cache_in_workers_that_are_then_replaced(tmp_path, monkeypatch):
    """On an empty cache folder the rehearsal runs first and its workers are restarted; the tasks that follow load
    the kernel and run on the same new workers throughout. With kernels in the folder there is no rehearsal."""
    memory.restart_workers()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    marks = tmp_path / "marks"
    marks.mkdir()
    try:
        rehearsal = [joblib.delayed(_rehearse)(k, marks) for k in range(2)]
        out = list(memory.parallel_compiling_first([joblib.delayed(_task)(k, True) for k in range(6)], 2, rehearsal))
        assert [k for k, _ in out] == list(range(6))
        rehearsed = {int(p.name.split("-")[2]) for p in marks.iterdir()}
        assert len(list(marks.iterdir())) == 2 and memory.compiled_kernel_files() > 0
        assert not rehearsed & {pid for _, pid in out}  # restarted after the rehearsal ...
        assert len({pid for _, pid in out}) <= 2  # ... not after the first group (two workers throughout)
        list(memory.parallel_compiling_first([joblib.delayed(_task)(0, True)], 2, rehearsal))
        assert len(list(marks.iterdir())) == 2  # the kernel cached: no rehearsal
    finally:
        memory.restart_workers()
