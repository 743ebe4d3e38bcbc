"""The Monte Carlo's memory (fusionbench.bench.memory): the default batches' size and the freed heap handed back."""

import ctypes
import os

import joblib
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
