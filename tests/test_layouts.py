"""Tests of fusionbench.files.layouts: other people's IMU log layouts read into fusionbench's frames and units.

One swaying recording (fusionbench's simulator, perfect IMU) is written in each layout by this file's own writer,
which takes the file axes from their letter definitions (never from the module's matrices) and the units from
fusionbench.simulation.units. Read back, the arrays must equal the original to float precision, and the strapdown of
them from the true initial state must reach the true attitude and velocity at the last sample within bounds that a
read one sample late, or with a wrong axis, exceeds a hundred times over (both reads are made and shown to fail).
Real pyins files, written by pyins itself, go through the pyins layouts: a sway through the strapdown, a static
record through the analytic coarse alignment.
"""

import ast
import dataclasses
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fusionbench.files.imufiles import IMUFileError, read_csv, write_csv
from fusionbench.files.layouts import (AXES, BUILTIN_LAYOUTS, Layout, layout_from_name_or_file, load_layout,
                                 read_layout)
from fusionbench.methods.aligner import Site
from fusionbench.methods.coarse import CoarseAligner
from fusionbench.simulation import attitude, trajectory as tj
from fusionbench.simulation.fields import FieldError
from fusionbench.simulation.imu import IMUSpec, simulate
from fusionbench.simulation.imudata import IMUData
from fusionbench.simulation.strapdown import NavState, Strapdown
from fusionbench.simulation.units import ARCSEC, DEG, DEG_PER_H, DEG_PER_S, G0, MICROSECOND, MILLISECOND, NANOSECOND
from tests.independent import P as P_PYINS

LAT, LON, H = 34 * DEG, 108 * DEG, 450.0
DT = 0.01
N = 3130  # 31.3 s: the sway's rates at the end differ from those at the start, so a time shift shows
#: The file's x, y, z by letter: R right, L left, F forward, B back, U up, D down, in RFU coordinates.
DIRS = {"R": (1, 0, 0), "L": (-1, 0, 0), "F": (0, 1, 0), "B": (0, -1, 0), "U": (0, 0, 1), "D": (0, 0, -1)}
LETTERS = {"RFU": "RFU", "FRD": "FRD", "FLU": "FLU", "NED-style": "FRD"}
#: SI per file unit, this test's own table.
UNIT = {"s": 1.0, "ms": MILLISECOND, "us": MICROSECOND, "ns": NANOSECOND, "rad/s": 1.0, "deg/s": DEG_PER_S,
        "deg/h": DEG_PER_H, "rad": 1.0, "deg": DEG, "arcsec": ARCSEC, "m/s^2": 1.0, "g": G0, "m/s": 1.0}


# ------------------------------------------------------------------------------------------ the recording


@pytest.fixture(scope="module")
def sway():
    """A swaying base at 34 N: the trajectory, its exact increments (t = dt, 2 dt, ...) and its exact rates
    sampled at t = 0, dt, ... (both N samples, one run, body RFU, SI). The rates are the trajectory's kinematics at
    the sample times, as a rate log holds them; ``simulate(output="rate")`` gives interval means at the interval
    ends instead, half a sample late for the trapezoid integration of a rate log."""
    tr = tj.Trajectory(LAT, LON, H, tj.EulerSway(mean=(1 * DEG, -2 * DEG, 123 * DEG), amplitude=(2 * DEG, 3 * DEG, 4 * DEG),
                                                 frequency=(0.3, 0.2, 0.1)), duration=40.0)
    inc = simulate(tr, IMUSpec(), DT, duration=N * DT, output="increment")
    t = DT * np.arange(N)
    w, f = tr.kinematics(t)
    return tr, {"increment": inc, "rate": IMUData(t, w, f, kind="rate")}


def nav_error(tr, imu):
    """Attitude error (rad, norm) and velocity error (m/s, norm) at the last sample of a position-fixed strapdown of
    ``imu`` from the true state at ``imu.t0``; the base does not translate, so the true velocity is zero."""
    _, dth, dv = imu.increments()
    s0 = tr.truth([imu.t0])
    out = Strapdown(NavState.broadcast(1, s0.C_bn[0], lat=s0.lat[0], lon=s0.lon[0], h=s0.h[0]), imu.dt,
                    position_fixed=True).run(dth, dv, record_every=dth.shape[1])
    phi = attitude.misalignment(out["C_bn"][0, -1], tr.truth([imu.t[-1]]).C_bn[0])
    return float(np.linalg.norm(phi)), float(np.linalg.norm(out["v_n"][0, -1]))


