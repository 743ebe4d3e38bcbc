"""The twin of a user's sensor (``fusionbench run twin --imu FILE --site LAT,LON,H``) and the IMU files a scenario
or a matrix names, through the command line a user types."""

import json
import subprocess
import sys

import numpy as np
import pytest

from fusionbench.bench import scenarios
from fusionbench.methods import claims
from fusionbench.simulation import imu, units


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fusionbench", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def _spec_file(path, arw_dpsh=0.02, bias_dph=0.01):
    path.write_text(f'[imu]\npreset = "navigation"\nname = "my-rlg"\narw_dpsh = {arw_dpsh}\n'
                    f'gyro_bias_sigma_dph = {bias_dph}\n')
    return path


def test_twin_is_a_template_left_out_of_all_and_needing_both_imu_and_site(tmp_path, capsys):
    assert scenarios.get("twin").template
    r = cli("run", "twin", "--quick", "--out", tmp_path / "a")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--imu" in r.stderr and "--site" in r.stderr
    r = cli("run", "twin", "--imu", "navigation", "--quick", "--out", tmp_path / "b")
    assert r.returncode == 2 and "--site" in r.stderr
    r = cli("run", "all", "--imu", "navigation", "--quick", "--out", tmp_path / "c")
    assert r.returncode == 2 and "not those of 'all'" in r.stderr
    assert not any((tmp_path / d).exists() for d in "abc")
    from fusionbench import cli as fcli

    for bad in ("north", "91,0,0", "1,2,3,4", "nan"):  # in the process: the command line's own exit and stderr
        code = fcli.main(["run", "twin", "--imu", "navigation", "--site", bad, "--out", str(tmp_path / "d")])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and ("--site" in err or "lat_deg" in err), err
    assert not (tmp_path / "d").exists()


def test_run_all_leaves_the_template_out(monkeypatch):
    from fusionbench import cli as fcli

    seen = []
    monkeypatch.setattr(fcli.reportdir, "prepare", lambda folders: seen.extend(folders) or [])
    monkeypatch.setattr("fusionbench.bench.experiment.run_scenario",
                        lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
    assert fcli.main(["run", "all", "--quick", "--out", "/nonexistent-fusionbench-test"]) == fcli.EXIT_INTERRUPTED
    names = {p.name for p in seen}
    assert "twin" not in names and "conformance" in names and len(names) == len(scenarios.builtin_names()) - 1


def test_twin_runs_the_user_sensor_at_the_user_site(tmp_path):
    spec_path = _spec_file(tmp_path / "my_imu.toml")
    out = tmp_path / "twin"
    r = cli("run", "twin", "--imu", spec_path.name, "--site", "-41.3,174.8,20", "--methods", "coarse-i0",
            "--runs", 2, "--quick", "--out", out, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["provenance"]["overrides"] == {"imu": str(spec_path.resolve()),
                                           "site": {"lat_deg": -41.3, "lon_deg": 174.8, "height_m": 20.0}}
    conds = m["conditions"]
    assert len(conds) == 5 and all(c["lat_deg"] == -41.3 and c["imu"] == "my-rlg" for c in conds.values())
    # the azimuth limit is the east gyro bias over the horizontal earth rate: with a per-run bias only its
    # sign and size vary, so each condition's limit is at most a few sigma of bias / (W cos L)
    w_h = 7.292115e-5 * np.cos(np.radians(41.3))
    sigma_limit = 0.01 * units.DEG_PER_H / w_h / units.ARCMIN
    assert all(abs(c["limit_arcmin"]["U"]) < 5 * sigma_limit for c in conds.values())
    # the bound grows with the sensor's angle random walk: the twin really uses the file
    worse = cli("run", "twin", "--imu", _spec_file(tmp_path / "worse.toml", arw_dpsh=0.08), "--site", "-41.3,174.8,20",
                "--methods", "coarse-i0", "--runs", 1, "--quick", "--out", tmp_path / "worse")
    assert worse.returncode == 0, worse.stderr
    mw = json.loads((tmp_path / "worse" / "metrics.json").read_text())
    ratio = mw["conditions"]["static-h0"]["bound_arcmin"]["U"] / conds["static-h0"]["bound_arcmin"]["U"]
    assert 3.0 < ratio <= 4.0  # ARW x 4: the white-noise part of the azimuth bound x 4, the rest unchanged
    assert m["cells"]["coarse-i0"]["static-h0"]["status"] in ("pass", "fail")


def test_expect_auto_refuses_where_the_gyro_bias_hides_the_earth_rate(tmp_path):
    mems = scenarios.get("twin", {"imu": "mems", "site": {"lat_deg": 34.0}})
    tact = scenarios.get("twin", {"imu": "navigation", "site": {"lat_deg": 34.0}})
    ratio = claims.azimuth_bias_ratio(imu.PRESETS["mems"], np.radians(34.0))
    assert ratio > claims.MAX_BIAS_TO_EARTH_RATE
    assert {c.expect for c in mems.conditions} == {"refuse"}
    assert {c.expect for c in tact.conditions} == {"align"}


def test_a_scenario_names_an_imu_file_relative_to_itself(tmp_path):
    (tmp_path / "sensors").mkdir()
    _spec_file(tmp_path / "sensors" / "mine.toml", arw_dpsh=0.03)
    scn = tmp_path / "s.toml"
    scn.write_text('name = "s"\nduration_s = 60\nrate_hz = 10\nimu = "sensors/mine.toml"\n[site]\nlat_deg = 30\n')
    s = scenarios.load(scn)
    assert s.imu_spec.name == "my-rlg"
    assert s.imu_spec.gyro.white == pytest.approx((0.03 * units.DEG_PER_SQRT_H,) * 3)
    scn.write_text('name = "s"\nduration_s = 60\nrate_hz = 10\nimu = "sensors/none.toml"\n[site]\nlat_deg = 30\n')
    with pytest.raises(ValueError) as exc:
        scenarios.load(scn)
    msg = str(exc.value)
    assert "\n" not in msg and "s.toml: field 'imu'" in msg and "none.toml" in msg
