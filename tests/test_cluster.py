"""Monte Carlo on a Dask cluster (``run --scheduler`` / ``--cluster``): the numbers of ``--jobs 1``, bit for bit."""

import json
import os
import subprocess
import sys

import pytest

distributed = pytest.importorskip("distributed")


def cli(*args):
    return subprocess.run([sys.executable, "-m", "fusionbench", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


def _numbers(folder):
    """metrics.json without what may differ between two runs of the same numbers (wall times, provenance)."""
    def walk(x):
        if isinstance(x, dict):
            return {k: walk(v) for k, v in x.items() if k not in ("wall_s", "provenance")}
        return [walk(v) for v in x] if isinstance(x, list) else x
    return walk(json.loads((folder / "metrics.json").read_text()))


RUN = ("run", "static-34n", "--quick", "--runs", 5, "--methods", "coarse,kf")


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "r"
    r = cli(*RUN, "--jobs", 1, "--out", out)
    assert r.returncode == 0, r.stderr
    return _numbers(out)


def test_a_local_cluster_gives_the_numbers_of_jobs_1(tmp_path, serial):
    r = cli(*RUN, "--cluster", "local:2", "--out", tmp_path / "c")
    assert r.returncode == 0, r.stderr
    assert _numbers(tmp_path / "c") == serial


@pytest.fixture
def environ_kept():
    """This process's environment put back after the test: a LocalCluster's nannies set their workers' variables
    (MALLOC_TRIM_THRESHOLD_, OMP_NUM_THREADS, ...) in the process that starts them, and the later tests' subprocesses
    would inherit them."""
    saved = dict(os.environ)
    yield
    os.environ.clear()
    os.environ.update(saved)


def test_a_local_cluster_leaves_this_process_environment_as_it_was():
    from fusionbench.bench.cluster import connect

    before = dict(os.environ)
    with connect(cluster=1) as n_jobs:
        inside = dict(os.environ)
    assert n_jobs == 2
    assert inside != before, "dask's nannies no longer set their workers' variables here: nothing to put back"
    assert dict(os.environ) == before


def test_a_running_scheduler_with_two_workers_gives_the_numbers_of_jobs_1(tmp_path, serial, environ_kept):
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc:
        r = cli(*RUN, "--scheduler", lc.scheduler_address, "--out", tmp_path / "s")
    assert r.returncode == 0, r.stderr
    assert _numbers(tmp_path / "s") == serial


def test_bad_cluster_options_are_one_line(tmp_path):
    for args, words in ((("--cluster", "remote"), "local:N"), (("--cluster", "local:0"), "N >= 1"),
                        (("--cluster", "local", "--scheduler", "tcp://x:1"), "not allowed"),
                        (("--scheduler", "tcp://127.0.0.1:9"), "no Dask scheduler answered")):
        r = cli(*RUN, *args, "--out", tmp_path / "x")
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
        assert not (tmp_path / "x").exists()
