"""A car's drive with turns simulated by pyins (an independent simulator), written as a user's files (the contract
CSV and KF-GINS's layout, an aiding CSV at 10 Hz and at 1 Hz from an antenna 1.5 m from the IMU, 50 ms late),
aligned by every moving-base method through ``fusionbench align``, against pyins's truth."""

import json

import numpy as np
import pytest

from fusionbench.cli import main
from fusionbench.files.imufiles import write_csv
from fusionbench.simulation import attitude, units
from fusionbench.simulation.imudata import IMUData
from tests import independent

LEVER = (0.5, 1.2, 0.74)      # m, body right-front-up: 1.49 m
DELAY = 0.05                  # s
WEEK_S = 388800.0             # the KF-GINS file's clock: GPS seconds of week
SIGMA_V, SIGMA_P = 0.02, 0.3  # m/s, m
SITE = ("--lat", 45.0, "--lon", 12.0, "--height", 100.0)
MOVING = ("coarse-i0", "gtsam", "gtsam-robust", "gtsam-adaptive")


@pytest.fixture(scope="module")
def drive():
    return independent.drive(rate_hz=100.0, duration_s=300.0)


def _aiding_csv(path, d, every, velocity=True, position=False, shift=0, t0=0.0, seed=0, noise=1.0):
    """The antenna's rows at every ``every``-th sample (pyins's translation of the trajectory), with ``noise`` times
    their sigma of noise, stamped ``DELAY`` late on the IMU file's clock (``t0`` added); ``shift`` rows later than the
    truth they carry."""
    rng = np.random.default_rng(seed)
    sv, sp = noise * SIGMA_V, noise * SIGMA_P
    lla, v = d.antenna(LEVER)
    k = np.arange(every, d.t.size - every, every)  # the last row's stamp stays inside the record when read unlate
    src = np.clip(k - shift * every, 0, None)  # a row read one epoch late: the measurement of the epoch before
    cols, data = ["t"], [t0 + d.t[k] + DELAY]
    if velocity:
        cols += ["vE", "vN", "vU", "sigma_v"]
        data += [v[src, 0] + rng.normal(0, sv, k.size), v[src, 1] + rng.normal(0, sv, k.size),
                 v[src, 2] + rng.normal(0, sv, k.size), np.full(k.size, SIGMA_V)]
    if position:
        north, east = rng.normal(0, sp, (2, k.size))
        rm, rn = 6.36e6, 6.39e6  # the noise only: metres to degrees near 45 deg
        cols += ["lat", "lon", "h", "sigma_p"]
        data += [lla[src, 0] + np.degrees(north / rm), lla[src, 1] + np.degrees(east / (rn * np.cos(np.radians(45)))),
                 lla[src, 2] + rng.normal(0, sp, k.size), np.full(k.size, SIGMA_P)]
    np.savetxt(path, np.column_stack(data), delimiter=",", header=",".join(cols), comments="", fmt="%.12f")
    return path


@pytest.fixture(scope="module")
def files(drive, tmp_path_factory):
    """The IMU as the contract CSV (rates at the sample times) and as KF-GINS's layout (increments, FRD, seconds of
    week), and aiding CSVs on each file's clock."""
    d, tmp = drive, tmp_path_factory.mktemp("pyins-drive")
    csv = write_csv(tmp / "drive.csv", IMUData(d.t, d.gyro, d.accel, "rate"))
    kfg = tmp / "IMU.txt"
    np.savetxt(kfg, np.column_stack([WEEK_S + d.t[1:], d.dtheta @ independent.P, d.dvel @ independent.P]),
               fmt="%.15g")
    return {"csv": csv, "kf-gins": kfg,
            "v10": _aiding_csv(tmp / "v10.csv", d, 10),
            "exact": _aiding_csv(tmp / "exact.csv", d, 10, noise=0.0),
            "exact-late": _aiding_csv(tmp / "exact-late.csv", d, 10, shift=1, noise=0.0),
            "pv1": _aiding_csv(tmp / "pv1.csv", d, 100, position=True, t0=WEEK_S)}


