"""How the command line fails (docs/contract.md, command line): one line ``fusionbench: error: ...`` and exit 2 for
bad input, a method that fails or a bad metrics file for check, ``fusionbench: interrupted`` and exit 130 on Ctrl-C,
quiet exit 141 when the reader of its output goes away, no traceback unless asked for. Report folders whole or
untouched: tests/test_cli_failures_reports.py.

Through the public path: ``python -m fusionbench`` in a subprocess where the process matters (signals, pipes,
the environment), ``fusionbench.cli.main`` in this process where it is only faster."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from fusionbench.bench.check import packaged_reference
from tests.cli_failures_helpers import fake_report, fb, hidden, one_line, snapshot

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


def cli(*args, env=None, **kw):
    return subprocess.run([sys.executable, "-m", "fusionbench", *map(str, args)], capture_output=True, text=True,
                          env={**os.environ, **(env or {})}, timeout=120, **kw)


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
