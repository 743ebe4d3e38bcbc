"""What the tests of the command line's failures share: ``fusionbench ARGS`` in this process, the one-line error
they expect, and a previous report folder with what it holds."""

import json
from pathlib import Path

from fusionbench.cli import main


def fb(capsys, *args):
    """``fusionbench ARGS`` in this process: (exit status, stdout, stderr)."""
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


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
