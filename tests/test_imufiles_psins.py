"""Tests of the PSINS .imu files of fusionbench.files.imufiles: written with the residual carry, the pyins fixture,
the 7-column variant's dithered times (jitter resampled, a gap refused), bad rows and bad headers."""

import json

import numpy as np
import pytest

from fusionbench.files.imufiles import read_imu, write_psins
from fusionbench.simulation.attitude import dcm_to_euler
from fusionbench.simulation.units import ARCSEC, DEG
from tests.imufiles_helpers import DATA, _assert_error, _incr_imu, _rate_imu

PSINS_HEAD = ("% comment\n\n-2 1 160 0 0 0\n-30 150 0 0 20 9.780325\n"
              "0.01 0.01 0.01 10 10 10\n")


def _imu_file(tmp_path, rows, head=PSINS_HEAD, name="x.imu"):
    p = tmp_path / name
    p.write_text(head + "".join(r + "\n" for r in rows))
    return p


# ---------------------------------------------------------------- round trips

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


# ---------------------------------------------------------------- bad files

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
