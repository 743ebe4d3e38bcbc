"""Report folders are whole or untouched (docs/contract.md, command line): a previous report replaced whole, a
folder of other files refused, a killed run's leftovers swept and a live run's kept; by run, identify and
consistency."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fusionbench.files import reportdir
from tests.cli_failures_helpers import fake_report, fb, hidden, one_line, snapshot


# ---------------------------------------------------------------------------------------- report folders


def test_a_previous_report_is_replaced_whole(capsys, tmp_path, tiny):
    out = tmp_path / "rep"
    fake_report(out)
    status, stdout, err = fb(capsys, "run", tiny, "--jobs", 1, "--out", out)
    assert status == 0, err
    assert {"metrics.json", "report.md", "report.html", "errors.png", "azimuth.png"} <= set(snapshot(out))
    assert "stale.png" not in snapshot(out) and "old" not in json.loads((out / "metrics.json").read_text())
    assert f"tiny-cli: {out / 'report.md'}" in stdout and hidden(tmp_path) == []


def test_an_out_folder_that_is_not_a_report_is_refused_and_untouched(capsys, tmp_path, tiny):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("years of work")
    (out / "data").mkdir()
    (out / "data" / "metrics.json").write_text("{}")
    before = snapshot(out)
    status, stdout, err = fb(capsys, "run", tiny, "--jobs", 1, "--out", out)
    assert status == 2 and stdout == ""
    one_line(err, str(out), "previous fusionbench report", "--out")
    assert snapshot(out) == before
    # a previous report with a folder of the user's in it is not a report either
    fake_report(tmp_path / "rep")
    (tmp_path / "rep" / "notes").mkdir()
    assert fb(capsys, "run", tiny, "--jobs", 1, "--out", tmp_path / "rep")[0] == 2
    assert (tmp_path / "rep" / "notes").is_dir() and (tmp_path / "rep" / "stale.png").exists()


def test_an_empty_out_folder_is_used(capsys, tmp_path, tiny):
    (tmp_path / "empty").mkdir()
    assert fb(capsys, "run", tiny, "--jobs", 1, "--out", tmp_path / "empty")[0] == 0
    assert (tmp_path / "empty" / "metrics.json").is_file() and hidden(tmp_path) == []


def test_an_unwritable_out_fails_at_once_before_any_work(capsys, tmp_path, tiny, monkeypatch):
    import fusionbench.bench.experiment

    def no_work(*args, **kwargs):
        raise AssertionError("a Monte Carlo started")

    monkeypatch.setattr(fusionbench.bench.experiment, "run_scenario", no_work)
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    for out in (blocker / "rep", blocker / "deeper" / "rep", blocker):
        t0 = time.perf_counter()
        status, stdout, err = fb(capsys, "run", tiny, "--out", out)
        assert time.perf_counter() - t0 < 0.5
        assert status == 2 and stdout == ""
        one_line(err, str(out), "file")
    assert blocker.read_text() == "not a folder" and sorted(p.name for p in tmp_path.iterdir()) == ["a-file",
                                                                                                    "tiny.toml"]
    status, _, err = fb(capsys, "run", "all", "--out", blocker)
    assert status == 2
    one_line(err, "a-file")


def test_run_all_refuses_a_single_scenario_report_as_its_folder(capsys, tmp_path, monkeypatch):
    import fusionbench.bench.experiment

    monkeypatch.setattr(fusionbench.bench.experiment, "run_scenario", None)
    before = fake_report(tmp_path / "rep")
    status, _, err = fb(capsys, "run", "all", "--out", tmp_path / "rep")
    assert status == 2
    one_line(err, "one scenario's report")
    assert snapshot(tmp_path / "rep") == before


def test_a_failed_swap_puts_the_previous_report_back(tmp_path, monkeypatch):
    target = tmp_path / "rep"
    before = fake_report(target)
    real_rename = os.rename

    def rename(src, dst):
        if Path(src).name.startswith(".rep.tmp-"):
            raise KeyboardInterrupt  # between setting the old report aside and moving the new one in
        return real_rename(src, dst)

    monkeypatch.setattr(os, "rename", rename)
    with pytest.raises(KeyboardInterrupt):
        with reportdir.staged(target) as tmp:
            (tmp / "metrics.json").write_text("{}")
    assert snapshot(target) == before and hidden(tmp_path) == []


def test_is_report_knows_a_report_from_other_folders(tmp_path):
    fake_report(tmp_path / "rep")
    assert reportdir.is_report(tmp_path / "rep")
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "metrics.json").write_text('{"other": "tool"}')
    assert not reportdir.is_report(tmp_path / "x") and not reportdir.is_report(tmp_path / "absent")
    assert not reportdir.is_report(tmp_path)  # it holds folders


def test_the_current_folder_is_never_replaced(tmp_path, monkeypatch):
    fake_report(tmp_path / "rep")
    monkeypatch.chdir(tmp_path / "rep")
    with pytest.raises(ValueError, match="current folder"):
        reportdir.check_replaceable(".")


# ---------------------------------------------------------------------------------------- a killed run's leftovers

#: Assembles a report, touches argv[2] and waits to be killed.
KILLED = """import pathlib, sys, time
from fusionbench.files import reportdir
with reportdir.staged(sys.argv[1]) as tmp:
    (tmp / "metrics.json").write_text("half a report")
    pathlib.Path(sys.argv[2]).touch()
    time.sleep(60)
"""


def dead_pid():
    """The pid of a process that has ended."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def leftover(parent, name, what, pid, host=None):
    """A hidden folder as a run of process ``pid`` on ``host`` (this one) leaves it, a file in it."""
    path = parent / f".{name}.{what}-{pid}-{host or reportdir.HOST}-deadbeef"
    path.mkdir()
    (path / "metrics.json").write_text("half a report")
    return path