def shift_errors(tr, imu):
    """What a read one sample late does, from the truth alone (no strapdown): it starts from C(t0 + dt), applies the
    body rotation of (t0, tN], C(t0)^T C(tN), and is compared with C(tN + dt). Returns the attitude error (rad) and
    the velocity error that the initial tilt error builds over the record, g |phi_EN| T (m/s)."""
    t0, tn = imu.t0, imu.t[-1]
    C = tr.truth([t0, t0 + DT, tn, tn + DT]).C_bn
    att = np.linalg.norm(attitude.misalignment(C[1] @ C[0].T @ C[2], C[3]))
    tilt = np.linalg.norm(attitude.misalignment(C[1], C[0])[:2])
    return float(att), float(G0 * tilt * (tn - t0))


# --------------------------------------------------------------------------------------- this test's writer


def to_file_axes(v_rfu, axes):
    """Components of RFU vectors along the directions the layout's file x, y, z name (exact: entries 0 and +-1)."""
    return np.asarray(v_rfu) @ np.array([DIRS[c] for c in LETTERS[axes]], dtype=float).T


def write_log(path, layout, imu, header_order=None, extra=False, duplicate_first=False):
    """``imu`` (one run, SI, RFU) written in ``layout`` by this test's own code; ``header_order`` permutes the
    columns of a header, ``extra`` adds an unused temperature column, ``duplicate_first`` repeats the first row at
    t0 - dt as pyins does for increments."""
    t = imu.t / UNIT[layout.time_unit]
    g = to_file_axes(imu.gyro[0], layout.axes) / UNIT[layout.gyro_unit]
    a = to_file_axes(imu.accel[0], layout.axes) / UNIT[layout.accel_unit]
    values = np.column_stack([t, g, a])
    if duplicate_first:
        values = np.vstack([np.r_[(imu.t[0] - imu.dt) / UNIT[layout.time_unit], values[0, 1:]], values])
    cols = layout.columns
    if layout.header:
        names = [cols[j] for j in (header_order or range(7))] + (["temp_c"] if extra else [])
        where = [names.index(c) for c in cols]
    else:
        names, where = None, list(cols)
    width = max(where) + 1 + int(extra)
    table = np.full((values.shape[0], width), 21.5)  # unused columns: a temperature
    table[:, where] = values
    sep = {"whitespace": "   ", "auto": ","}.get(layout.delimiter, layout.delimiter)
    lines = [f"{layout.comment} written by tests/test_layouts.py"] if layout.comment else []
    lines += [sep.join(names)] if names else []
    lines += [sep.join("%.17g" % v for v in row) for row in table]
    if layout.comment:
        lines.insert(len(lines) // 2, f"{layout.comment} a comment line among the samples")
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


FORMATS = {
    "deg_s-g-ms": ("rate", """
[layout]
description = "a logger's dump: no header, blanks between columns, time in ms, deg/s and g, x forward y left z up"
delimiter = "whitespace"
time = 7
gyro = [4, 5, 6]
accel = [0, 1, 2]
time_unit = "ms"
gyro_unit = "deg/s"
accel_unit = "g"
axes = "FLU"
""", {}),
    "deg_h-us": ("rate", """
[layout]
name = "ship-log"
delimiter = ";"
header = true
comment = "//"
time = "Stamp_us"
gyro = ["wx", "wy", "wz"]
accel = ["fx", "fy", "fz"]
time_unit = "us"
gyro_unit = "deg/h"
accel_unit = "g"
axes = "NED-style"
""", {"header_order": [6, 5, 4, 0, 3, 2, 1], "extra": True}),
    "arcsec-ns": ("increment", """
[layout]
kind = "increment"
delimiter = "|"
header = true
comment = "%"
time = "t_ns"
gyro = ["dthx", "dthy", "dthz"]
accel = ["dvx", "dvy", "dvz"]
time_unit = "ns"
gyro_unit = "arcsec"
axes = "FRD"
""", {"extra": True}),
}
#: Built-in layout: (kind of recording, writer options).
BUILTINS = {"pyins": ("rate", {}), "pyins-increment": ("increment", {"duplicate_first": True}),
            "kf-gins": ("increment", {}), "fusionbench-csv": ("rate", {"header_order": [3, 1, 0, 2, 4, 6, 5]})}
CASES = [("builtin", name) for name in BUILTINS] + [("format", name) for name in FORMATS]


def case_layout(tmp_path, source, name):
    if source == "builtin":
        kind, opts = BUILTINS[name]
        return layout_from_name_or_file(name), kind, opts
    kind, text, opts = FORMATS[name]
    fmt = tmp_path / f"{name}.toml"
    fmt.write_text(text)
    return layout_from_name_or_file(str(fmt)), kind, opts


def wrong_axes(axes):
    """Another axes name: a read with it flips or swaps axes."""
    return "FLU" if LETTERS[axes] != "FLU" else "FRD"


# ---------------------------------------------------------------------------------- round trips and truth


@pytest.mark.parametrize("source,name", CASES, ids=[n for _, n in CASES])
def test_layout_reads_back_the_recording_and_its_attitude(tmp_path, sway, source, name, record_property):
    tr, rec = sway
    layout, kind, opts = case_layout(tmp_path, source, name)
    ref = rec[kind]
    path = write_log(tmp_path / f"log-{name}.txt", layout, ref, **opts)
    back, meta = read_layout(path, layout)
    assert (back.kind, back.runs, back.samples) == (kind, 1, N)
    assert meta["format"] == layout.name and meta["axes"] == layout.axes and meta["path"] == str(path)
    # the same numbers: exactly in SI units (a signed permutation is exact), to float precision when scaled
    exact = all(UNIT[u] == 1.0 for u in (layout.time_unit, layout.gyro_unit, layout.accel_unit))
    for got, want in ((back.t, ref.t), (back.gyro, ref.gyro), (back.accel, ref.accel)):
        if exact:
            np.testing.assert_array_equal(got, want)
        else:
            np.testing.assert_allclose(got, want, rtol=2e-15, atol=0)
    # the strapdown of what was read lands on the truth; a read one sample late misses by shift_att
    shift_att, shift_v = shift_errors(tr, back)
    att, vel = nav_error(tr, back)
    late = nav_error(tr, IMUData(back.t + back.dt, back.gyro, back.accel, back.kind))
    flipped, _ = read_layout(path, dataclasses.replace(layout, axes=wrong_axes(layout.axes)))
    wrong = nav_error(tr, flipped)
    record_property("attitude_error_arcsec", att / ARCSEC)
    record_property("velocity_error_mps", vel)
    record_property("late_read_errors_arcsec_mps", (late[0] / ARCSEC, late[1]))
    record_property("wrong_axes_errors_arcsec_mps", (wrong[0] / ARCSEC, wrong[1]))
    bound_att, bound_v = shift_att / 100, shift_v / 1000
    assert bound_att > ARCSEC  # the sway turns ~0.03 deg per sample: a late read is not a rounding error
    assert att < bound_att and vel < bound_v
    assert late[0] == pytest.approx(shift_att, rel=0.02)  # the late read fails as predicted ...
    assert late[1] == pytest.approx(shift_v, rel=0.2) and late[1] > 100 * bound_v
    assert wrong[0] > 100 * bound_att and wrong[1] > 100 * bound_v  # ... and so does a wrong axis


def test_fusionbench_csv_layout_equals_read_csv(tmp_path, sway):
    _, rec = sway
    path = write_csv(tmp_path / "own.csv", rec["rate"])
    a, meta_a = read_csv(path)
    b, meta_b = read_layout(path, "fusionbench-csv")
    for name in ("t", "gyro", "accel"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    assert (b.kind, meta_b["samples"], meta_b["dt"]) == (a.kind, meta_a["samples"], meta_a["dt"])


JITTER_CASES = [("builtin", "pyins"), ("builtin", "kf-gins"), ("format", "arcsec-ns")]


@pytest.mark.parametrize("source,name", JITTER_CASES, ids=[n for _, n in JITTER_CASES])
def test_a_log_with_jittered_times_is_resampled_and_lands_on_the_truth(tmp_path, sway, source, name):
    """The sway stamped 10 % of a step early or late at random: rates at the actual times, or the exact increments
    over the actual intervals (4-point Gauss-Legendre, the first one mean step long). Read onto the uniform grid of
    the same span, the strapdown lands on the truth within the uniform round trip's bounds: the resampling bound
    c (max|dw/dt| + int |w x dw/dt| dt) of this sway is under 0.1 arcsec, a tenth of them."""
    tr, _ = sway
    layout, kind, _ = case_layout(tmp_path, source, name)
    tau = DT * np.arange(N) + np.random.default_rng(5).uniform(-0.1, 0.1, N) * DT
    if kind == "rate":
        gyro, accel = tr.kinematics(tau)
    else:
        starts = np.r_[tau[0] - (tau[-1] - tau[0]) / (N - 1), tau[:-1]]
        x, w = np.polynomial.legendre.leggauss(4)
        mid, half = 0.5 * (starts + tau), 0.5 * (tau - starts)
        rates = tr.kinematics((mid[:, None] + half[:, None] * x).ravel())
        gyro, accel = (np.einsum("nqi,nq->ni", r.reshape(N, 4, 3), half[:, None] * w) for r in rates)
    jittered = SimpleNamespace(t=tau, gyro=gyro[None], accel=accel[None], dt=DT)  # IMUData would refuse the times
    back, meta = read_layout(write_log(tmp_path / f"jit-{name}.txt", layout, jittered), layout)
    assert meta["resampled"] and meta["kind"] == kind and back.kind == "increment"
    assert back.samples == N - (kind == "rate") and back.t[-1] == pytest.approx(tau[-1], abs=1e-9)
    assert np.ptp(np.diff(back.t)) < 1e-9 and 0.05 * DT < meta["jitter_s"] < 0.21 * DT
    shift_att, shift_v = shift_errors(tr, back)
    att, vel = nav_error(tr, back)
    assert att < shift_att / 100 and vel < shift_v / 1000


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


# ------------------------------------------------------------------------------------------------ the axes


#: Known motions: (what, RFU vector, the file's x, y, z for RFU, FRD, FLU); written by hand from the definitions.
MOTIONS = [
    ("yaw rate to the left (about up)", "gyro", (0, 0, 2), {"RFU": (0, 0, 2), "FRD": (0, 0, -2), "FLU": (0, 0, 2)}),
    ("roll rate, right side down (about forward)", "gyro", (0, 3, 0),
     {"RFU": (0, 3, 0), "FRD": (3, 0, 0), "FLU": (3, 0, 0)}),
    ("pitch rate, nose up (about right)", "gyro", (5, 0, 0), {"RFU": (5, 0, 0), "FRD": (0, 5, 0), "FLU": (0, -5, 0)}),
    ("forward specific force", "accel", (0, 7, 0), {"RFU": (0, 7, 0), "FRD": (7, 0, 0), "FLU": (7, 0, 0)}),
    ("specific force to the right", "accel", (4, 0, 0), {"RFU": (4, 0, 0), "FRD": (0, 4, 0), "FLU": (0, -4, 0)}),
    ("level and still: specific force up", "accel", (0, 0, 9.8),
     {"RFU": (0, 0, 9.8), "FRD": (0, 0, -9.8), "FLU": (0, 0, 9.8)}),
]


@pytest.mark.parametrize("axes", ["RFU", "FRD", "FLU", "NED-style"])
@pytest.mark.parametrize("what,sensor,rfu,files", MOTIONS, ids=[m[0] for m in MOTIONS])
def test_known_motion_lands_on_the_right_rfu_axis(tmp_path, axes, what, sensor, rfu, files):
    v = np.array(files[LETTERS[axes]], dtype=float)
    g, a = (v, np.zeros(3)) if sensor == "gyro" else (np.zeros(3), v)
    path = tmp_path / "m.txt"
    path.write_text("".join(f"{k * 0.1} {' '.join(map(str, g))} {' '.join(map(str, a))}\n" for k in range(3)))
    imu, _ = read_layout(path, Layout(axes=axes))
    np.testing.assert_array_equal((imu.gyro if sensor == "gyro" else imu.accel)[0], np.tile(rfu, (3, 1)))
    np.testing.assert_array_equal((imu.accel if sensor == "gyro" else imu.gyro)[0], np.zeros((3, 3)))


def test_axes_matrices_are_the_letter_definitions():
    for name, M in AXES.items():
        # column j of M is the direction file axis j names, in RFU
        np.testing.assert_array_equal(M, np.array([DIRS[c] for c in LETTERS[name]], dtype=float).T)
        assert np.linalg.det(M) == 1.0  # a proper rotation: the file's axes are right-handed
    np.testing.assert_array_equal(AXES["FRD"], P_PYINS)  # the map tests/independent.py uses for pyins
    assert AXES["NED-style"] is AXES["FRD"]


# ------------------------------------------------------------------------------------------- real pyins files


def _pyins_rph(t, rph0, sway_deg, freq_hz):
    return np.asarray(rph0) + np.asarray(sway_deg) * np.sin(2 * np.pi * np.outer(t, freq_hz))


def _c_bn_from_pyins(rph_deg):
    """fusionbench's C_bn of pyins roll, pitch, heading (deg): pitch and roll are the same angles, yaw is counter-
    clockwise from north, so yaw = -heading; C_bn = Rz(yaw) Rx(pitch) Ry(roll)."""
    rph = np.radians(np.atleast_2d(rph_deg))
    return attitude.euler_to_dcm(np.column_stack([rph[:, 1], rph[:, 0], -rph[:, 2]]))


def test_pyins_conversion_agrees_with_tests_independent():
    from pyins import transform

    rph = np.array([[3.0, -5.0, 120.0], [-1.0, 2.0, 300.0]])
    np.testing.assert_allclose(_c_bn_from_pyins(rph), P_PYINS @ transform.mat_from_rph(rph) @ P_PYINS, atol=1e-15)


@pytest.mark.parametrize("sensor_type,name", [("rate", "pyins"), ("increment", "pyins-increment")])
def test_pyins_sway_file_written_by_pyins_follows_its_truth(tmp_path, sensor_type, name, record_property):
    from pyins import sim

    rate_hz, n = 50.0, 1566  # 31.3 s, as N
    t = np.arange(n + 1) / rate_hz  # one sample more than written: the truth of a read one sample late
    rph = _pyins_rph(t, (1.0, -2.0, 200.0), (2.0, 3.0, 4.0), (0.3, 0.2, 0.1))
    _, df = sim.generate_imu(t, np.tile([-30.0, 150.0, 0.0], (n + 1, 1)), rph, np.zeros((n + 1, 3)),
                             sensor_type=sensor_type)
    path = tmp_path / f"{name}.csv"
    df.iloc[:n].to_csv(path)
    imu, meta = read_layout(path, name)
    C = _c_bn_from_pyins(rph)
    assert imu.t0 == 0.0 and imu.samples == (n if sensor_type == "rate" else n - 1)
    assert meta["skipped_rows"] == (sensor_type == "increment")

    def error(data):
        k0 = int(round(data.t0 * rate_hz))
        _, dth, dv = data.increments()
        out = Strapdown(NavState.broadcast(1, C[k0], lat=-30 * DEG, lon=150 * DEG), data.dt,
                        position_fixed=True).run(dth, dv, record_every=dth.shape[1])
        return float(np.linalg.norm(attitude.misalignment(out["C_bn"][0, -1], C[k0 + dth.shape[1]])))

    late = np.linalg.norm(attitude.misalignment(C[1] @ C[0].T @ C[n - 1], C[n]))  # as shift_errors
    err, err_late = error(imu), error(IMUData(imu.t + imu.dt, imu.gyro, imu.accel, imu.kind))
    flipped, _ = read_layout(path, dataclasses.replace(BUILTIN_LAYOUTS[name], axes="FLU"))
    err_flip = error(flipped)
    record_property("attitude_error_arcsec", err / ARCSEC)
    record_property("late_and_flipped_arcsec", (err_late / ARCSEC, err_flip / ARCSEC))
    assert err < late / 100
    assert err_late == pytest.approx(late, rel=0.02) and err_flip > 100 * err


def test_pyins_increment_file_drops_the_duplicated_first_row(tmp_path):
    from pyins import sim

    t = np.arange(6) * 0.1
    rph = _pyins_rph(t, (1.0, 2.0, 30.0), (1.0, 1.0, 1.0), (0.5, 0.5, 0.5))
    _, df = sim.generate_imu(t, np.tile([40.0, 0.0, 0.0], (6, 1)), rph, np.zeros((6, 3)), sensor_type="increment")
    np.testing.assert_array_equal(df.iloc[0].to_numpy(), df.iloc[1].to_numpy())  # pyins repeats its first increment
    df.to_csv(tmp_path / "i.csv")
    imu, meta = read_layout(tmp_path / "i.csv", "pyins-increment")
    np.testing.assert_array_equal(imu.t, t[1:])
    np.testing.assert_array_equal(imu.gyro[0], df[["gyro_x", "gyro_y", "gyro_z"]].to_numpy()[1:] @ P_PYINS)
    np.testing.assert_array_equal(imu.accel[0], df[["accel_x", "accel_y", "accel_z"]].to_numpy()[1:] @ P_PYINS)
    assert meta["skipped_rows"] == 1 and imu.t0 == pytest.approx(0.0)


def test_coarse_alignment_of_a_pyins_file_gives_pyins_attitude(tmp_path, record_property):
    from pyins import sim

    lat, lon, h, rph = 40.0, 116.0, 50.0, (3.0, -5.0, 120.0)  # pyins: roll, pitch, heading (deg, clockwise)
    n = 601
    t = np.arange(n) / 10.0
    _, df = sim.generate_imu(t, np.tile([lat, lon, h], (n, 1)), np.tile(rph, (n, 1)), np.zeros((n, 3)),
                             sensor_type="rate")
    df.to_csv(tmp_path / "static.csv")
    site = Site.from_degrees(lat, lon, h)
    truth = _c_bn_from_pyins(rph)[0]
    imu, _ = read_layout(tmp_path / "static.csv", "pyins")
    est = CoarseAligner().align(imu, site).C_bn_final[0]
    err = np.linalg.norm(attitude.misalignment(est, truth))
    angles = attitude.dcm_to_euler(est) / DEG
    record_property("coarse_error_arcsec", err / ARCSEC)
    assert err < 1e-3 * ARCSEC  # a perfect static record: TRIAD is exact up to rounding
    np.testing.assert_allclose(angles, [-5.0, 3.0, -120.0], atol=1e-6)
    wrong, _ = read_layout(tmp_path / "static.csv", dataclasses.replace(BUILTIN_LAYOUTS["pyins"], axes="RFU"))
    assert np.linalg.norm(attitude.misalignment(CoarseAligner().align(wrong, site).C_bn_final[0], truth)) > 1.0


# ------------------------------------------------------------------------------------------------ bad input


def _one_line(exc_info, *words):
    msg = str(exc_info.value)
    assert "\n" not in msg, msg
    for w in words:
        assert w in msg, (w, msg)
    return msg


def _kfgins_rows(n=5, cols=7):
    return "".join(" ".join(str(v) for v in [456300 + 0.005 * k, 1e-6, 2e-6, 3e-6, 1e-3, 2e-3, 0.049][:cols]) + "\n"
                   for k in range(n))


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


# ---------------------------------------------------------------------------------------- docs/layouts.md

DOC = (Path(__file__).parents[1] / "docs" / "layouts.md").read_text()


def _table_rows(first_header):
    """First cells and whole rows of the markdown table whose header row starts with ``| first_header |``."""
    lines = DOC.splitlines()
    start = next(i for i, s in enumerate(lines[:-1])
                 if s.startswith(f"| {first_header} |") and lines[i + 1].startswith("|---"))
    rows = []
    for s in lines[start + 2:]:
        if not s.startswith("|"):
            break
        rows.append(s)
    return {row.split("|")[1].strip().strip("`"): row for row in rows}


def test_doc_documents_every_key_axes_and_builtin(tmp_path):
    from fusionbench.files.layouts import LAYOUT_KEYS

    assert sorted(_table_rows("key")) == sorted(LAYOUT_KEYS)
    assert sorted(_table_rows("name")) == sorted(BUILTIN_LAYOUTS)
    axes = _table_rows("`axes`")
    assert sorted(axes) == sorted(AXES)
    for name, row in axes.items():
        shown = row.split("`")[-2] if name != "NED-style" else None
        if shown:
            np.testing.assert_array_equal(np.array(ast.literal_eval(shown), dtype=float), AXES[name])


def test_doc_example_loads(tmp_path):
    example = DOC.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "my.toml").write_text(example)
    lay = load_layout(tmp_path / "my.toml")
    assert (lay.name, lay.delimiter, lay.time, lay.gyro, lay.time_unit, lay.gyro_unit, lay.accel_unit, lay.axes) == (
        "my-logger", ";", "ms", ("wx", "wy", "wz"), "ms", "deg/s", "g", "FLU")
    p = tmp_path / "log.txt"
    p.write_text("// bench logger\nms;wx;wy;wz;fx;fy;fz;temp\n0;0;0;90;1;0;0;20\n10;0;0;90;1;0;0;20\n")
    imu, _ = read_layout(p, lay)
    np.testing.assert_allclose(imu.t, [0.0, 0.01], rtol=0, atol=1e-18)
    np.testing.assert_allclose(imu.gyro[0, 0], [0.0, 0.0, 90 * DEG], rtol=1e-15)  # up is up in FLU
    np.testing.assert_allclose(imu.accel[0, 0], [0.0, G0, 0.0], rtol=1e-15)  # FLU x is forward