def _align(capsys, imu_file, method, aiding, lever=LEVER, delay=DELAY, fmt=None):
    args = ["align", str(imu_file), *map(str, SITE), "--method", method, "--imu", "navigation", "--json"]
    args += ["--format", fmt] if fmt else []
    if aiding is not None:
        args += ["--aiding", str(aiding), "--lever-arm", ",".join(map(str, lever)), "--aiding-delay", str(delay)]
    status = main(args)
    out, err = capsys.readouterr()
    return status, (json.loads(out) if status == 0 else err)


def _error(res, d, t0=0.0):
    """Misalignment (3,) arcmin of the answer against pyins's truth at its last sample (``t_end``, on a clock that
    reads ``t0`` at the drive's start)."""
    k = int(round((res["t_end"] - t0 - d.t[0]) * 100))
    assert k == d.t.size - 1 and abs(d.t[k] + t0 - res["t_end"]) < 1e-6
    return attitude.misalignment(np.array(res["C_bn"]), d.C_bn[k]) / units.ARCMIN


def test_without_aiding_every_method_refuses_the_drive_naming_aiding(capsys, files):
    for method in ("coarse", "pid", "adrc", "kf", "coarse-i0", "gtsam"):
        status, err = _align(capsys, files["csv"], method, None)
        assert status == 2 and err.count("\n") == 1 and "the base moves" in err and "--aiding FILE" in err, err


def test_a_static_method_refuses_the_aiding_of_a_moving_base(capsys, files):
    status, err = _align(capsys, files["csv"], "pid", files["v10"])
    assert status == 2 and err.count("\n") == 1 and "pid: aiding: expected none or rows at rest" in err, err


# the azimuth bound of this drive with 10-Hz velocity rows of 0.02 m/s is about 0.4 arcmin and the level's 0.02:
# what each method reaches (measured over the conformance drives: efficiency 1-2.1) within a margin of 3
@pytest.mark.parametrize("method, level, azimuth", [("coarse-i0", 0.3, 3.0), ("eso-td", 0.3, 3.0), ("gtsam", 0.2, 2.0),
                                                    ("gtsam-robust", 0.2, 2.0), ("gtsam-adaptive", 0.2, 2.0)])
def test_velocity_rows_at_10_hz_from_a_lever_arm_align_the_contract_csv(capsys, drive, files, method, level, azimuth):
    status, res = _align(capsys, files["csv"], method, files["v10"])
    assert status == 0, res
    err = _error(res, drive)
    assert np.all(np.abs(err[:2]) < level) and abs(err[2]) < azimuth, err
    assert res["aiding"]["rows"] == 2999 and res["aiding"]["lever_arm_m"] == list(LEVER)


@pytest.mark.parametrize("method", ["coarse-i0", "eso-td", "gtsam"])
def test_position_and_velocity_at_1_hz_align_the_kf_gins_layout(capsys, drive, files, method):
    status, res = _align(capsys, files["kf-gins"], method, files["pv1"], fmt="kf-gins")
    assert status == 0, res
    err = _error(res, drive, WEEK_S)
    assert np.all(np.abs(err[:2]) < 0.3) and abs(err[2]) < 4.0, err


# exact rows: the methods land on pyins's truth (coarse-i0 0.011 arcmin of azimuth, eso-td 0.03, the graphs 1e-4), and
# reading them wrong moves the answer by far more (measured, arcmin of the largest axis: lever arm ignored 0.95 / 0.72
# / 6.7, one epoch late 0.44 / 0.79 / 4.7, the latency ignored 0.22 / 0.25 / 2.4 for coarse-i0 / eso-td / gtsam)
@pytest.mark.parametrize("method, exact", [("coarse-i0", 0.03), ("eso-td", 0.04), ("gtsam", 0.003)])
def test_exact_rows_land_on_the_truth_and_misread_rows_do_not(capsys, drive, files, method, exact):
    status, good = _align(capsys, files["csv"], method, files["exact"])
    assert status == 0, good
    assert np.abs(_error(good, drive)).max() < exact
    bad = {"lever arm ignored": _align(capsys, files["csv"], method, files["exact"], lever=(0.0, 0.0, 0.0))[1],
           "one epoch late": _align(capsys, files["csv"], method, files["exact-late"])[1],
           "latency ignored": _align(capsys, files["csv"], method, files["exact"], delay=0.0)[1]}
    for what, res in bad.items():
        assert isinstance(res, dict), res
        assert np.abs(_error(res, drive)).max() > 5 * exact, what