def test_a_killed_runs_leftover_is_removed_by_the_next_run_and_a_live_runs_kept(capsys, tmp_path, tiny):
    out = tmp_path / "rep"
    fake_report(out)
    started = tmp_path / "started"
    p = subprocess.Popen([sys.executable, "-c", KILLED, str(out), str(started)])
    try:
        deadline = time.monotonic() + 60
        while not started.exists():
            assert time.monotonic() < deadline and p.poll() is None
            time.sleep(0.05)
    finally:
        p.kill()  # SIGKILL: no clean-up runs
        p.wait()
    killed = hidden(tmp_path)
    assert len(killed) == 1 and killed[0].startswith(f".rep.tmp-{p.pid}-")
    live = leftover(tmp_path, "rep", "tmp", os.getpid())  # a run going on: this process
    elsewhere = leftover(tmp_path, "rep", "tmp", dead_pid(), "000000" if reportdir.HOST != "000000" else "ffffff")
    aside = leftover(tmp_path, "rep", "old", dead_pid())
    status, _, err = fb(capsys, "run", tiny, "--jobs", 1, "--out", out)
    assert status == 0, err
    assert sorted(hidden(tmp_path)) == sorted([live.name, elsewhere.name]) and not aside.exists()
    assert (live / "metrics.json").read_text() == "half a report"  # a live run's, untouched
    assert "old" not in json.loads((out / "metrics.json").read_text())


def test_run_all_removes_each_scenarios_leftovers_before_any_work(capsys, tmp_path, monkeypatch):
    import fusionbench.bench.experiment

    def stop(*args, **kwargs):
        raise ValueError("stopped after the folders were checked")

    monkeypatch.setattr(fusionbench.bench.experiment, "run_scenario", stop)
    out = tmp_path / "all"
    out.mkdir()
    live = [leftover(out, name, what, os.getpid()).name
            for name in ("static-34n", "sway-34n") for what in ("tmp", "old")]
    for name in ("static-34n", "sway-34n", "conformance"):
        leftover(out, name, "tmp", dead_pid())
    status, _, err = fb(capsys, "run", "all", "--out", out)
    assert status == 2
    one_line(err, "stopped after the folders were checked")
    assert sorted(hidden(out)) == sorted(live)


def test_a_report_set_aside_by_a_killed_run_is_put_back(tmp_path):
    out = tmp_path / "rep"
    before = fake_report(out)
    pid = dead_pid()
    os.rename(out, tmp_path / f".rep.old-{pid}-{reportdir.HOST}-deadbeef")  # killed between the two renames
    leftover(tmp_path, "rep", "tmp", pid)
    assert reportdir.prepare([out]) == []
    assert snapshot(out) == before and hidden(tmp_path) == []


def test_only_the_targets_own_leftovers_are_swept(tmp_path):
    pid = dead_pid()
    others = [leftover(tmp_path, name, "tmp", pid).name for name in ("rep.x", "rep2", "re")]
    legacy = leftover(tmp_path, "rep", "tmp", pid).rename(tmp_path / f".rep.tmp-{pid}-deadbeef")  # before the host
    (tmp_path / f".rep.tmp-{pid}-{reportdir.HOST}-not-hex").mkdir()  # not a name fusionbench makes
    (tmp_path / f".rep.tmp-{pid}-{reportdir.HOST}-deadbeef").write_text("a file, not a folder")
    assert reportdir.sweep(tmp_path / "rep") == [legacy]
    assert sorted(hidden(tmp_path)) == sorted(others + [f".rep.tmp-{pid}-{reportdir.HOST}-not-hex",
                                                        f".rep.tmp-{pid}-{reportdir.HOST}-deadbeef"])


@pytest.mark.parametrize("command", ["identify", "consistency"])
def test_identify_and_consistency_refuse_a_folder_of_other_files(capsys, tmp_path, recording, command, monkeypatch):
    import fusionbench.recording.consistency
    import fusionbench.recording.identify

    monkeypatch.setattr(fusionbench.recording.identify, "identify",
                        lambda *a, **k: pytest.fail("identified before the check"))
    monkeypatch.setattr(fusionbench.recording.consistency, "consistency",
                        lambda *a, **k: pytest.fail("aligned before the check"))
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("years of work")
    (out / "data").mkdir()
    before = snapshot(out)
    args = ["--lat", 34, "--methods", "coarse", "--window", 20] if command == "consistency" else []
    status, stdout, err = fb(capsys, command, recording, "--out", out, *args)
    assert status == 2 and stdout == ""
    one_line(err, f"{out}: ", f"previous fusionbench {command} output", "found other files", "--out another folder")
    assert snapshot(out) == before and hidden(tmp_path) == []
    fake_report(tmp_path / "rep")  # a run's report is not theirs to replace either
    assert fb(capsys, command, recording, "--out", tmp_path / "rep", *args)[0] == 2


def test_consistency_replaces_its_previous_output_and_sweeps_a_killed_ones(capsys, tmp_path, recording):
    out = tmp_path / "cons"
    args = ["consistency", recording, "--lat", 34, "--methods", "coarse", "--window", 20, "--out", out]
    assert fb(capsys, *args)[0] == 0
    live = leftover(tmp_path, "cons", "tmp", os.getpid())
    leftover(tmp_path, "cons", "tmp", dead_pid())
    status, stdout, err = fb(capsys, *args[:-4], "--methods", "coarse,coarse-i0", *args[-4:])
    assert status == 0, err
    assert set(json.loads((out / "consistency.json").read_text())["methods"]) == {"coarse", "coarse-i0"}
    assert sorted(p.name for p in out.iterdir()) == ["consistency.json", "consistency.png"]
    assert hidden(tmp_path) == [live.name]
