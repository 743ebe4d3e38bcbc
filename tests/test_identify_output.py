"""fusionbench identify's output folder: a failing write leaves the previous output as it was, a folder holding other
files is refused before any work, and a sub-folder makes a previous output another folder."""

from pathlib import Path

import pytest

from fusionbench.recording import identify
from tests.identify_helpers import ACCEL_N, GYRO_N, _record


def _snapshot(folder):
    return {p.relative_to(folder).as_posix(): None if p.is_dir() else p.read_bytes()
            for p in sorted(Path(folder).rglob("*"))}


@pytest.fixture(scope="module")
def small():
    """A short white-noise record, identified in a moment."""
    return _record(4000, {"white": (GYRO_N,) * 3}, {"white": (ACCEL_N,) * 3}, 5)


def test_a_failing_figure_leaves_the_previous_output_as_it_was(small, tmp_path, monkeypatch):
    import fusionbench.recording.allanplot

    out = tmp_path / "id"
    identify.run_identify(small, out, name="first")
    before = _snapshot(out)
    assert set(before) == {"imu_spec.toml", "identify.json", "allan.png"} and b'"first"' in before["imu_spec.toml"]

    def half_then_fail(ident, path, lines):
        Path(path).write_bytes(b"half a figure")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(fusionbench.recording.allanplot, "allan_figure", half_then_fail)
    with pytest.raises(OSError, match="No space left"):
        identify.run_identify(small, out, name="second")
    assert _snapshot(out) == before and [p.name for p in tmp_path.iterdir()] == ["id"]  # no hidden folder left
    with pytest.raises(OSError):
        identify.write_identify_report(identify.identify(small), out)
    assert _snapshot(out) == before
    monkeypatch.undo()
    identify.run_identify(small, out, name="second")  # a previous output: replaced whole
    assert b'"second"' in (out / "imu_spec.toml").read_bytes() and set(_snapshot(out)) == set(before)
    assert [p.name for p in tmp_path.iterdir()] == ["id"]


@pytest.mark.parametrize("files", [
    {"notes.txt": "mine"},
    {"identify.json": '{"record": {}, "method": {}, "spec": {}}', "notes.txt": "mine"},  # an output, and a file of mine
    {"identify.json": '{"record": {}}'},  # not what identify writes
    {"metrics.json": '{"scenario": "s", "methods": {}}'},  # a run's report
    {"consistency.json": '{"kind": "consistency"}'},  # the other command's
])
def test_a_folder_of_other_files_is_refused_before_any_work(small, tmp_path, monkeypatch, files):
    out = tmp_path / "mine"
    out.mkdir()
    for name, text in files.items():
        (out / name).write_text(text)
    before = _snapshot(out)
    monkeypatch.setattr(identify, "identify", lambda *a, **k: pytest.fail("identified before the folder was checked"))
    for write in (lambda: identify.run_identify(small, out), lambda: identify.write_identify_report(None, out)):
        with pytest.raises(ValueError) as err:
            write()
        msg = str(err.value)
        assert "\n" not in msg and msg.startswith(f"{out}: ") and "previous fusionbench identify output" in msg
        assert "found other files" in msg and "--out another folder" in msg
        assert _snapshot(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["mine"]


def test_a_sub_folder_makes_a_previous_output_another_folder(small, tmp_path):
    out = tmp_path / "id"
    identify.run_identify(small, out)
    (out / "allan.png").unlink()  # a previous output missing a file is still one
    identify.run_identify(small, out)
    (out / "data").mkdir()
    with pytest.raises(ValueError, match="found other files"):
        identify.run_identify(small, out)
    assert (out / "data").is_dir()
