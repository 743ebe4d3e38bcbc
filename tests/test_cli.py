"""The command line end to end, through subprocesses, as a user runs it."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fusionbench.files.imufiles import write_csv
from fusionbench.simulation import attitude, trajectory as tj, units
from fusionbench.simulation.imu import PRESETS, simulate

D = np.pi / 180


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fusionbench", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_console_script_is_installed_and_reports_its_version():
    exe = shutil.which("fusionbench")
    assert exe, "pip install . puts the fusionbench console script on PATH"
    r = subprocess.run([exe, "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.startswith("fusionbench ")


def test_list_names_scenarios_and_methods():
    r = cli("list")
    assert r.returncode == 0
    for name in ("static-34n", "sway-34n", "coarse", "coarse-i0"):
        assert name in r.stdout


@pytest.mark.parametrize("heading", [200.0, -179.0])
def test_align_json_on_a_written_csv_from_any_heading(tmp_path, heading):
    lat = -30 * D
    tr = tj.Trajectory(lat, 0.0, 0.0, tj.EulerSway(mean=(2 * D, -1 * D, -heading * D)), duration=120.0)
    spec = PRESETS["navigation"].noise_free()
    data = simulate(tr, spec, 0.01)
    path = write_csv(tmp_path / "rec.csv", data)
    r = cli("align", path, "--lat", -30, "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert set(out) == {"method", "t_end", "C_bn", "pitch_deg", "roll_deg", "yaw_deg", "heading_deg", "base",
                        "sigma_arcmin", "limit_arcmin", "limit_note", "outside_claim"}
    # a static record inside the default method's claim; no --imu: no limit, and the note says why
    assert out["base"] == "static" and out["outside_claim"] is None
    assert out["limit_arcmin"] is None and "--imu" in out["limit_note"]
    C_true = tr.truth([120.0]).C_bn[0]
    err = attitude.misalignment(np.array(out["C_bn"]), C_true)
    # noise-free navigation-grade biases: level within 0.5 arcmin, azimuth within 3 arcmin of the truth
    assert np.abs(err[:2]).max() < 0.5 * units.ARCMIN and abs(err[2]) < 3 * units.ARCMIN
    assert out["heading_deg"] == pytest.approx(heading % 360, abs=0.05)
    assert out["t_end"] == pytest.approx(120.0 - 0.005, abs=1e-9)


def test_align_takes_the_site_from_a_psins_header_and_an_explicit_value_wins(tmp_path):
    fixture = Path(__file__).parent / "data" / "pyins_sway_lat30s.imu"
    truth = json.loads(fixture.with_suffix(".json").read_text())
    header = cli("align", fixture, "--method", "kf", "--json")
    assert header.returncode == 0, header.stderr
    given = cli("align", fixture, "--method", "kf", "--lat", truth["lat_deg"], "--lon", truth["lon_deg"],
                "--height", truth["height_m"], "--json")
    assert json.loads(header.stdout) == json.loads(given.stdout)
    # the header's site is the right one: the fine alignment of this perfect 2-minute record lands on the truth
    # (0.02 deg), whereas the filter told 30 N instead of the header's 30 S settles 0.17 deg away
    heading = json.loads(header.stdout)["heading_deg"]
    assert heading == pytest.approx(truth["last_heading_deg"], abs=0.05)
    other = json.loads(cli("align", fixture, "--method", "kf", "--lat", 30, "--json").stdout)["heading_deg"]
    assert abs(other - truth["last_heading_deg"]) > 0.1


def test_align_a_file_without_a_site_needs_lat(tmp_path):
    tr = tj.Trajectory(0.6, 0.0, 0.0, tj.EulerSway(), duration=20.0)
    path = write_csv(tmp_path / "nosite.csv", simulate(tr, PRESETS["navigation"].noise_free(), 0.01))
    r = cli("align", path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "nosite.csv" in r.stderr and "--lat" in r.stderr and "Traceback" not in r.stderr


def test_align_bad_file_is_one_clear_line_and_exit_2(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("t,gx,gy,gz,ax,ay\n0,0,0,0,0,0\n")
    r = cli("align", p, "--lat", 34)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "bad.csv" in r.stderr and "az" in r.stderr
    assert "Traceback" not in r.stderr


def test_align_refuses_an_impossible_latitude_and_an_unknown_method(tmp_path):
    r = cli("align", tmp_path / "x.csv", "--lat", 95)
    assert r.returncode == 2 and "latitude" in r.stderr
    r = cli("align", tmp_path / "x.csv", "--lat", 30, "--method", "magic")
    assert r.returncode == 2 and "magic" in r.stderr


def test_run_check_and_regression(tmp_path):
    out = tmp_path / "rep"
    r = cli("run", "static-34n", "--quick", "--runs", 2, "--out", out, "--methods",
            "coarse,fusionbench.methods.coarse:InertialCoarseAligner")
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["quick"] is True and m["runs"] == 2
    # a method given by its import path is labelled by its name, and the report says which path that was
    assert set(m["methods"]) == {"coarse", "coarse-i0"}
    assert "`coarse-i0` (`fusionbench.methods.coarse:InertialCoarseAligner`)" in (out / "report.md").read_text()
    assert (out / "errors.png").exists()
    _check_provenance(m["provenance"], runs=2)
    ref = tmp_path / "ref.json"
    ref.write_text(json.dumps(m))
    assert cli("check", out, "--reference", ref).returncode == 0
    m["methods"]["coarse"]["final_error_arcmin"]["U"]["rms"] /= 3
    ref.write_text(json.dumps(m))
    r = cli("check", out, "--reference", ref)
    assert r.returncode == 1 and "final phiU |rms|" in r.stdout
    # a reference of another size: one line naming both sizes, exit 2, no table
    ref.write_text(json.dumps({**m, "quick": False, "runs": 50}))
    r = cli("check", out, "--reference", ref)
    assert r.returncode == 2 and r.stdout == "" and len(r.stderr.strip().splitlines()) == 1
    assert "--quick size, 2 runs, seed 0" in r.stderr and "default size, 50 runs, seed 0" in r.stderr


def test_check_finds_the_installed_reference_of_the_runs_size_from_any_directory(tmp_path):
    out = tmp_path / "rep"
    assert cli("run", "static-34n", "--quick", "--out", out, cwd=tmp_path).returncode == 0
    r = cli("check", out, cwd=tmp_path)  # not the repository root: the references ship with the package
    assert r.returncode == 0, r.stdout + r.stderr
    assert "ok against" in r.stdout and str(Path("references", "quick", "static-34n.json")) in r.stdout
    m = json.loads((out / "metrics.json").read_text())
    (out / "metrics.json").write_text(json.dumps({**m, "scenario": "my-own"}))
    r = cli("check", out, cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "no reference for scenario 'my-own'" in r.stderr and "--reference" in r.stderr


def test_check_tolerance_admits_one_run_moving_by_one_standard_deviation():
    from fusionbench.bench.check import compare

    def metrics(rms, std=3.0):
        stat = {"mean": 0.0, "std": std, "rms": rms, "max_abs": rms}
        return {"runs": 3, "methods": {"m": {"final_error_arcmin": {ax: dict(stat) for ax in "ENU"},
                                            "settling_time_s": {"U": {"mean": 10.0, "std": 0.0}}}}}

    ref = metrics(1.0)  # allowed: 1.0 * 1.1 + max(0.05, 3.0 / 3) = 2.1 arcmin
    assert compare(metrics(2.05), ref) == []
    bad = compare(metrics(2.15), ref)
    assert [(row[1], round(row[4], 6)) for row in bad] == [(f"final phi{ax} |rms| (arcmin)", 2.1) for ax in "ENU"]
    assert compare(metrics(1.2), metrics(1.0, std=0.0))  # no spread: 10 % + 0.05 arcmin only


def test_run_with_a_bad_scenario_file_writes_nothing(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('name = "x"\nduration_s = 10\nrate_hz = 10\n[site]\nlat_deg = 91\n')
    r = cli("run", p, "--out", tmp_path / "o")
    assert r.returncode == 2 and "lat_deg" in r.stderr and str(p) in r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args,word", [(["--runs", "0"], "runs"), (["--seed", "-1"], "seed"),
                                       (["--methods", "nope"], "nope")])
def test_run_refuses_bad_sizes_and_methods(tmp_path, args, word):
    r = cli("run", "static-34n", "--quick", "--out", tmp_path / "o", *args)
    assert r.returncode == 2 and word in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "o").exists()


def _check_provenance(p, runs):
    """metrics.json says which code, when, on what, with which command and size, and how long it took."""
    from datetime import datetime, timedelta, timezone
    from importlib import metadata
    from pathlib import Path

    import fusionbench

    assert p["fusionbench"] == fusionbench.__version__
    head = subprocess.run(["git", "-C", str(Path(fusionbench.__file__).parent), "rev-parse", "HEAD"],
                          capture_output=True, text=True)
    assert p["git_commit"] == (head.stdout.strip() if head.returncode == 0 else None)
    when = datetime.fromisoformat(p["date_utc"])
    assert timedelta(0) <= datetime.now(timezone.utc) - when < timedelta(minutes=10)
    assert p["libraries"]["numpy"] == metadata.version("numpy") and p["python"] == sys.version.split()[0]
    assert p["command"].split()[1:4] == ["run", "static-34n", "--quick"]
    assert p["runs"] == runs and p["seed"] == 0 and p["quick"] is True and p["duration_s"] == 120.0
    assert 0.0 < p["wall_s"] < 300.0


@pytest.mark.parametrize("quick", [True, False])
def test_installed_references_cover_every_builtin_scenario_at_its_size(quick):
    # a reference made at another size than the scenario's own would make `check` refuse every user's run
    from fusionbench.bench import scenarios
    from fusionbench.bench.check import packaged_reference

    folder = packaged_reference(quick)
    for name in scenarios.builtin_names(templates=False):  # what run all runs (a template has no reference)
        ref = json.loads((folder / f"{name}.json").read_text())
        duration, runs = scenarios.get(name).sized(quick)
        assert (ref["scenario"], ref["quick"], ref["runs"], ref["seed"]) == (name, quick, runs, 0), name
        assert ref["duration_s"] == pytest.approx(duration), name
