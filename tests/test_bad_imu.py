"""Bad IMU data at the boundary (issue 14): the container, the readers and writers, the simulator's arguments.
Each defect is one ValueError line naming the field or file, what was expected and what was found."""

import numpy as np
import pytest

from fusionbench.files.imufiles import IMUFileError, read_imu, write_npz, write_psins
from fusionbench.simulation import imu, trajectory as tj
from fusionbench.simulation.imudata import MAX_RATE_RADPS, MAX_SPECIFIC_FORCE_MPS2, IMUData

N = 200
T = np.arange(1, N + 1) * 0.01
GYRO = np.tile([1e-5, 2e-5, 3e-5], (N, 1))
ACCEL = np.tile([0.0, 0.0, 9.8], (N, 1))


def _one_line(exc, *words):
    msg = str(exc.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


@pytest.mark.parametrize("field, t, gyro, accel, words", [
    ("t", T[::-1], GYRO, ACCEL, ["IMUData t", "not strictly increasing", "sample 1"]),
    ("t", np.r_[np.nan, T[1:]], GYRO, ACCEL, ["IMUData t", "non-finite", "sample 0"]),
    ("t", np.r_[T[:100], T[100:] + 0.005], GYRO, ACCEL, ["IMUData t", "non-uniform time step", "sample 100",
                                                        "fusionbench.files.resample.uniform_imu"]),
    ("gyro", T, GYRO + 1j, ACCEL, ["IMUData gyro", "expected real numbers", "complex"]),
    ("gyro", T, np.where(np.arange(N)[:, None] == 7, np.nan, GYRO), ACCEL, ["IMUData gyro", "non-finite", "sample 7"]),
    ("gyro", T, GYRO + 1e6, ACCEL, ["IMUData gyro", f"beyond the {MAX_RATE_RADPS:g} rad/s", "sample 0, axis x"]),
    ("accel", T, GYRO, ACCEL * 1e300, ["IMUData accel", f"beyond the {MAX_SPECIFIC_FORCE_MPS2:g} m/s^2", "axis z"]),
    ("accel", T, GYRO, ACCEL.astype(str), ["IMUData accel", "expected real numbers"]),
])
def test_the_container_refuses_what_no_imu_records(field, t, gyro, accel, words):
    with pytest.raises(ValueError) as exc:
        IMUData(t, gyro, accel, "rate")
    _one_line(exc, *words)


def test_an_increments_range_is_its_rate_over_one_interval():
    ok = IMUData(T, GYRO * 0.01, ACCEL * 0.01, "increment")  # 9.8 m/s^2 over 10 ms
    assert ok.rates()[1][0, 0, 2] == pytest.approx(9.8)
    with pytest.raises(ValueError) as exc:  # 0.5 rad in 10 ms: 50 rad/s... is fine; 2 rad in 10 ms is not
        IMUData(T, np.full((N, 3), 2.0), ACCEL * 0.01, "increment")
    _one_line(exc, "IMUData gyro", "200 rad/s", "as a rate")
    IMUData(T, np.full((N, 3), 0.5), ACCEL * 0.01, "increment")


def test_files_with_values_beyond_an_imus_range_are_refused_with_their_row(tmp_path):
    p = tmp_path / "big.csv"  # degrees per second read as rad/s would be 57 times too big; 1e6 is counts
    rows = [f"{t:.2f},{1e6 if k == 4 else 1e-5},0,0,0,0,9.8" for k, t in enumerate(T)]
    p.write_text("t,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n")
    with pytest.raises(IMUFileError) as exc:
        read_imu(p)
    _one_line(exc, str(p), "row 4", "column 'gx'", "rad/s")
    np.savez(tmp_path / "c.npz", t=T, gyro=GYRO + 1j, accel=ACCEL)
    with pytest.raises(IMUFileError) as exc:
        read_imu(tmp_path / "c.npz")
    _one_line(exc, "c.npz", "array 'gyro'", "complex", "expected real numbers")
    np.savez(tmp_path / "o.npz", t=np.array([object()], dtype=object), gyro=GYRO, accel=ACCEL)
    with pytest.raises(IMUFileError) as exc:
        read_imu(tmp_path / "o.npz")
    _one_line(exc, "o.npz", "object (pickled) arrays", "never unpickles")


def test_a_psins_file_with_absurd_counts_is_refused_not_aligned(tmp_path):
    p = tmp_path / "x.imu"
    write_psins(p, IMUData(T, GYRO, ACCEL, "rate"), [0.0, 0.0, 0.0], lat=0.6)
    lines = p.read_text().splitlines()
    k = next(i for i, s in enumerate(lines) if s and not s.startswith("%")) + 3  # the first sample row
    for count, words in (("9000000000000000000", ["sample row 0", "rad/s", "as a rate"]),
                         ("99999999999999999999", ["sample row 0", "not an integer count (64-bit)"])):
        lines2 = list(lines)
        lines2[k] = " ".join([count] + lines[k].split()[1:])
        p.write_text("\n".join(lines2) + "\n")
        with pytest.raises(IMUFileError) as exc:
            read_imu(p)
        _one_line(exc, str(p), *words)


def test_writers_refuse_what_their_reader_would_refuse(tmp_path):
    data = IMUData(T, GYRO, ACCEL, "rate")
    with pytest.raises(ValueError) as exc:
        write_psins(tmp_path / "x.imu", data, [0.0, 0.0, 0.0], lat=float("nan"))
    _one_line(exc, "write_psins lat", "nan")
    with pytest.raises(ValueError) as exc:
        write_psins(tmp_path / "x.imu", data, [0.0, 0.0], lat=0.6)
    _one_line(exc, "write_psins attitude0", "3 finite numbers")
    assert not list(tmp_path.iterdir())  # nothing written
    with pytest.raises(FileNotFoundError) as exc:
        write_npz(tmp_path / "no" / "x.npz", data)
    _one_line(exc, str(tmp_path / "no" / "x.npz"), "folder", "does not exist")
    assert ".tmp" not in str(exc.value)


#: Jittered stamps (5 % of the 10 ms step) with one defect at sample 40: (the defect, its time, what the line says).
_JIT = T + 0.0005 * np.sin(7.0 * np.arange(N))
BAD_TIMES = [("gap", np.r_[_JIT[:40], _JIT[41:], _JIT[-1] + 0.01], ["gap in time", "about 1 sample(s) missing"]),
             ("duplicate", np.r_[_JIT[:40], _JIT[39], _JIT[41:]], ["time not strictly increasing", "a duplicate"]),
             ("reversal", np.r_[_JIT[:40], _JIT[39] - 0.002, _JIT[41:]], ["time not strictly increasing",
                                                                            "a reversal"]),
             ("short", np.r_[_JIT[:40], _JIT[39] + 0.002, _JIT[41:]], ["time step too short", "times the nominal step"])]


@pytest.mark.parametrize("what, t, words", BAD_TIMES, ids=[b[0] for b in BAD_TIMES])
@pytest.mark.parametrize("fmt", ["csv", "npz", "imu"])
def test_a_gap_a_duplicate_or_a_reversal_is_one_line_naming_the_row(tmp_path, fmt, what, t, words):
    """Jitter is read at the actual times; these are not. CSV rows and NPZ indices count from 0; a PSINS .imu
    carries its times as the 7-column variant's dither (us) after t0 = 0 and dt = 10 ms."""
    p = tmp_path / f"bad.{fmt}"
    if fmt == "csv":
        p.write_text("t,gx,gy,gz,ax,ay,az\n" + "".join(f"{v:.17g},1e-5,2e-5,3e-5,0,0,9.8\n" for v in t))
        where = "row 40 (line 42)"
    elif fmt == "npz":
        np.savez(p, t=t, gyro=GYRO, accel=ACCEL)
        where = "index 40"
    else:
        dither = np.diff(np.rint((t - T) * 1e6).astype(int), prepend=0)
        head = "0 0 0 0 0 0 0\n34 108 0 0 10 9.78 0\n0.01 0.01 0.01 10 10 10 0\n"
        p.write_text(head + "".join(f"1 2 3 0 0 9800 {d}\n" for d in dither))
        where = "sample row 40 (line 44) (time from t0, dt and the dither column)"
    with pytest.raises(IMUFileError) as exc:
        read_imu(p)
    _one_line(exc, str(p), f"at {where}", *words)
    good = {"csv": lambda: p.write_text("t,gx,gy,gz,ax,ay,az\n" + "".join(f"{v:.17g},1e-5,2e-5,3e-5,0,0,9.8\n"
                                                                           for v in _JIT)),
            "npz": lambda: np.savez(p, t=_JIT, gyro=GYRO, accel=ACCEL)}
    if fmt in good:  # the same stamps without the defect: jitter, read onto a uniform grid
        good[fmt]()
        data, meta = read_imu(p)
        assert meta["resampled"] and data.kind == "increment" and data.samples == N - 1


@pytest.mark.parametrize("kwargs, words", [
    ({"dt": 0.0}, ["simulate dt", "positive"]), ({"dt": -0.01}, ["simulate dt", "-0.01"]),
    ({"dt": 0.01, "runs": 0}, ["simulate runs", "found 0"]), ({"dt": 0.01, "duration": -5.0}, ["simulate duration"]),
])
def test_the_simulator_names_a_bad_argument(kwargs, words):
    tr = tj.Trajectory(0.6, 0.0, 0.0, duration=10.0)
    with pytest.raises(ValueError) as exc:
        imu.simulate(tr, imu.PRESETS["tactical"], **kwargs)
    _one_line(exc, *words)


@pytest.mark.parametrize("kwargs, words", [({"duration": -5.0}, ["Trajectory duration", "-5"]),
                                           ({"lon": float("nan")}, ["Trajectory lon", "nan"]),
                                           ({"h": 1e9}, ["Trajectory h"])])
def test_a_trajectory_names_a_bad_argument(kwargs, words):
    with pytest.raises(ValueError) as exc:
        tj.Trajectory(**{"lat": 0.6, "lon": 0.0, "h": 0.0, **kwargs})
    _one_line(exc, *words)


@pytest.mark.parametrize("accel, words", [(0.0, "found 0 m/s^2"), (1.0, "found 1 m/s^2")])
def test_align_refuses_a_record_whose_specific_force_is_not_gravity(tmp_path, capsys, accel, words):
    # all-zero accelerometers (a dead channel) or specific force in g: no attitude, one line, exit 2
    from fusionbench.cli import main

    p = tmp_path / "g.csv"
    rows = [f"{t:.2f},1e-5,4e-5,3e-5,0,0,{accel}" for t in T]
    p.write_text("t,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n")
    assert main(["align", str(p), "--lat", "34", "--json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(p) in err and "mean specific force" in err and words in err, err
