"""A user's own recording through the command line: other people's layouts (``--format``), the site from the
file, and ``consistency``; the numbers asserted are the truth of the simulated motion and the alignment limits."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from fusionbench import attitude, trajectory as tj, units
from fusionbench.imu import PRESETS, simulate
from fusionbench.imudata import IMUData
from fusionbench.imufiles import write_psins

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
