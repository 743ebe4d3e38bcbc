"""Tests of fusionbench.files.layouts: other people's IMU log layouts read into fusionbench's frames and units.

One swaying recording (fusionbench's simulator, perfect IMU) is written in each layout by this file's own writer,
which takes the file axes from their letter definitions (never from the module's matrices) and the units from
fusionbench.simulation.units. Read back, the arrays must equal the original to float precision, and the strapdown of
them from the true initial state must reach the true attitude and velocity at the last sample within bounds that a
read one sample late, or with a wrong axis, exceeds a hundred times over (both reads are made and shown to fail).
Real pyins files, written by pyins itself, go through the pyins layouts: a sway through the strapdown, a static
record through the analytic coarse alignment. Bad files and format files: tests/test_layouts_errors.py; the axes
and docs/layouts.md: tests/test_layouts_definitions.py.
"""

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fusionbench.files.imufiles import read_csv, write_csv
from fusionbench.files.layouts import BUILTIN_LAYOUTS, layout_from_name_or_file, read_layout
from fusionbench.methods.aligner import Site
from fusionbench.methods.coarse import CoarseAligner
from fusionbench.simulation import attitude, trajectory as tj
from fusionbench.simulation.imu import IMUSpec, simulate
from fusionbench.simulation.imudata import IMUData
from fusionbench.simulation.strapdown import NavState, Strapdown
from fusionbench.simulation.units import ARCSEC, DEG, DEG_PER_H, DEG_PER_S, G0, MICROSECOND, MILLISECOND, NANOSECOND
from tests.independent import P as P_PYINS
from tests.layouts_helpers import DIRS, LETTERS

LAT, LON, H = 34 * DEG, 108 * DEG, 450.0
DT = 0.01
N = 3130  # 31.3 s: the sway's rates at the end differ from those at the start, so a time shift shows
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
