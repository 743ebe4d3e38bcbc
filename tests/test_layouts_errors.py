"""Bad input to fusionbench.files.layouts: a log's bad rows, columns, times and paths, and bad format files, each
refused in one line naming the file, the row or line and the column or key."""

import os

import numpy as np
import pytest

from fusionbench.files.imufiles import IMUFileError
from fusionbench.files.layouts import Layout, layout_from_name_or_file, load_layout, read_layout
from fusionbench.simulation.fields import FieldError


def _one_line(exc_info, *words):
    msg = str(exc_info.value)
    assert "\n" not in msg, msg
    for w in words:
        assert w in msg, (w, msg)
    return msg


def _kfgins_rows(n=5, cols=7):
    return "".join(" ".join(str(v) for v in [456300 + 0.005 * k, 1e-6, 2e-6, 3e-6, 1e-3, 2e-3, 0.049][:cols]) + "\n"
                   for k in range(n))


@pytest.mark.parametrize("what, words", [
    ("gap", ["gap in time at row 3 (line 4)", "step 0.01 s after 456300.01 s, 2 times the nominal step 0.005 s: "
                                              "about 1 sample(s) missing"]),
    ("duplicate", ["time not strictly increasing at row 3 (line 4): a duplicate time, t=456300.01 s after "
                   "456300.01 s"]),
    ("reversal", ["time not strictly increasing at row 3 (line 4): a reversal, t=456300.005 s after 456300.01 s"]),
    ("short", ["time step too short at row 3 (line 4): step 0.001 s", "0.2 times the nominal step"]),
])
def test_bad_times_in_a_kf_gins_log_name_the_row(tmp_path, what, words):
    stamps = {"gap": "456300.02", "duplicate": "456300.01", "reversal": "456300.005", "short": "456300.011"}
    rows = _kfgins_rows(8).splitlines()
    if what == "gap":  # row 3 onwards a step later: one sample missing
        rows = rows[:3] + rows[4:]
    else:
        rows[3] = " ".join([stamps[what]] + rows[3].split()[1:])
    p = tmp_path / "k.txt"
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "kf-gins")
    _one_line(ei, "k.txt", *words)


def test_a_path_may_be_bytes_or_path_like(tmp_path):
    p = tmp_path / "k.txt"
    p.write_text(_kfgins_rows(5))
    want, _ = read_layout(p, "kf-gins")
    for path in (os.fsencode(p), str(p)):
        got, meta = read_layout(path, "kf-gins")
        assert meta["path"] == str(p) and np.array_equal(got.gyro, want.gyro)
    with pytest.raises(TypeError, match="expected a str, bytes or os.PathLike, found int"):
        read_layout(7, "kf-gins")


def test_missing_column_name(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("time,gyro_x,gyr_y,gyro_z,accel_x,accel_y,accel_z\n" + "0,0,0,0,0,0,9.8\n0.1,0,0,0,0,0,9.8\n")
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "pyins")
    _one_line(ei, "p.csv", "column 'gyro_y' (gyro y) missing from the header", "gyr_y")


def test_column_index_out_of_range(tmp_path):
    p = tmp_path / "k.txt"
    p.write_text(_kfgins_rows(cols=6))
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "kf-gins")
    _one_line(ei, "k.txt", "column 6 (accel z) out of range", "row 0 (line 1) has 6 fields")


def test_non_numeric_cell_names_row_line_and_column(tmp_path):
    p = tmp_path / "k.txt"
    rows = _kfgins_rows().splitlines()
    rows[3] = rows[3].replace("3e-06", "3e-06x")
    p.write_text("# KF-GINS\n" + "\n".join(rows) + "\n")
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "kf-gins")
    _one_line(ei, "k.txt", "non-numeric value '3e-06x' at row 3 (line 5), column 3 (gyro z)")


def test_header_where_none_is_expected_and_no_comment_prefix(tmp_path):
    p = tmp_path / "h.csv"
    p.write_text("time,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z\n0,0,0,0,0,0,9.8\n0.1,0,0,0,0,0,9.8\n")
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, Layout())
    _one_line(ei, "h.csv", "non-numeric value 'time' at row 0 (line 1), column 0 (time) (a header line?")
    p.write_text("# a comment\n0 0 0 0 0 0 9.8\n0.1 0 0 0 0 0 9.8\n")
    assert read_layout(p, Layout())[0].samples == 2
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, Layout(comment=""))  # no comment prefix: the comment is row 0, of 3 fields
    _one_line(ei, "h.csv", "column 3 (gyro z) out of range: row 0 (line 1) has 3 fields")


def test_skipped_row_keeps_the_file_row_numbers(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("time,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z\n"
                 + "".join(f"{0.1 * k},0,0,0,0,0,{'nan' if k == 2 else 0.98}\n" for k in range(4)))
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "pyins-increment")
    _one_line(ei, "p.csv", "non-finite value nan at row 2 (line 4), column 'accel_z' (accel z")


