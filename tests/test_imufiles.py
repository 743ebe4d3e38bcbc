"""Tests of fusionbench.files.imufiles: writer/reader round trips, the PSINS fixture, bad files, atomic writes."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

import fusionbench.files.imufiles as fio
from fusionbench.files.imufiles import IMUFileError, read_imu, write_csv, write_npz, write_psins
from fusionbench.simulation.attitude import dcm_to_euler
from fusionbench.simulation.imudata import IMUData
from fusionbench.simulation.units import ARCSEC, DEG

DATA = Path(__file__).parent / "data"
HEADER = "t,gx,gy,gz,ax,ay,az"


def _rate_imu(n=200, dt=0.01, runs=1, seed=0):
    rng = np.random.default_rng(seed)
    t = 3.0 + dt * np.arange(n)
    gyro = 1e-3 * rng.standard_normal((runs, n, 3)) + np.array([1e-5, 5e-5, 3e-5])
    accel = 1e-2 * rng.standard_normal((runs, n, 3)) + np.array([0.1, -0.2, 9.79])
    return IMUData(t, gyro, accel, kind="rate")


def _incr_imu(n=500, dt=0.02, runs=2, seed=1):
    r = _rate_imu(n, dt, runs, seed)
    return IMUData(r.t, r.gyro * dt, r.accel * dt, kind="increment")


def _csv(tmp_path, rows, name="data.csv", header=HEADER):
    p = tmp_path / name
    p.write_text(header + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    return p


def _good_rows(n=10, dt=0.1):
    return [[k * dt, 1e-5, 2e-5, 3e-5, 0.1, 0.2, 9.8] for k in range(n)]


def _assert_error(path, words, **kw):
    with pytest.raises(IMUFileError) as ei:
        read_imu(path, **kw)
    msg = str(ei.value)
    assert Path(path).name in msg, msg
    assert "\n" not in msg, msg
    assert any(w in msg.lower() for w in words), msg
    return msg


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


def test_psins_round_trip_residual_carry(tmp_path):
    imu = _incr_imu(n=3000)
    att0, lat, lon, h, g = (0.01, -0.02, 2.5), 0.6, 2.0, 35.0, 9.79
    p = write_psins(tmp_path / "x.imu", imu, att0, v0=(0.1, 0.2, 0.0), lat=lat, lon=lon, h=h, g=g,
                    gyro_scale_arcsec=0.01, accel_scale_ugs=10.0, run=1)
    back, meta = read_imu(p)
    assert back.kind == "increment" and back.samples == imu.samples
    np.testing.assert_allclose(back.t, imu.t, rtol=0, atol=1e-9)
    np.testing.assert_allclose(meta["attitude0"], att0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(meta["v0"], (0.1, 0.2, 0.0))
    assert meta["lat"] == pytest.approx(lat, abs=1e-15) and meta["lon"] == pytest.approx(lon, abs=1e-15)
    assert (meta["h"], meta["g"]) == (h, g)
    assert meta["dt"] == pytest.approx(imu.dt, rel=1e-12)
    assert meta["t0"] == pytest.approx(imu.t0, abs=1e-12)
    qg, qa = 0.01 * ARCSEC, 10.0 * 1e-6 * g
    err_g = (np.cumsum(back.gyro[0], 0) - np.cumsum(imu.gyro[1], 0)) / qg
    err_a = (np.cumsum(back.accel[0], 0) - np.cumsum(imu.accel[1], 0)) / qa
    # residual carry: every cumulative sum within half a count (plus float round-off), never a drift
    assert np.abs(err_g).max() <= 0.5 + 1e-6 and np.abs(err_a).max() <= 0.5 + 1e-6
    # whereas per-sample rounding would drift (the check is sensitive)
    naive = np.rint(imu.accel[1] / qa) * qa
    assert np.abs(np.cumsum(naive - imu.accel[1], 0)).max() / qa > 1.0
    # the counts themselves are integers
    counts = np.loadtxt(p, comments="%", skiprows=8, dtype=np.int64)
    assert counts.shape == (imu.samples, 6)


def test_psins_from_rates_uses_trapezoid_increments(tmp_path):
    imu = _rate_imu(n=400, dt=0.01)
    back, meta = read_imu(write_psins(tmp_path / "r.imu", imu, (0, 0, 0), lat=0.5))
    t_end, dth, dv = imu.increments()
    assert back.samples == t_end.size and meta["t0"] == pytest.approx(imu.t[0], abs=1e-12)
    np.testing.assert_allclose(back.t, t_end, atol=1e-9)
    qg, qa = 0.01 * ARCSEC, 10e-6 * 9.780325
    assert np.abs(np.cumsum(back.gyro[0] - dth[0], 0)).max() <= (0.5 + 1e-6) * qg
    assert np.abs(np.cumsum(back.accel[0] - dv[0], 0)).max() <= (0.5 + 1e-6) * qa


# ---------------------------------------------------------------- fixtures

def test_psins_fixture_header_and_samples():
    imu, meta = read_imu(DATA / "pyins_sway_lat30s.imu")
    truth = json.loads((DATA / "pyins_sway_lat30s.json").read_text())
    first = dcm_to_euler(np.array(truth["C_bn_first"]))
    np.testing.assert_allclose(meta["attitude0"], first, atol=1e-6)
    np.testing.assert_allclose(np.array(meta["attitude0"]) / DEG, [-2.0, 1.0, 160.0], atol=1e-9)
    assert imu.kind == "increment" and imu.runs == 1 and imu.samples == 5999
    assert meta["dt"] == pytest.approx(0.020) and imu.dt == pytest.approx(0.020)
    assert meta["t0"] == 0.0 and imu.t[0] == pytest.approx(0.02) and imu.t[-1] == pytest.approx(119.98)
    assert meta["lat"] == pytest.approx(truth["lat_deg"] * DEG)
    assert meta["lon"] == pytest.approx(truth["lon_deg"] * DEG)
    assert meta["h"] == truth["height_m"] and meta["g"] == 9.780325 and meta["v0"] == [0, 0, 0]
    # first row: 6874 9179 -4416 -35 -70 2001
    np.testing.assert_allclose(imu.gyro[0, 0], np.array([6874, 9179, -4416]) * 0.01 * ARCSEC)
    np.testing.assert_allclose(imu.accel[0, 0], np.array([-35, -70, 2001]) * 10e-6 * 9.780325)


def _psins7(path, counts, dither_us, head):
    """A file in the 7-column layout as PSINS's own ``imufile.m`` writes it when the times jitter: each header
    row ends with a 0, each sample row with its time dither in microseconds."""
    rows = [" ".join(str(v) for v in r) + " 0" for r in head]
    rows += [" ".join(str(int(v)) for v in (*c, d)) for c, d in zip(counts, dither_us)]
    path.write_text("% PSINS-format SIMU log file. (DO NOT MODIFY!)\n% [g_x, g_y, g_z, a_x, a_y, a_z, dt]\n\n"
                    + "\n".join(rows) + "\n")
    return path


def test_psins_seven_column_variant_reads_the_same_samples_and_the_dithered_times(tmp_path):
    six, meta6 = read_imu(DATA / "pyins_sway_lat30s.imu")
    lines = [s for s in (DATA / "pyins_sway_lat30s.imu").read_text().splitlines() if s.strip() and s[0] != "%"]
    head = [s.split() for s in lines[:3]]
    counts = np.array([s.split() for s in lines[3:]], dtype=np.int64)
    n = counts.shape[0]
    dither = np.zeros(n, dtype=np.int64)
    dither[[10, 500]] = 7          # 7 us late at rows 10 and 500 (the interval is 20 000 us)
    dither[[11, 502]] = -7         # and back on time at rows 11 and 502
    seven, meta7 = read_imu(_psins7(tmp_path / "d.imu", counts, dither, head))
    assert meta7["columns"] == 7 and meta6["columns"] == 6
    np.testing.assert_array_equal(seven.gyro, six.gyro)
    np.testing.assert_array_equal(seven.accel, six.accel)
    for key in ("attitude0", "lat", "lon", "h", "t0", "dt", "g"):
        assert meta7[key] == meta6[key]
    # PSINS's time rule, written out: t_k = t0 + (k + 1) dt + 1e-6 * sum(dither[:k + 1])
    expected = 0.0 + 0.020 * np.arange(1, n + 1)
    expected[[10, 500, 501]] += 7e-6
    np.testing.assert_allclose(seven.t, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.delete(seven.t, [10, 500, 501]), np.delete(six.t, [10, 500, 501]), atol=1e-12)
    # all-zero dither: the 6-column file exactly
    zero, _ = read_imu(_psins7(tmp_path / "z.imu", counts, np.zeros(n, dtype=np.int64), head))
    np.testing.assert_array_equal(zero.t, six.t)


def test_psins_seven_column_jitter_is_resampled_and_a_gap_refused(tmp_path):
    """Row 2 half a millisecond late (2.5 % of the 20 ms step), row 3 on time: the intervals are 20, 20, 20.5, 19.5,
    20, 20 ms. On the grid from t0 the interval (40, 60] ms takes 20/20.5 of row 2's counts, (60, 80] the rest of
    row 2 and all of row 3; the others are the rows as they are."""
    counts = np.tile([1000, -2000, 300, 40, -50, 2001], (6, 1))
    head = [["0"] * 6, ["30", "120", "0", "0", "20", "9.78"], ["0.01"] * 3 + ["10"] * 3]
    imu, meta = read_imu(_psins7(tmp_path / "j.imu", counts, np.array([0, 0, 500, -500, 0, 0]), head))
    assert meta["resampled"] and imu.kind == "increment" and imu.samples == 6
    np.testing.assert_allclose(imu.t, 0.020 * np.arange(1, 7), rtol=0, atol=1e-12)
    # the grid time 60 ms lies 20 ms into row 2's interval (40, 60.5]: c = (20 ms)(0.5 ms) / 2
    assert meta["jitter_s"] == pytest.approx(500e-6, abs=1e-12)
    assert meta["resampling_c_s2"] == pytest.approx(0.5 * 20e-3 * 0.5e-3, rel=1e-9)
    share = np.array([1, 1, 20 / 20.5, 1 + 0.5 / 20.5, 1, 1])
    q = np.r_[np.full(3, 0.01 * ARCSEC), np.full(3, 10e-6 * 9.78)]
    np.testing.assert_allclose(np.column_stack([imu.gyro[0], imu.accel[0]]), share[:, None] * counts * q,
                               rtol=1e-12, atol=1e-18)
    dither = np.array([0, 0, 0, 20000, 0, 0])  # row 3 a whole step late: the sample before it missing
    msg = _assert_error(_psins7(tmp_path / "g.imu", counts, dither, head), ["gap in time"])
    assert "sample row 3 " in msg and "dither" in msg and "about 1 sample(s) missing" in msg
    rows = [" ".join(map(str, r)) for r in counts]
    msg = _assert_error(_imu_file(tmp_path, rows[:3] + ["1 2 3 4 5 2001 0"] + rows, name="m.imu"), ["fields"])
    assert "sample row 3" in msg and "expected 6" in msg


def test_a_written_psins_file_integrates_to_the_truth_unlike_one_rounded_sample_by_sample(tmp_path):
    """The writer carries each sample's rounding remainder into the next, so the strapdown of the written file
    ends where the strapdown of its exact increments does. pyins's copy of the same recording (written sample by
    sample without the carry) drifts by the summed rounding errors: 0.8 arcsec over these 2 minutes."""
    from fusionbench.simulation import attitude
    from fusionbench.simulation.strapdown import NavState, Strapdown

    truth = json.loads((DATA / "pyins_sway_lat30s.json").read_text())
    rates, _ = read_imu(DATA / "pyins_sway_lat30s.csv")
    pyins_copy, hdr = read_imu(DATA / "pyins_sway_lat30s.imu")
    written, _ = read_imu(write_psins(tmp_path / "w.imu", rates, hdr["attitude0"], lat=hdr["lat"], h=hdr["h"]))

    def final_error_arcsec(imu):
        _, dth, dv = imu.increments()
        nav = NavState.broadcast(1, attitude.euler_to_dcm(hdr["attitude0"]), lat=hdr["lat"], h=hdr["h"])
        out = Strapdown(nav, imu.dt, position_fixed=True).run(dth, dv)
        return np.linalg.norm(attitude.misalignment(out["C_bn"][0, -1], np.array(truth["C_bn_last"]))) / ARCSEC

    exact = final_error_arcsec(rates)  # the trapezoid increments themselves, unquantised
    assert exact < 0.05
    # within a few counts of 0.01 arcsec of the unquantised file, whereas the copy without the carry drifts
    assert abs(final_error_arcsec(written) - exact) < 0.02
    assert final_error_arcsec(pyins_copy) > 0.5


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


PSINS_HEAD = ("% comment\n\n-2 1 160 0 0 0\n-30 150 0 0 20 9.780325\n"
              "0.01 0.01 0.01 10 10 10\n")


def _imu_file(tmp_path, rows, head=PSINS_HEAD, name="x.imu"):
    p = tmp_path / name
    p.write_text(head + "".join(r + "\n" for r in rows))
    return p


def test_psins_minimal_and_bad_rows(tmp_path):
    good = ["1 2 3 4 5 2001"] * 4
    imu, meta = read_imu(_imu_file(tmp_path, good))
    assert imu.samples == 4 and meta["dt"] == pytest.approx(0.02)
    msg = _assert_error(_imu_file(tmp_path, good[:2] + ["1 2 3 4 5"] + good, name="f.imu"), ["fields"])
    assert "line 8" in msg and "6 integers" in msg
    msg = _assert_error(_imu_file(tmp_path, good + ["1 2 3.5 4 5 6"], name="i.imu"), ["integer"])
    assert "'3.5'" in msg
    _assert_error(_imu_file(tmp_path, good + ["1 2 x 4 5 6"], name="x2.imu"), ["integer"])
    _assert_error(_imu_file(tmp_path, good[:1], name="s.imu"), ["too short"])


def test_psins_bad_header(tmp_path):
    rows = ["1 2 3 4 5 6"] * 3
    msg = _assert_error(_imu_file(tmp_path, rows, head="-2 1 160 0 0\n-30 150 0 0 20 9.78\n"
                                  "0.01 0.01 0.01 10 10 10\n"), ["fields"])
    assert "header row 1" in msg
    _assert_error(_imu_file(tmp_path, rows, head="-2 1 160 0 0 0\n-30 150 0 0 nan 9.78\n"
                            "0.01 0.01 0.01 10 10 10\n", name="n.imu"), ["finite"])
    _assert_error(_imu_file(tmp_path, rows, head="-2 1 160 0 0 0\n-30 150 0 0 -20 9.78\n"
                            "0.01 0.01 0.01 10 10 10\n", name="d.imu"), ["positive"])
    _assert_error(_imu_file(tmp_path, [], head="% only\n-2 1 160 0 0 0\n", name="h.imu"), ["header"])


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
