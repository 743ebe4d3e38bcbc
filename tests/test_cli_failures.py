"""How the command line fails (docs/contract.md, command line): one line ``fusionbench: error: ...`` and exit 2 for
bad input or a method that fails, ``fusionbench: interrupted`` and exit 130 on Ctrl-C, quiet exit 141 when the
reader of its output goes away, no traceback unless asked for, and report folders that are whole or untouched.

Through the public path: ``python -m fusionbench`` in a subprocess where the process matters (signals, pipes,
the environment), ``fusionbench.cli.main`` in this process where it is only faster."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fusionbench.bench.check import packaged_reference
from fusionbench.cli import main
from fusionbench.files import reportdir

TINY = """name = "tiny-cli"
description = "30 s static at 50 Hz, 2 runs"
duration_s = 30.0
rate_hz = 50.0
runs = 2
methods = ["coarse"]
[site]
lat_deg = 34.0
[imu]
preset = "navigation"
"""

#: Methods a user might write, each failing its own way (module ``fb_user_methods`` on the path).
USER_METHODS = '''
import os
import time
from pathlib import Path

from fusionbench.methods.coarse import CoarseAligner


class InitRaises(CoarseAligner):
    name = "init-raises"

    def __init__(self, **options):
        raise RuntimeError("no constructor today")


class AlignRaises(CoarseAligner):
    name = "align-raises"

    def align(self, *args, **kwargs):
        raise ZeroDivisionError("boom in align")


class ReturnsNone(CoarseAligner):
    name = "returns-none"

    def align(self, *args, **kwargs):
        return None


NOT_A_CLASS = 42


class InterruptsTheReport(CoarseAligner):
    """Aligns like coarse; its own figure writes half a file, then Ctrl-C arrives."""
    name = "interrupts-the-report"

    def report_figures(self, folder):
        (Path(folder) / "half.png").write_bytes(b"half a figure")
        raise KeyboardInterrupt


class Sleeps(CoarseAligner):
    """Touches $FB_STARTED, then takes a minute: a long Monte Carlo to interrupt."""
    name = "sleeps"

    def align(self, *args, **kwargs):
        Path(os.environ["FB_STARTED"]).touch()
        time.sleep(60)
        return super().align(*args, **kwargs)
'''


@pytest.fixture(scope="module")
def user_path(tmp_path_factory):
    """A folder on sys.path (and PYTHONPATH for subprocesses) with the user's methods and a broken module."""
    folder = tmp_path_factory.mktemp("user")
    (folder / "fb_user_methods.py").write_text(USER_METHODS)
    (folder / "fb_user_broken.py").write_text("def align(:\n")
    sys.path.insert(0, str(folder))
    yield folder
    sys.path.remove(str(folder))


