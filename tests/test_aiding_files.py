"""Aiding files (fusionbench.files.aidingfiles, fusionbench.files.aidingnmea; docs/aiding.md "Files"): each reader on
a small hand-written file against the numbers written in it, and every bad input through the command line (one line
naming the file, exit status 2)."""

import json

import numpy as np
import pynmea2
import pytest

from fusionbench.cli import main
from fusionbench.files.aidingfiles import AidingFileError, aiding_summary, read_aiding

D = np.pi / 180
KNOT = 1852.0 / 3600.0  # m/s


def nmea(body):
    """``$body*HH``: a sentence with its checksum (pynmea2's)."""
    return f"${body}*{pynmea2.NMEASentence.checksum(body):02X}"


def write(path, text):
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------------------------------------- csv
CSV = """# a receiver's rows; columns in another order, the header's case as it comes
T,lat,lon,h,vN,vE,vU,sigma_P,sigma_v,zupt
10.0,34.5,108.25,452.0,1.5,-2.0,0.25,0.8,0.05,0
10.5,,,,2.0,-2.5,,,0.04,
11.0,34.5001,108.2501,,,,,1.2,,0
11.5,,,,,,,,,1
"""


def test_a_csv_with_every_column_some_empty_reads_to_the_numbers_written(tmp_path):
    path = write(tmp_path / "rows.csv", CSV)
    a = read_aiding(path, lever_arm=(0.3, 1.2, 0.9), delay=0.05, time_offset=100.0)
    nan = np.nan
    assert a.source == str(path) and a.delay == 0.05 and a.lever_arm.tolist() == [0.3, 1.2, 0.9]
    np.testing.assert_array_equal(a.t, [110.0, 110.5, 111.0, 111.5])  # + the time offset
    np.testing.assert_array_equal(a.t_valid, [109.95, 110.45, 110.95, 111.45])  # - the latency
    np.testing.assert_array_equal(a.velocity, [[-2.0, 1.5, 0.25], [-2.5, 2.0, nan], [nan, nan, nan],
                                               [0.0, 0.0, 0.0]])  # ENU; the row at rest is a zero velocity
    np.testing.assert_allclose(a.position[:, :2], np.radians([[34.5, 108.25], [nan, nan], [34.5001, 108.2501],
                                                             [nan, nan]]), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(a.position[:, 2], [452.0, nan, nan, nan])
    np.testing.assert_array_equal(a.sigma_v[:, 0], [0.05, 0.04, 0.045, 0.045])  # empty: the column's median
    np.testing.assert_array_equal(a.sigma_p[:, 1], [0.8, 1.0, 1.2, 1.0])
    np.testing.assert_array_equal(a.at_rest, [False, False, False, True])
    assert aiding_summary(a) == {"file": str(path), "rows": 4, "kinds": ["velocity", "position", "at_rest"],
                                 "lever_arm_m": [0.3, 1.2, 0.9], "delay_s": 0.05, "t_first_s": 110.0,
                                 "t_last_s": 111.5}


def test_a_csv_of_velocity_alone_has_no_position_and_no_sigma(tmp_path):
    a = read_aiding(write(tmp_path / "v.csv", "t,vE,vN\n1,0.5,-0.5\n2,0.75,-0.25\n"))
    assert a.position is None and a.sigma_v is None and a.sigma_p is None and a.at_rest is None
    np.testing.assert_array_equal(a.velocity, [[0.5, -0.5, np.nan], [0.75, -0.25, np.nan]])
    assert aiding_summary(a)["kinds"] == ["velocity"]


# ---------------------------------------------------------------------------------------------------------- kf-gins
def test_a_kf_gins_7_column_file_gives_positions_and_their_std_in_enu(tmp_path):
    path = write(tmp_path / "GNSS-RTK.txt", "456250.000    30.4447858054   114.4718661162     21.095    0.010    "
                                             "0.009    0.019 \n456251.000    30.4447857891   114.4718661133     "
                                             "21.091    0.011    0.008    0.020 \n")
    a = read_aiding(path, "kf-gins")
    np.testing.assert_array_equal(a.t, [456250.0, 456251.0])  # GPS seconds of week, as the IMU file's
    np.testing.assert_allclose(a.position, [[30.4447858054 * D, 114.4718661162 * D, 21.095],
                                            [30.4447857891 * D, 114.4718661133 * D, 21.091]], rtol=1e-15)
    np.testing.assert_array_equal(a.sigma_p, [[0.009, 0.010, 0.019], [0.008, 0.011, 0.020]])  # E, N, U from N, E, D
    assert a.velocity is None and a.sigma_v is None


def test_a_kf_gins_13_column_file_turns_its_ned_velocity_to_enu(tmp_path):
    # time, lat, lon, h, vN, vE, vD, std N, E, D, vstd N, E, D
    path = write(tmp_path / "gnss13.txt", "100.0 30.0 114.0 21.0 1.0 2.0 -0.5 0.01 0.02 0.03 0.1 0.2 0.3\n"
                                          "101.0 30.0 114.0 21.5 1.5 2.5 0.25 0.01 0.02 0.03 0.1 0.2 0.3\n")
    a = read_aiding(path, "kf-gins", time_offset=-100.0)
    np.testing.assert_array_equal(a.t, [0.0, 1.0])
    np.testing.assert_array_equal(a.velocity, [[2.0, 1.0, 0.5], [2.5, 1.5, -0.25]])  # up = -down
    np.testing.assert_array_equal(a.sigma_p[0], [0.02, 0.01, 0.03])  # KF-GINS's position std: columns 7-9
    np.testing.assert_array_equal(a.sigma_v[0], [0.2, 0.1, 0.3])
    np.testing.assert_array_equal(a.position[:, 2], [21.0, 21.5])


# ---------------------------------------------------------------------------------------------------------- nmea
NMEA = "\n".join([
    "# a receiver's log across midnight",
    nmea("GPGSV,3,1,11,03,03,111,00"),                                         # not ours: skipped
    nmea("GPRMC,235959.50,A,4807.0380,N,01131.0000,E,10.0,90.0,230394,,,A"),  # 10 kn east: VTG's wins below
    nmea("GPGGA,235959.50,4807.0380,N,01131.0000,E,1,08,0.9,545.4,M,46.9,M,,"),
    nmea("GPVTG,54.7,T,,M,5.5,N,10.2,K,A"),                                    # 5.5 kn at 54.7 deg
    nmea("GPGST,235959.50,1.0,0.5,0.4,30.0,0.8,0.6,1.5"),                       # sigma lat 0.8, lon 0.6, alt 1.5
    nmea("GNRMC,000000.50,A,4807.0390,S,01131.0010,W,0.0,,240394,,,A"),         # next day; at rest, no course
    nmea("GNGGA,000000.50,4807.0390,S,01131.0010,W,2,08,0.9,546.0,M,,M,,"),     # no geoid separation
    nmea("GPRMC,000001.00,V,,,,,,,240394,,,N"),                                 # no fix: skipped
    nmea("GPGGA,000001.50,4807.0400,N,01131.0020,E,0,00,,,M,,M,,"),             # quality 0: skipped
    nmea("GPGGA,000002.00,4807.0410,N,01131.0030,E,1,08,0.9,547.0,M,46.9,M,,"),  # position only
]) + "\n"


def test_nmea_epochs_merge_their_sentences_and_count_on_past_midnight(tmp_path):
    a = read_aiding(write(tmp_path / "log.nmea", NMEA), "nmea", time_offset=-86000.0)
    np.testing.assert_allclose(a.t, [399.5, 400.5, 402.0], rtol=0, atol=1e-9)  # 86399.5, 86400.5, 86402 s
    s = 5.5 * KNOT
    np.testing.assert_allclose(a.velocity, [[s * np.sin(54.7 * D), s * np.cos(54.7 * D), np.nan],
                                            [0.0, 0.0, np.nan], [np.nan, np.nan, np.nan]], rtol=1e-14)
    lat = np.array([48 + 7.038 / 60, -(48 + 7.039 / 60), 48 + 7.041 / 60])
    lon = np.array([11 + 31.0 / 60, -(11 + 31.001 / 60), 11 + 31.003 / 60])
    np.testing.assert_allclose(a.position[:, :2], np.radians(np.column_stack([lat, lon])), rtol=1e-13)
    np.testing.assert_allclose(a.position[:, 2], [545.4 + 46.9, 546.0, 547.0 + 46.9], rtol=1e-14)
    np.testing.assert_array_equal(a.sigma_p, [[0.6, 0.8, 1.5]] * 3)  # E (lon), N (lat), U; carried to later epochs
    assert a.sigma_v is None and a.at_rest is None


def test_nmea_of_gga_alone_counts_on_past_midnight_by_the_time_of_day(tmp_path):
    text = "\n".join(nmea(f"GPGGA,{hms},4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")
                     for hms in ("235958.00", "235959.00", "000000.00", "000001.00"))
    a = read_aiding(write(tmp_path / "gga.nmea", text), "nmea")
    np.testing.assert_array_equal(a.t, [86398.0, 86399.0, 86400.0, 86401.0])
    assert a.velocity is None and a.sigma_p is None


def test_nmea_rmc_alone_gives_velocity_and_position_without_height(tmp_path):
    a = read_aiding(write(tmp_path / "rmc.nmea", nmea("GPRMC,120000.00,A,3000.000,N,11400.000,E,2.0,180.0,010124,,,D")
                          + "\n"), "nmea")
    np.testing.assert_allclose(a.velocity[0, :2], [0.0, -2.0 * KNOT], atol=1e-15)  # due south
    np.testing.assert_allclose(a.position[0, :2], [30 * D, 114 * D], rtol=1e-15)
    assert np.isnan(a.position[0, 2]) and a.t[0] == 43200.0


# ---------------------------------------------------------------------------------------------------------- bad input
@pytest.fixture(scope="module")
def still(tmp_path_factory):
    """A 20-s stationary CSV recording at 50 Hz."""
    from fusionbench.files.imufiles import write_csv
    from fusionbench.simulation import trajectory as tj
    from fusionbench.simulation.imu import PRESETS, simulate

    tr = tj.Trajectory(0.6, 0.0, 0.0, tj.EulerSway(mean=(0.0, 0.0, 1.0)), duration=20.0)
    return write_csv(tmp_path_factory.mktemp("rec") / "still.csv", simulate(tr, PRESETS["navigation"].noise_free(),
                                                                             0.02))


def fb(capsys, *args):
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


def one_line(err, *words):
    assert "Traceback" not in err and err.count("\n") == 1 and err.startswith("fusionbench: error: "), err
    for word in words:
        assert word in err, (word, err)


BAD = [  # (format, the file, words of its one line)
    ("csv", "", ["no header line"]),
    ("csv", "t,vE,vU\n1,2,3\n", ["column 'vN' missing"]),
    ("csv", "t,h\n1,2\n", ["column 'lat' missing"]),
    ("csv", "vE,vN\n1,2\n", ["column 't' missing"]),
    ("csv", "t,vE,vN,speed\n1,0,0,0\n", ["unknown column 'speed'", "found t,vE,vN,speed"]),
    ("csv", "t,vE,vN,vE\n1,0,0,0\n", ["column 'vE' appears 2 times"]),
    ("csv", "t,sigma_v\n1,0.1\n", ["no measurement column"]),
    ("csv", "t,vE,vN\n", ["no rows", "found none"]),
    ("csv", "t,vE,vN\n1,0.1,abc\n", ["row 0 (line 2), column 'vN'", "expected a number, found 'abc'"]),
    ("csv", "t,vE,vN\n1,0.1,inf\n", ["row 0 (line 2), column 'vN'", "expected a finite number", "'inf'"]),
    ("csv", "t,vE,vN\n1,0,0\n2,0\n", ["row 1 (line 3) has 2 fields, expected 3"]),
    ("csv", "t,vE,vN\n1,0,0\n,0,0\n", ["row 1 (line 3), column 't'", "expected a time in s, found an empty field"]),
    ("csv", "t,vE,vN\n# c\n1,0,0\n2,0,0\n2,0,0\n", ["row 2 (line 5)", "expected strictly increasing times",
                                                    "found 2 s after 2 s (row 1 (line 4))"]),
    ("csv", "t,lat,lon\n1,34,\n", ["row 0 (line 2)", "column 'lat' given but 'lon' empty"]),
    ("csv", "t,vE,vN,sigma_v\n1,0,0,\n", ["row 0 (line 2), column 'sigma_v'", "expected a standard deviation",
                                          "found an empty field"]),
    ("csv", "t,vE,vN,sigma_v\n1,0,0,-1\n", ["column 'sigma_v'", "expected a positive standard deviation, found -1"]),
    ("csv", "t,zupt\n1,2\n", ["row 0 (line 2), column 'zupt'", "expected 1 (at rest), 0 or empty, found 2"]),
    ("csv", "t,vE,vN\n1,2500,0\n", ["velocity", "expected m/s below 2000", "at row 0"]),
    ("csv", "t,lat,lon\n1,95,0\n", ["position", "latitude within +-90 deg", "found 95 at row 0"]),
    ("kf-gins", "1 2 3 4 5 6 7 8\n", ["row 0 (line 1) has 8 fields, expected 7", "or 13"]),
    ("kf-gins", "1 30 114 20 0.1 0.1 0.1\n2 30 114 20 0.1 0.1\n", ["row 1 (line 2) has 6 fields, expected 7"]),
    ("kf-gins", "1 30 x 20 0.1 0.1 0.1\n", ["row 0 (line 1), field 3 (lon)", "expected a finite number, found 'x'"]),
    ("kf-gins", "2 30 114 20 0.1 0.1 0.1\n1 30 114 20 0.1 0.1 0.1\n", ["row 1 (line 2)", "strictly increasing"]),
    ("kf-gins", "1 30 114 20 0.1 0 0.1\n", ["sigma_p", "expected positive finite standard deviations", "row 0"]),
    ("nmea", "$GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*00\n",
     ["line 1: checksum does not match", "expected a sentence ending *HH"]),
    ("nmea", "$GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,\n", ["line 1", "checksum missing"]),
    ("nmea", "# log\nhello receiver\n", ["line 2: expected an NMEA 0183 sentence", "found 'hello receiver'"]),
    ("nmea", nmea("GPRMC,120000.00,V,,,,,,,010124,,,N") + "\n", ["no rows", "valid fix", "1 of an invalid fix"]),
    ("nmea", nmea("GPGGA,120001.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,") + "\n"
     + nmea("GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,") + "\n",
     ["epoch 1 (line 2)", "expected strictly increasing times", "found 43200 s after 43201 s"]),
    ("nmea", nmea("GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,54x.4,M,46.9,M,,") + "\n",
     ["line 1: GGA field 'altitude': expected a number, found '54x.4'"]),
]


@pytest.mark.parametrize("fmt,text,words", BAD, ids=[f"{f}-{w[0][:40]}" for f, _, w in BAD])
def test_a_bad_aiding_file_is_one_line_naming_it(capsys, tmp_path, still, fmt, text, words):
    path = write(tmp_path / f"rows.{fmt}", text)
    status, out, err = fb(capsys, "align", still, "--lat", 34, "--aiding", path, "--aiding-format", fmt)
    assert status == 2 and out == ""
    one_line(err, str(path), *words)
    with pytest.raises(ValueError):  # and the same in Python
        read_aiding(path, fmt)


def test_a_missing_aiding_file_is_one_line(capsys, tmp_path, still):
    status, _, err = fb(capsys, "align", still, "--lat", 34, "--aiding", tmp_path / "none.csv")
    assert status == 2
    one_line(err, "none.csv", "file not found")
    with pytest.raises(AidingFileError):
        read_aiding(tmp_path / "none.csv")


def test_rows_at_rest_outside_the_record_are_refused_until_the_offset_puts_them_in(capsys, tmp_path, still):
    """A stationary record of 20 s with zero-velocity rows stamped 51..68 s: the method names the file and the row
    (the last one after the end of the record); moved by -50 s they lie inside and align as without them."""
    path = write(tmp_path / "rest.csv", "t,zupt\n" + "".join(f"{51 + k},1\n" for k in range(18)))
    status, _, err = fb(capsys, "align", still, "--lat", 34, "--aiding", path)
    assert status == 2
    one_line(err, "coarse: ", str(path), "row 17 is valid at 68.000000 s", "after the IMU record")
    args = ["align", still, "--lat", 34, "--json"]
    status, out, err = fb(capsys, *args, "--aiding", path, "--aiding-time-offset", -50, "--lever-arm", "-0.5,1,0.25")
    assert status == 0, err
    aided = json.loads(out)
    plain = json.loads(fb(capsys, *args)[1])
    assert aided.pop("aiding") == {"file": str(path), "format": "csv", "rows": 18, "kinds": ["at_rest"],
                                   "lever_arm_m": [-0.5, 1.0, 0.25], "delay_s": 0.0, "time_offset_s": -50.0,
                                   "t_first_s": 1.0, "t_last_s": 18.0}
    assert aided == plain  # the same keys and attitude: rows at rest add nothing to a stationary record


def test_consistency_refuses_a_bad_aiding_file_and_writes_nothing(capsys, tmp_path, still):
    path = write(tmp_path / "rows.csv", "t,vE,vN\n1,0,0\n0.5,0,0\n")
    status, out, err = fb(capsys, "consistency", still, "--lat", 34, "--methods", "coarse", "--window", 5,
                          "--aiding", path, "--out", tmp_path / "cons")
    assert status == 2 and out == ""
    one_line(err, str(path), "row 1 (line 3)", "strictly increasing")
    assert not (tmp_path / "cons").exists()


def test_nmea_keeps_the_first_sentence_of_a_type_in_an_epoch_skips_a_leading_vtg_and_carries_a_gst(tmp_path):
    text = "\n".join([nmea("GPVTG,90.0,T,,M,10.0,N,18.52,K,A"),  # before any epoch: no epoch to belong to
                      nmea("GPGST,115959.90,1.0,0.5,0.4,30.0,0.8,0.6,1.5"),  # an epoch of its own: for those after
                      nmea("GPGGA,120000.00,3000.000,N,11400.000,E,1,08,0.9,100.0,M,0.0,M,,"),
                      nmea("GNGGA,120000.00,3100.000,N,11400.000,E,1,08,0.9,200.0,M,0.0,M,,"),  # same epoch
                      nmea("GPGGA,120001.00,3000.000,N,11400.000,E,1,08,0.9,101.0,M,0.0,M,,")]) + "\n"
    a = read_aiding(write(tmp_path / "dup.nmea", text), "nmea")
    np.testing.assert_array_equal(a.t, [43200.0, 43201.0])
    np.testing.assert_array_equal(a.position[:, 2], [100.0, 101.0])
    np.testing.assert_array_equal(a.sigma_p, [[0.6, 0.8, 1.5]] * 2)
    assert a.velocity is None


def test_rows_written_as_an_aiding_csv_read_back_the_same(tmp_path):
    from fusionbench.files.aidingfiles import write_csv
    from fusionbench.simulation import drive
    from fusionbench.simulation.aidingsim import AidingSpec, simulate_aiding

    car = drive.car_drive(np.radians(45.0), heading=0.5, duration=60.0, wait=0.05)
    rows = simulate_aiding(car, AidingSpec(1.0, (0.05,) * 3, (0.5,) * 3, lever_arm=(0.5, 1.2, 0.74), delay=0.05),
                           runs=2, seed=1)
    path = write_csv(tmp_path / "gnss.csv", rows, run=1)
    back = read_aiding(path, lever_arm=rows.lever_arm, delay=0.05)
    # 12 significant digits: 1e-10 deg of latitude (1e-5 m), 1e-12 m/s
    assert np.allclose(back.velocity, rows.velocity[1], atol=1e-10)
    assert np.allclose(back.position[:, :2], rows.position[1, :, :2], atol=1e-11)
    assert np.array_equal(back.t, rows.t) and np.allclose(back.sigma_p, 0.5)