def test_out_of_range_value_names_the_file_column_and_unit(tmp_path):
    p = tmp_path / "d.txt"  # 200 rad/s: deg/s written where rad/s was declared
    p.write_text("".join(f"{0.1 * k} 0 200 0 0 0 9.8\n" for k in range(4)))
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, Layout())
    _one_line(ei, "d.txt", "row 0 (line 1), column 2 (gyro y, read in rad/s)", "a unit or scaling error")


def test_rows_of_another_width_and_bad_time(tmp_path):
    p = tmp_path / "k.txt"
    p.write_text(_kfgins_rows() + "456300.025 1 2 3\n")
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "kf-gins")
    _one_line(ei, "k.txt", "row 5 (line 6) has 4 fields, expected 7 as in row 0 (line 1)")
    p.write_text(_kfgins_rows().replace("456300.01 ", "456300.02 "))
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "kf-gins")
    _one_line(ei, "k.txt", "time not strictly increasing at row 3 (line 4)")
    p.write_text(_kfgins_rows(n=1))
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "kf-gins")
    _one_line(ei, "k.txt", "too short: 1 samples")
    p.write_text("")
    with pytest.raises(IMUFileError) as ei:
        read_layout(p, "pyins")
    _one_line(ei, "k.txt", "no header line found")


BAD_FORMATS = [
    ("gyro_units = 'deg/s'", "field 'layout.gyro_units': unknown"),
    ("gyro_unit = 'deg/sec'", "field 'layout.gyro_unit': expected one of ['deg/h', 'deg/s', 'rad/s'], found 'deg/sec'"),
    ("kind = 'increment'\ngyro_unit = 'deg/s'", "field 'layout.gyro_unit': expected one of ['arcsec', 'deg', 'rad']"),
    ("accel_unit = 'ft/s^2'", "field 'layout.accel_unit'"),
    ("time_unit = 'min'", "field 'layout.time_unit'"),
    ("axes = 'ENU'", "field 'layout.axes': expected one of ['FLU', 'FRD', 'NED-style', 'RFU'], found 'ENU'"),
    ("delimiter = 'tab'", "field 'layout.delimiter'"),
    ("header = 'yes'", "field 'layout.header': expected true or false"),
    ("gyro = ['gx', 'gy', 'gz']", "field 'layout.gyro': a column name ('gx') needs header = true"),
    ("gyro = [1, 2]", "field 'layout.gyro': expected 3 columns"),
    ("time = -1", "field 'layout.time': expected a column"),
    ("accel = [4, 5, 1]", "field 'layout.accel': column 1 is already the gyro x column"),
    ("skip_rows = 1.5", "field 'layout.skip_rows'"),
    ("comment = '# '", "field 'layout.comment'"),
]


@pytest.mark.parametrize("line,expected", BAD_FORMATS, ids=[b[0].split("=")[0].strip() for b in BAD_FORMATS])
def test_bad_format_file_is_one_line_naming_file_and_key(tmp_path, line, expected):
    p = tmp_path / "fmt.toml"
    p.write_text("[layout]\n" + line + "\n")
    with pytest.raises(FieldError) as ei:
        load_layout(p)
    _one_line(ei, str(p), expected)


def test_format_file_level_problems(tmp_path):
    p = tmp_path / "fmt.toml"
    for text, words in (("[layout]\n[extra]\n", "field 'extra': unknown"),
                        ("kind = 'rate'\n", "field 'kind': unknown"),
                        ("", "field 'layout': expected a [layout] table, found none"),
                        ("[layout\n", "not valid TOML")):
        p.write_text(text)
        with pytest.raises(ValueError) as ei:
            layout_from_name_or_file(str(p))
        _one_line(ei, str(p), words)
    with pytest.raises(ValueError) as ei:
        layout_from_name_or_file(tmp_path / "missing.toml")
    _one_line(ei, "missing.toml", "no such layout file")
    with pytest.raises(ValueError) as ei:
        layout_from_name_or_file("kfgins")
    _one_line(ei, "expected a built-in layout (pyins, pyins-increment, kf-gins, fusionbench-csv)", "'kfgins'")


def test_format_file_defaults_and_name(tmp_path):
    p = tmp_path / "minimal.toml"
    p.write_text("[layout]\n")
    assert load_layout(p) == Layout(name="minimal")
    lay = Layout(kind="increment")
    assert (lay.gyro_unit, lay.accel_unit, lay.delimiter, lay.comment) == ("rad", "m/s", "auto", "#")
    with pytest.raises(FieldError) as ei:
        Layout(gyro_unit="deg/s", kind="increment")
    _one_line(ei, "Layout: field 'gyro_unit'")