@pytest.fixture
def tiny(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(TINY)
    return p


def fb(capsys, *args):
    """``fusionbench ARGS`` in this process: (exit status, stdout, stderr)."""
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


def cli(*args, env=None, **kw):
    return subprocess.run([sys.executable, "-m", "fusionbench", *map(str, args)], capture_output=True, text=True,
                          env={**os.environ, **(env or {})}, timeout=120, **kw)


def one_line(err, *words):
    """stderr is one ``fusionbench: error:`` line holding every word, and no traceback."""
    assert "Traceback" not in err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith("fusionbench: error: "), err
    for word in words:
        assert word in err, (word, err)


def fake_report(folder, scenario="tiny-cli"):
    """A previous run's report folder, with a file the new run does not write."""
    folder.mkdir(parents=True)
    (folder / "metrics.json").write_text(json.dumps({"scenario": scenario, "methods": {}, "old": True}))
    (folder / "report.md").write_text("# the previous run\n")
    (folder / "stale.png").write_bytes(b"from the previous run")
    return snapshot(folder)


def snapshot(folder):
    """Every file and folder under ``folder`` and what the files hold."""
    return {p.relative_to(folder).as_posix(): None if p.is_dir() else p.read_bytes()
            for p in sorted(Path(folder).rglob("*"))}


def hidden(folder):
    """Temporary or set-aside folders left in ``folder`` (there should be none)."""
    return [p.name for p in Path(folder).iterdir() if p.name.startswith(".")]


# ---------------------------------------------------------------------------------------- bad values


@pytest.mark.parametrize("args,words", [
    (["--jobs", "0"], ["--jobs", "non-zero worker count", "'0'"]),
    (["--jobs", "two"], ["--jobs", "'two'"]),
    (["--runs", "0"], ["--runs", "positive number of Monte Carlo runs", "'0'"]),
    (["--runs", "1.5"], ["--runs", "'1.5'"]),
    (["--seed", "-1"], ["--seed", "non-negative integer", "'-1'"]),
    (["--seed", "x"], ["--seed", "'x'"]),
])
def test_bad_jobs_runs_and_seed_are_one_line(capsys, tmp_path, tiny, args, words):
    status, out, err = fb(capsys, "run", tiny, "--out", tmp_path / "o", *args)
    assert status == 2 and out == ""
    one_line(err, *words)
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def rest_rows(tmp_path_factory):
    """An aiding CSV of two rows at rest, inside the 60-s ``recording``."""
    path = tmp_path_factory.mktemp("aiding") / "rest.csv"
    path.write_text("t,zupt\n10,1\n20,1\n")
    return path


@pytest.mark.parametrize("command", ["align", "consistency"])
@pytest.mark.parametrize("args,words", [
    (["--lever-arm", "1,2"], ["--lever-arm", "expected three numbers X,Y,Z in m", "found '1,2'"]),
    (["--lever-arm", "a,b,c"], ["--lever-arm", "body right, front, up", "found 'a,b,c'"]),
    (["--lever-arm", "300,0,0"], ["--lever-arm", "at most 200 m long", "found '300,0,0'"]),
    (["--lever-arm", "-0.5,1,nan"], ["--lever-arm", "found '-0.5,1,nan'"]),
    (["--aiding-delay", "soon"], ["--aiding-delay", "expected a number of seconds, found 'soon'"]),
    (["--aiding-delay", "20"], ["--aiding-delay", "latency within +-10 s, found 20 s", "--aiding-time-offset"]),
    (["--aiding-time-offset", "inf"], ["--aiding-time-offset", "expected a number of seconds, found 'inf'"]),
    (["--aiding-format", "gpx"], ["--aiding-format", "invalid choice: 'gpx'"]),
])
def test_bad_aiding_options_are_one_line_and_write_nothing(capsys, tmp_path, recording, rest_rows, command, args,
                                                           words):
    out = tmp_path / "o"
    status, stdout, err = fb(capsys, command, recording, "--lat", 34, "--aiding", rest_rows, *args,
                             *(["--out", out] if command == "consistency" else []))
    assert status == 2 and stdout == ""
    one_line(err, *words)
    assert not out.exists()


@pytest.mark.parametrize("command", ["align", "consistency"])
@pytest.mark.parametrize("option,value", [("--aiding-format", "nmea"), ("--lever-arm", "-0.5,1,0"),
                                          ("--aiding-delay", "0.1"), ("--aiding-time-offset", "-5")])
def test_an_aiding_option_without_aiding_is_one_line(capsys, tmp_path, recording, command, option, value):
    out = tmp_path / "o"
    status, stdout, err = fb(capsys, command, recording, "--lat", 34, option, value,
                             *(["--out", out] if command == "consistency" else []))
    assert status == 2 and stdout == ""
    one_line(err, f"{option}: ", "give them with --aiding FILE")
    assert not out.exists()


# ---------------------------------------------------------------------------------------- a user's method


@pytest.mark.parametrize("spec,words", [
    ("fb_user_methods:InitRaises", ["RuntimeError", "no constructor today"]),
    ("fb_user_methods:AlignRaises", ["align() raised ZeroDivisionError", "boom in align"]),
    ("fb_user_methods:ReturnsNone", ["align() returned None", "expected an AlignmentResult"]),
    ("fb_user_methods:NOT_A_CLASS", ["expected a class, found an int"]),
    ("fb_user_broken:Aligner", ["SyntaxError", "fb_user_broken.py"]),
    (":", ["expected a registered name or module:Class"]),
    ("fb_user_methods:", ["expected a registered name or module:Class"]),
])
def test_align_names_a_failing_user_method_in_one_line(capsys, user_path, recording, spec, words):
    status, out, err = fb(capsys, "align", recording, "--lat", 34, "--method", spec)
    assert status == 2 and out == ""
    one_line(err, f"method {spec!r}", *words)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A 60-s stationary CSV recording at 50 Hz."""
    from fusionbench.files.imufiles import write_csv
    from fusionbench.simulation import trajectory as tj
    from fusionbench.simulation.imu import PRESETS, simulate

    tr = tj.Trajectory(0.6, 0.0, 0.0, tj.EulerSway(mean=(0.0, 0.0, 1.0)), duration=60.0)
    data = simulate(tr, PRESETS["navigation"].noise_free(), 0.02)
    return write_csv(tmp_path_factory.mktemp("rec") / "still.csv", data)


@pytest.mark.parametrize("spec,words", [
    ("fb_user_methods:InitRaises", ["RuntimeError", "no constructor today"]),
    ("fb_user_methods:AlignRaises", ["ZeroDivisionError", "boom in align"]),
    ("fb_user_methods:NOT_A_CLASS", ["expected a class, found an int"]),
    ("fb_user_broken:Aligner", ["SyntaxError"]),
])
def test_run_names_a_failing_user_method_and_writes_nothing(capsys, tmp_path, tiny, user_path, spec, words):
    status, _, err = fb(capsys, "run", tiny, "--methods", f"coarse,{spec}", "--jobs", 1, "--out", tmp_path / "o")
    assert status == 2
    one_line(err, f"method {spec!r}", *words)
    assert not (tmp_path / "o").exists() and hidden(tmp_path) == []


def test_run_names_a_method_failing_in_a_worker(tmp_path, tiny, user_path):
    r = cli("run", tiny, "--methods", "fb_user_methods:AlignRaises", "--jobs", 2, "--out", tmp_path / "o",
            env={"PYTHONPATH": os.pathsep.join([str(user_path), os.environ.get("PYTHONPATH", "")])})
    assert r.returncode == 2
    one_line(r.stderr, "method 'fb_user_methods:AlignRaises'", "ZeroDivisionError", "boom in align")
    assert not (tmp_path / "o").exists()


def test_traceback_flag_and_variable_show_the_trace(capsys, tmp_path, tiny, user_path, monkeypatch):
    args = ["run", tiny, "--methods", "fb_user_methods:InitRaises", "--out", tmp_path / "o"]
    for argv in (["--traceback", *args], [*args, "--traceback"]):
        status, _, err = fb(capsys, *argv)
        assert status == 2 and err.startswith("Traceback") and "RuntimeError: no constructor today" in err
    monkeypatch.setenv("FUSIONBENCH_TRACEBACK", "0")
    one_line(fb(capsys, *args)[2], "no constructor today")
    r = cli("align", tmp_path / "missing.csv", "--lat", 34, env={"FUSIONBENCH_TRACEBACK": "1"})
    assert r.returncode == 2 and "Traceback" in r.stderr and "IMUFileError" in r.stderr
    r = cli("align", tmp_path / "missing.csv", "--lat", 34)
    assert r.returncode == 2
    one_line(r.stderr, "missing.csv", "file not found")


# ---------------------------------------------------------------------------------------- pipes and Ctrl-C


def test_a_closed_pipe_is_quiet_and_exits_141():
    p = subprocess.Popen([sys.executable, "-m", "fusionbench", "list"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()  # `fusionbench list | head -0`: the reader is gone before the first line
    err = p.stderr.read()
    assert p.wait(timeout=60) == 141 and err == b""
    p.stderr.close()


@pytest.mark.parametrize("target", ["the command, as workers start", "the process group, workers busy"])
def test_ctrl_c_in_the_monte_carlo_stops_the_workers_and_keeps_the_old_report(tmp_path, tiny, user_path, target):
    out = tmp_path / "rep"
    before = fake_report(out)
    started = tmp_path / "started"
    env = {**os.environ, "FB_STARTED": str(started),
           "PYTHONPATH": os.pathsep.join([str(user_path), os.environ.get("PYTHONPATH", "")])}
    # SIGINT at its default in the run: a shell without job control starts background commands with SIGINT ignored
    # (nohup cmd &, a CI script launched so), and a Python that inherits an ignored SIGINT keeps ignoring it, as a
    # background job should; the run then finished normally, exit 0
    p = subprocess.Popen([sys.executable, "-m", "fusionbench", "run", tiny, "--methods", "fb_user_methods:Sleeps",
                          "--jobs", "2", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env=env, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert "Monte Carlo runs" in p.stdout.readline()
        if target.startswith("the command"):  # `kill -INT`, or a Ctrl-C while the workers are being made
            time.sleep(0.5)
            p.send_signal(signal.SIGINT)
        else:  # Ctrl-C on a terminal: the whole foreground group, workers included, inside the method
            deadline = time.monotonic() + 60
            while not started.exists():
                assert time.monotonic() < deadline and p.poll() is None, p.stderr.read()
                time.sleep(0.05)
            os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=60)  # a guard against a hang
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    # joblib's resource tracker may add its own shutdown warnings (another process, racing ours): not ours to print
    ours = [ln for ln in err.splitlines() if "resource_tracker" not in ln and "warnings.warn(" not in ln]
    assert p.returncode == 130 and ours == ["fusionbench: interrupted"] and "Traceback" not in err, err
    deadline = time.monotonic() + 10
    while True:  # the workers stopped with it
        try:
            os.killpg(p.pid, 0)
        except ProcessLookupError:
            break
        assert time.monotonic() < deadline, "a worker outlived the interrupted run"
        time.sleep(0.1)
    assert snapshot(out) == before and hidden(tmp_path) == []


@pytest.mark.parametrize("previous", [True, False])
def test_ctrl_c_while_the_report_is_written_leaves_the_old_one_or_none(capsys, tmp_path, tiny, user_path, previous):
    out = tmp_path / "rep"
    before = fake_report(out) if previous else None
    status, _, err = fb(capsys, "run", tiny, "--methods", "coarse,fb_user_methods:InterruptsTheReport",
                        "--jobs", 1, "--out", out)
    assert status == 130 and err == "fusionbench: interrupted\n"
    assert (snapshot(out) == before) if previous else not out.exists()
    assert hidden(tmp_path) == []


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


# ---------------------------------------------------------------------------------------- check


@pytest.fixture
def run_and_ref(tmp_path):
    """A run's folder and a reference, both the installed quick reference of static-34n."""
    src = packaged_reference(True) / "static-34n.json"
    (tmp_path / "run").mkdir()
    shutil.copy(src, tmp_path / "run" / "metrics.json")
    shutil.copy(src, tmp_path / "ref.json")
    return tmp_path / "run", tmp_path / "ref.json"


@pytest.mark.parametrize("which", ["run", "ref"])
@pytest.mark.parametrize("edit,words", [
    (lambda m: m["methods"]["coarse"]["final_error_arcmin"]["U"].pop("rms"),
     ["key 'methods.coarse.final_error_arcmin.U.rms'", "expected a number, found none"]),
    (lambda m: m["methods"]["coarse"]["settling_time_s"].update(U="soon"),
     ["key 'methods.coarse.settling_time_s.U'", "expected an object, found the string 'soon'"]),
    (lambda m: m["methods"]["coarse"]["final_error_arcmin"]["E"].update(std=None),
     ["key 'methods.coarse.final_error_arcmin.E.std'", "expected a number, found null"]),
    (lambda m: m.update(methods=[]), ["key 'methods'", "expected an object, found a list"]),
])
def test_check_names_the_file_and_the_first_bad_key(capsys, run_and_ref, which, edit, words):
    run, ref = run_and_ref
    path = run / "metrics.json" if which == "run" else ref
    m = json.loads(path.read_text())
    edit(m)
    path.write_text(json.dumps(m))
    status, out, err = fb(capsys, "check", run, "--reference", ref)
    assert status == 2 and out == ""
    one_line(err, f"{path}: ", *words)


def test_check_refuses_a_metrics_file_that_is_not_an_object(capsys, run_and_ref):
    run, ref = run_and_ref
    ref.write_text("[1, 2]")
    status, _, err = fb(capsys, "check", run, "--reference", ref)
    assert status == 2
    one_line(err, str(ref), "expected a JSON object, found a list")
    assert fb(capsys, "check", run, "--reference", run / "metrics.json")[0] == 0  # the unedited pair passes


def test_every_installed_reference_has_the_shape_check_reads():
    from fusionbench.bench.check import load_metrics

    for path in sorted(packaged_reference(True).parent.glob("*/*.json")):
        load_metrics(path, "reference metrics")


def test_check_ignores_a_folder_set_aside(tmp_path, run_and_ref):
    from fusionbench.bench.check import metrics_files

    run, _ = run_and_ref
    (tmp_path / "all").mkdir()
    shutil.copytree(run, tmp_path / "all" / "static-34n")
    shutil.copytree(run, tmp_path / "all" / ".static-34n.old-1-deadbeef")
    assert metrics_files(tmp_path / "all") == [tmp_path / "all" / "static-34n" / "metrics.json"]
