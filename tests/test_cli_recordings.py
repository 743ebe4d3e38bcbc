"""A user's own recording through the command line: other people's layouts (``--format``), the site from the
file, ``consistency``, and a car's drive with its receiver's rows (``--aiding``); the numbers asserted are the truth
of the simulated motion and the alignment limits."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from fusionbench.cli import main
from fusionbench.files.imufiles import write_csv, write_psins
from fusionbench.simulation import attitude, trajectory as tj, units
from fusionbench.simulation.drive import car_drive
from fusionbench.simulation.imu import PRESETS, simulate
from fusionbench.simulation.imudata import IMUData

D = np.pi / 180
LAT, LON, H = 47.0 * D, 8.0 * D, 400.0
#: fusionbench's body axes (x right, y forward, z up) as front-right-down ones: (y, x, -z)
RFU_TO_FRD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fusionbench", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def static():
    """A static record at 47 N heading 250 deg, pitch 1.5, roll -3 deg, 100 Hz, 120 s, navigation-grade fixed biases
    (no noise): the analytic coarse alignment lands on the theoretical limit."""
    tr = tj.Trajectory(LAT, LON, H, tj.EulerSway(mean=(1.5 * D, -3.0 * D, -250.0 * D)), duration=120.0)
    return tr, simulate(tr, PRESETS["navigation"].noise_free(), 0.01)


def _kfgins(path, imu, week_s=345600.0):
    """The i2Nav KF-GINS text layout: GNSS seconds of week, angle and velocity increments (rad, m/s), body FRD."""
    rows = np.column_stack([week_s + imu.t, imu.gyro[0] @ RFU_TO_FRD.T, imu.accel[0] @ RFU_TO_FRD.T])
    np.savetxt(path, rows, fmt="%.15g", delimiter=" ")
    return path


def _align(*args):
    r = cli("align", *args, "--json")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_a_kf_gins_log_and_the_same_record_as_psins_imu_align_to_the_same_attitude(tmp_path, static):
    tr, imu = static
    log = _kfgins(tmp_path / "IMU.txt", imu)
    r = cli("align", log, "--format", "kf-gins")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--lat" in r.stderr and "IMU.txt" in r.stderr
    a = _align(log, "--format", "kf-gins", "--lat", 47, "--lon", 8, "--height", 400)
    imufile = write_psins(tmp_path / "same.imu", imu, (0.0, 0.0, 0.0), lat=LAT, lon=LON, h=H)
    b = _align(imufile)  # the site from the header
    err = attitude.misalignment(np.array(a["C_bn"]), np.array(b["C_bn"]))
    assert np.abs(err).max() < 0.05 * units.ARCMIN  # the .imu rounds to 0.01 arcsec and 10 ug*s counts
    # and both sit on the truth at the last sample, within the limits of the fixed biases (level: bias / g;
    # azimuth: east gyro bias / (earth rate cos L)), as the record's own time says: t_end is the last sample
    truth = tr.truth([a["t_end"]]).C_bn[0]
    assert a["t_end"] == pytest.approx(345600.0 + 120.0, abs=1e-6)
    e = attitude.misalignment(np.array(a["C_bn"]), truth)
    lim_level = 25 * units.UG / 9.81 * np.sqrt(2)
    lim_az = 0.005 * units.DEG_PER_H * np.sqrt(2) / (7.292115e-5 * np.cos(LAT))
    assert np.abs(e[:2]).max() < 1.2 * lim_level and abs(e[2]) < 1.2 * lim_az
    # the FRD axes are really turned: read as if it were right-front-up, the same log is far off
    fmt = tmp_path / "wrong.toml"
    fmt.write_text('[layout]\ndelimiter = "whitespace"\nkind = "increment"\naxes = "RFU"\n')
    r = cli("align", log, "--format", fmt, "--lat", 47, "--json")
    assert r.returncode != 0 or np.abs(attitude.misalignment(np.array(json.loads(r.stdout)["C_bn"]), truth)).max() > D


def test_a_layout_file_in_customary_units_reads_the_same_record(tmp_path, static):
    tr, imu = static
    t = imu.t - 0.5 * imu.dt  # mean rates belong to the interval's midpoint
    rows = np.column_stack([t * 1e3, imu.gyro[0] / imu.dt / units.DEG_PER_S, imu.accel[0] / imu.dt / units.G0])
    log = tmp_path / "logger.csv"
    log.write_text("# my logger\nms;wx;wy;wz;ax;ay;az\n" + "\n".join(";".join(f"{v:.17g}" for v in r) for r in rows))
    fmt = tmp_path / "logger.toml"
    fmt.write_text('[layout]\ndelimiter = ";"\nheader = true\ntime = "ms"\ngyro = ["wx", "wy", "wz"]\n'
                   'accel = ["ax", "ay", "az"]\ntime_unit = "ms"\ngyro_unit = "deg/s"\naccel_unit = "g"\n')
    a = _align(log, "--format", fmt, "--lat", 47)
    b = _align(_kfgins(tmp_path / "IMU.txt", imu), "--format", "kf-gins", "--lat", 47)
    assert np.abs(attitude.misalignment(np.array(a["C_bn"]), np.array(b["C_bn"]))).max() < 1e-3 * units.ARCSEC
    r = cli("align", log, "--format", tmp_path / "missing.toml", "--lat", 47)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "missing.toml" in r.stderr


def test_consistency_on_a_moored_record_from_its_psins_file(tmp_path):
    """Five windows of 300 s of a moored record with a disturbance: kf's window-to-window disagreement in azimuth is
    of the size two windows at the attainable bound show."""
    tr = tj.moored(LAT, LON, H, mean=(1 * D, -2 * D, -120 * D), amplitude=(0.5 * D, 0.8 * D, 0.3 * D),
                   frequency=(0.2, 0.12, 0.05), disturbance_rms=0.02, duration=1500.0)
    data = simulate(tr, PRESETS["navigation"], 0.02, seed=3)
    path = write_psins(tmp_path / "moored.imu", data, (1 * D, -2 * D, -120 * D), lat=LAT, lon=LON, h=H)
    out = tmp_path / "cons"
    r = cli("consistency", path, "--methods", "coarse-i0,kf", "--imu", "navigation", "--out", out)
    assert r.returncode == 0, r.stderr
    assert "5 windows of 300 s" in r.stdout and "attainable bound" in r.stdout
    res = json.loads((out / "consistency.json").read_text())
    assert (out / "consistency.png").stat().st_size > 10_000
    assert res["windows"] == 5 and res["t_end_s"][-1] == pytest.approx(data.t[-1], abs=1e-9)  # ends at the last sample
    # kf's azimuth disagreement over 4 window pairs against two windows at the bound: inside the 0.1 % tails of
    # an RMS of 4 normal values (chi-square, 4 degrees of freedom)
    lo, hi = (np.sqrt(chi2.ppf(q, 4) / 4) for q in (0.001, 0.999))
    ratio = res["methods"]["kf"]["summary"]["rms_over_expected"]["U"]
    assert lo < ratio < hi, (lo, ratio, hi)
    r = cli("consistency", path, "--methods", "coarse", "--window", 800, "--out", tmp_path / "x")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "window" in r.stderr
    r = cli("consistency", path, "--methods", "nosuch", "--out", tmp_path / "y")
    assert r.returncode == 2 and "nosuch" in r.stderr and not (tmp_path / "y").exists()


def test_identify_refuses_a_record_too_short_with_one_line_and_writes_nothing(tmp_path, static):
    _, imu = static
    first5s = IMUData(imu.t[:500], imu.gyro[:, :500], imu.accel[:, :500], imu.kind)
    short = write_psins(tmp_path / "short.imu", first5s, (0.0, 0.0, 0.0), lat=LAT)
    r = cli("identify", short, "--out", tmp_path / "id")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "10 s" in r.stderr
    assert not (tmp_path / "id").exists()


# ---------------------------------------------------------------------------------------- a moving base, aided
SITE = ("--lat", 34, "--lon", 108, "--height", 400)
LEVER = (0.3, 1.2, 0.9)


def fb(capsys, *args):
    """``fusionbench ARGS`` in this process: (exit status, stdout, stderr)."""
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


def _aiding_csv(path, t, v):
    with open(path, "w") as f:
        f.write("# the receiver's velocity, on the IMU file's clock\nt,vE,vN,vU,sigma_v\n")
        f.writelines(f"{tk:.17g},{vk[0]:.17g},{vk[1]:.17g},{vk[2]:.17g},0.02\n" for tk, vk in zip(t, v))
    return path


@pytest.fixture(scope="module")
def car(tmp_path_factory):
    """A car's drive with turns (fusionbench.simulation.drive.car_drive: 0.5 m/s^2 to 10 m/s, 40-deg turns at 6 m/s)
    at 34 N, 108 E, 400 m, heading 57 deg, 300 s at 50 Hz, navigation grade (seed 1), as the contract CSV (rates at the
    interval ends); and its receiver at the IMU's rate (0.02 m/s white noise, antenna LEVER m right, front, up) as an
    aiding CSV of the rows valid at the file's samples after its first (the record's initial state)."""
    from fusionbench.simulation.aidingsim import AidingSpec, simulate_aiding  # after simulation.imu: imported first
    # meets imusim and imu importing each other half-initialised

    folder = tmp_path_factory.mktemp("car")
    tr = car_drive(34 * D, 108 * D, 400.0, heading=1.0, duration=300.0)
    imu = simulate(tr, PRESETS["navigation"], 0.02, seed=1, output="rate")
    rows = simulate_aiding(tr, AidingSpec(rate_hz=50.0, velocity_sigma=(0.02,) * 3, lever_arm=LEVER), grid=imu.t,
                           seed=1)
    keep = rows.t > imu.t[0] + 1e-9
    return tr, write_csv(folder / "car.csv", imu), _aiding_csv(folder / "car_aiding.csv", rows.t[keep],
                                                               rows.velocity[0, keep]), rows.velocity[0, keep]


def test_a_car_drive_is_refused_without_its_aiding_and_aligned_with_it(capsys, tmp_path, car):
    """coarse-i0 (the moving-base method that takes rows at the IMU's rate today) on the drive: refused without the
    rows, naming --aiding; with them, at the last sample within 0.5 arcmin of level (the accelerometer bias over g
    is 0.09 arcmin) and 5 arcmin of azimuth of the truth (seeds 0-5 of this drive: 0.1 to 3.1 arcmin)."""
    tr, imu_csv, rows_csv, v = car
    args = ["align", imu_csv, *SITE, "--method", "coarse-i0"]
    status, out, err = fb(capsys, *args)
    assert status == 2 and out == "" and err.count("\n") == 1
    assert "coarse-i0: the base moves" in err and "--aiding FILE" in err
    status, out, err = fb(capsys, *args, "--aiding", rows_csv, "--lever-arm", ",".join(map(str, LEVER)), "--json")
    assert status == 0, err
    res = json.loads(out)
    assert set(res) == {"method", "t_end", "C_bn", "pitch_deg", "roll_deg", "yaw_deg", "heading_deg", "aiding", "base",
                        "sigma_arcmin", "limit_arcmin", "limit_note", "outside_claim"}
    assert res["base"] == "moving" and res["outside_claim"] is None and res["sigma_arcmin"] is None
    assert res["limit_arcmin"] is None and "--imu" in res["limit_note"]  # no --imu given
    assert res["aiding"] == {"file": str(rows_csv), "format": "csv", "rows": 14999, "kinds": ["velocity"],
                             "lever_arm_m": list(LEVER), "delay_s": 0.0, "time_offset_s": 0.0, "t_first_s": 0.04,
                             "t_last_s": 300.0}
    assert res["t_end"] == pytest.approx(300.0, abs=1e-9)
    err_arcmin = attitude.misalignment(np.array(res["C_bn"]), tr.truth([res["t_end"]]).C_bn[0]) / units.ARCMIN
    assert np.abs(err_arcmin[:2]).max() < 0.5 and abs(err_arcmin[2]) < 5.0, err_arcmin
    # the same rows stamped 0.1 s late (the latency) on a clock 1000 s behind: the options put them back
    t = np.arange(2, 15001) * 0.02
    late = _aiding_csv(tmp_path / "late.csv", t - 1000.0 + 0.1, v)
    status, out, err = fb(capsys, *args, "--aiding", late, "--lever-arm", ",".join(map(str, LEVER)), "--json",
                          "--aiding-time-offset", 1000, "--aiding-delay", 0.1)
    assert status == 0, err
    again = json.loads(out)
    assert again["aiding"]["delay_s"] == 0.1 and again["aiding"]["time_offset_s"] == 1000.0
    assert np.abs(attitude.misalignment(np.array(again["C_bn"]), np.array(res["C_bn"]))).max() < 1e-3 * units.ARCSEC
    # without the latency the rows are valid 0.1 s late, the last one after the record: refused, naming it
    status, _, err = fb(capsys, *args, "--aiding", late, "--aiding-time-offset", 1000)
    assert status == 2 and "row 14998 is valid at 300.100000 s" in err and "after the IMU record" in err


def test_consistency_of_a_car_drive_gives_each_window_its_rows(capsys, tmp_path, car):
    _, imu_csv, rows_csv, _ = car
    args = ["consistency", imu_csv, *SITE, "--methods", "coarse-i0", "--window", 150]
    status, _, err = fb(capsys, *args, "--out", tmp_path / "none")
    assert status == 2 and err.count("\n") == 1 and "every method refused every window" in err and "--aiding" in err
    assert not (tmp_path / "none").exists()
    status, out, err = fb(capsys, *args, "--aiding", rows_csv, "--out", tmp_path / "cons")
    assert status == 0, err
    assert "aiding rows per window: 7499, 7499" in out
    res = json.loads((tmp_path / "cons" / "consistency.json").read_text())
    # window 0 holds samples 0.02 .. 150 s, its rows are valid in (0.02, 150]; window 1 the rows in (150.02, 300]
    assert res["aiding"]["rows_per_window"] == [7499, 7499] and res["aiding"]["rows"] == 14999
    assert res["methods"]["coarse-i0"]["windows_aligned"] == 2
    d = res["methods"]["coarse-i0"]["disagreement_arcmin"]
    assert abs(d["E"][0]) < 1.0 and abs(d["N"][0]) < 1.0 and abs(d["U"][0]) < 10.0, d
