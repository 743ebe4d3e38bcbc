"""Tests of fusionbench.files.imufiles with CSV and NPZ files: writer/reader round trips, the CSV fixtures, bad files and
paths, atomic writes (of all three formats). The PSINS .imu format is tested in test_imufiles_psins.py."""

import os

import numpy as np
import pytest

import fusionbench.files.imufiles as fio
from fusionbench.files.imufiles import IMUFileError, read_imu, write_csv, write_npz, write_psins
from tests.imufiles_helpers import DATA, _assert_error, _incr_imu, _rate_imu

HEADER = "t,gx,gy,gz,ax,ay,az"


def _csv(tmp_path, rows, name="data.csv", header=HEADER):
    p = tmp_path / name
    p.write_text(header + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    return p


def _good_rows(n=10, dt=0.1):
    return [[k * dt, 1e-5, 2e-5, 3e-5, 0.1, 0.2, 9.8] for k in range(n)]


# ---------------------------------------------------------------- round trips

def test_csv_round_trip_rate_exact(tmp_path):
    imu = _rate_imu(runs=2)
    p = write_csv(tmp_path / "r.csv", imu, run=1)
    back, meta = read_imu(p)
    assert back.kind == "rate" and back.runs == 1 and meta["path"] == str(p)
    np.testing.assert_array_equal(back.t, imu.t)
    np.testing.assert_array_equal(back.gyro[0], imu.gyro[1])
    np.testing.assert_array_equal(back.accel[0], imu.accel[1])


def test_npz_round_trip_rate_exact(tmp_path):
    imu = _rate_imu()
    p = write_npz(tmp_path / "r.npz", imu)
    back, meta = read_imu(p)
    assert back.kind == "rate" and meta["format"] == "npz"
    np.testing.assert_array_equal(back.t, imu.t)
    np.testing.assert_array_equal(back.gyro, imu.gyro)
    np.testing.assert_array_equal(back.accel, imu.accel)


@pytest.mark.parametrize("ext,writer", [(".csv", write_csv), (".npz", write_npz)])
def test_increments_written_as_average_rates(tmp_path, ext, writer):
    imu = _incr_imu()
    back, _ = read_imu(writer(tmp_path / ("i" + ext), imu, run=1))
    np.testing.assert_array_equal(back.t, imu.t - 0.5 * imu.dt)
    np.testing.assert_array_equal(back.gyro[0], imu.gyro[1] / imu.dt)
    np.testing.assert_array_equal(back.accel[0], imu.accel[1] / imu.dt)


# ---------------------------------------------------------------- fixtures

@pytest.mark.parametrize("name", ["pyins_sway_lat30s.csv", "pyins_static_40n_perfect.csv",
                                  "pyins_static_40n_noisy.csv"])
def test_csv_fixtures_read(name):
    imu, meta = read_imu(DATA / name)
    assert imu.kind == "rate" and imu.runs == 1 and imu.samples > 100
    assert 9.7 < np.linalg.norm(imu.accel[0, 0]) < 9.9


def test_csv_columns_any_order_extra_columns_and_comments(tmp_path):
    p = tmp_path / "o.csv"
    p.write_text("# a comment\n\naz,label,t,ay,ax,gz,gy,gx\n"
                 "9.8,x,0.0,0.2,0.1,3,2,1\n# mid comment\n9.9,y,0.5,0.3,0.2,6,5,4\n")
    imu, _ = read_imu(p)
    np.testing.assert_array_equal(imu.t, [0.0, 0.5])
    np.testing.assert_array_equal(imu.gyro[0], [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(imu.accel[0], [[0.1, 0.2, 9.8], [0.2, 0.3, 9.9]])


# ---------------------------------------------------------------- bad files

def test_missing_column(tmp_path):
    p = _csv(tmp_path, [r[:3] + r[4:] for r in _good_rows()], header="t,gx,gy,ax,ay,az")
    msg = _assert_error(p, ["missing"])
    assert "'gz'" in msg and HEADER in msg


@pytest.mark.parametrize("bad,word", [("nan", "nan"), ("inf", "inf"), ("-inf", "inf")])
def test_non_finite_cell(tmp_path, bad, word):
    rows = _good_rows()
    rows[4][2] = bad
    msg = _assert_error(_csv(tmp_path, rows), [word])
    assert "row 4" in msg and "'gy'" in msg and "non-finite" in msg


def test_non_numeric_cell(tmp_path):
    rows = _good_rows()
    rows[6][5] = "abc"
    msg = _assert_error(_csv(tmp_path, rows), ["non-numeric"])
    assert "'abc'" in msg and "row 6" in msg and "line 8" in msg and "'ay'" in msg


def test_wrong_field_count(tmp_path):
    rows = _good_rows()
    rows[3] = rows[3][:5]
    _assert_error(_csv(tmp_path, rows), ["fields"])


def test_non_increasing_time(tmp_path):
    rows = _good_rows()
    rows[5][0] = rows[4][0]
    msg = _assert_error(_csv(tmp_path, rows), ["not strictly increasing"])
    assert "row 5" in msg


def test_decreasing_time(tmp_path):
    rows = _good_rows()
    rows[5][0], rows[6][0] = rows[6][0], rows[5][0]
    _assert_error(_csv(tmp_path, rows), ["not strictly increasing"])


@pytest.mark.parametrize("shift, words", [
    (0.10, ["gap in time at row 12 (line 14)", "step 0.2 s", "about 1 sample(s) missing"]),
    (0.20, ["gap in time at row 12 (line 14)", "step 0.3 s", "about 2 sample(s) missing"]),
    (-0.06, ["time step too short at row 12 (line 14)", "step 0.04 s", "an extra sample"]),
])
def test_a_gap_or_a_short_step_is_refused_naming_its_row(tmp_path, shift, words):
    rows = _good_rows(20)
    for r in rows[12:]:
        r[0] += shift
    msg = _assert_error(_csv(tmp_path, rows), [words[0]])
    assert all(w in msg for w in words) and "between 0.5 and 1.5 nominal steps" in msg, msg


def test_a_step_of_1_4_nominal_steps_is_jitter_read_at_its_actual_times(tmp_path):
    """Rows 12 on 0.04 s late: one step of 0.14 s in steps of 0.1 s. The rates (constant 1e-5, 2e-5, 3e-5 rad/s)
    integrate to the same increments on the uniform grid of the same span, 1.94 s in 19 intervals."""
    rows = _good_rows(20)
    for r in rows[12:]:
        r[0] += 0.04
    imu, meta = read_imu(_csv(tmp_path, rows))
    assert meta["resampled"] and imu.kind == "increment" and imu.samples == 19 and imu.t0 == pytest.approx(0.0)
    np.testing.assert_allclose(imu.t, 1.94 / 19 * np.arange(1, 20), rtol=0, atol=1e-14)
    np.testing.assert_allclose(imu.gyro[0], np.tile([1e-5, 2e-5, 3e-5], (19, 1)) * 1.94 / 19, rtol=1e-12)
    np.testing.assert_allclose(imu.accel[0].sum(axis=0), np.array([0.1, 0.2, 9.8]) * 1.94, rtol=1e-14)


def test_small_jitter_accepted(tmp_path):
    rows = _good_rows(20)
    rows[7][0] += 0.5e-4  # 5e-4 of the 0.1 s step, inside the 1e-3 tolerance: read as it is
    imu, meta = read_imu(_csv(tmp_path, rows))
    assert imu.samples == 20 and imu.kind == "rate" and not meta["resampled"] and meta["resampling_c_s2"] == 0.0
    assert imu.t[7] == rows[7][0] and meta["jitter_s"] == pytest.approx(0.5e-4)


def test_too_short(tmp_path):
    msg = _assert_error(_csv(tmp_path, _good_rows(5)), ["too short"], min_samples=50)
    assert "5 samples" in msg and "at least 50" in msg
    _assert_error(_csv(tmp_path, _good_rows(1), name="one.csv"), ["too short"])
    _assert_error(_csv(tmp_path, [], name="empty.csv"), ["too short"])


def test_no_header(tmp_path):
    p = tmp_path / "blank.csv"
    p.write_text("# only a comment\n")
    _assert_error(p, ["header"])


def test_missing_file(tmp_path):
    for name in ("nope.csv", "nope.npz", "nope.imu"):
        _assert_error(tmp_path / name, ["not found"])


def test_directory_instead_of_file(tmp_path):
    d = tmp_path / "dir.csv"
    d.mkdir()
    _assert_error(d, ["directory"])


def test_unknown_extension(tmp_path):
    p = tmp_path / "data.txt"
    p.write_text(HEADER + "\n")
    msg = _assert_error(p, ["extension"])
    assert "'.txt'" in msg and ".csv" in msg and ".npz" in msg and ".imu" in msg


def _npz(tmp_path, name="x.npz", n=10, **override):
    arrays = {"t": 0.1 * np.arange(n), "gyro": np.zeros((n, 3)), "accel": np.full((n, 3), 9.8)}
    arrays.update(override)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    p = tmp_path / name
    with open(p, "wb") as f:
        np.savez(f, **arrays)
    return p


def test_npz_wrong_shape(tmp_path):
    msg = _assert_error(_npz(tmp_path, gyro=np.zeros((10, 2))), ["shape"])
    assert "'gyro'" in msg and "(10, 2)" in msg and "(10, 3)" in msg
    _assert_error(_npz(tmp_path, "t2.npz", t=np.zeros((10, 1))), ["shape"])
    _assert_error(_npz(tmp_path, "a3.npz", accel=np.zeros((9, 3))), ["shape"])


def test_npz_missing_array_nan_and_bad_archive(tmp_path):
    assert "'accel'" in _assert_error(_npz(tmp_path, accel=None), ["missing"])
    g = np.zeros((10, 3))
    g[3, 1] = np.nan
    msg = _assert_error(_npz(tmp_path, "n.npz", gyro=g), ["nan"])
    assert "index 3" in msg and "'gy'" in msg
    t = 0.1 * np.arange(10)
    t[7] = t[6]
    msg = _assert_error(_npz(tmp_path, "t.npz", t=t), ["not strictly increasing"])
    assert "index 7" in msg and "a duplicate time" in msg
    t[7] = t[6] - 0.01
    assert "a reversal" in _assert_error(_npz(tmp_path, "r.npz", t=t), ["not strictly increasing at index 7"])
    t = 0.1 * np.arange(10) + 0.01 * np.sin(np.arange(10))  # jitter of up to a tenth of the step
    imu, meta = read_imu(_npz(tmp_path, "j.npz", t=t))
    assert meta["resampled"] and imu.kind == "increment" and imu.samples == 9
    np.testing.assert_allclose(imu.accel[0], 9.8 * (t[-1] - t[0]) / 9, rtol=1e-12)
    _assert_error(_npz(tmp_path, "s.npz", t=np.array(["a"] * 10)), ["dtype"])
    bad = tmp_path / "bad.npz"
    bad.write_text("not a zip")
    _assert_error(bad, ["npz"])


def test_a_path_is_a_str_bytes_or_path_like_and_anything_else_is_one_line(tmp_path):
    p = _csv(tmp_path, _good_rows())
    want, _ = read_imu(p)

    class Where:  # an os.PathLike of one's own
        def __fspath__(self):
            return os.fsencode(p)

    for path in (str(p), os.fsencode(p), Where(), p):
        for reader in (read_imu, fio.read_csv):
            imu, meta = reader(path)
            assert meta["path"] == str(p) and np.array_equal(imu.gyro, want.gyro) and np.array_equal(imu.t, want.t)
    with pytest.raises(IMUFileError) as ei:
        read_imu(os.fsencode(tmp_path / "gone.npz"))
    assert str(ei.value) == f"{tmp_path / 'gone.npz'}: file not found"
    for bad in (3, None, ["a.csv"]):
        with pytest.raises(TypeError) as ei:
            read_imu(bad)
        msg = str(ei.value)
        assert "\n" not in msg and msg.startswith("IMU file path: expected a str, bytes or os.PathLike, found "), msg
        assert type(bad).__name__ in msg


def test_error_is_a_value_error_with_attributes(tmp_path):
    with pytest.raises(ValueError) as ei:
        read_imu(tmp_path / "gone.csv")
    assert ei.value.path == str(tmp_path / "gone.csv") and ei.value.problem == "file not found"


# ---------------------------------------------------------------- atomic writes

@pytest.mark.parametrize("writer", ["csv", "npz", "imu"])
def test_write_into_a_file_as_directory_fails_cleanly(tmp_path, writer):
    blocker = tmp_path / "blocker"
    blocker.write_text("I am a file")
    target = blocker / f"out.{writer}"
    fn = {"csv": write_csv, "npz": write_npz, "imu": lambda p, i: write_psins(p, i, (0, 0, 0), lat=0.5)}
    with pytest.raises(OSError):
        fn[writer](target, _rate_imu())
    assert not os.path.exists(target)
    assert sorted(os.listdir(tmp_path)) == ["blocker"]


@pytest.mark.parametrize("writer", [write_csv, write_npz,
                                    lambda p, i: write_psins(p, i, (0, 0, 0), lat=0.5)])
def test_exception_mid_write_leaves_nothing(tmp_path, monkeypatch, writer):
    def boom(*args, **kwargs):
        raise RuntimeError("disk full (simulated)")
    monkeypatch.setattr(fio.np, "savetxt", boom)
    monkeypatch.setattr(fio.np, "savez", boom)
    target = tmp_path / "out.dat"
    with pytest.raises(RuntimeError):
        writer(target, _rate_imu())
    assert not target.exists() and os.listdir(tmp_path) == []


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "keep.csv"
    write_csv(target, _rate_imu(seed=3))
    before = target.read_bytes()

    def boom(*args, **kwargs):
        raise RuntimeError("simulated")
    monkeypatch.setattr(fio.np, "savetxt", boom)
    with pytest.raises(RuntimeError):
        write_csv(target, _rate_imu(seed=4))
    assert target.read_bytes() == before and os.listdir(tmp_path) == ["keep.csv"]


def test_non_finite_data_not_written(tmp_path):
    imu = _rate_imu()
    imu.gyro[0, 5, 0] = np.nan
    with pytest.raises(ValueError):
        write_csv(tmp_path / "n.csv", imu)
    with pytest.raises(ValueError):
        write_psins(tmp_path / "n.imu", imu, (0, 0, 0), lat=0.1)
    assert os.listdir(tmp_path) == []
