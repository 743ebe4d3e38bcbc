"""Property tests of the boundary (issue 14): whatever a file or a scenario mapping holds, the readers and the
scenario parser either return a valid result or raise their one-line error naming the file; never another
exception, never a result with non-finite samples. Whatever shapes the settling metrics are given, they return one
value per history or one line naming the argument (issue 24)."""

import io
import os
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusionbench.bench import scenarios
from fusionbench.files.imufiles import IMUFileError, read_imu
from fusionbench.scoring import metrics

#: Examples per property (FUZZ_EXAMPLES=2000 for a deeper search than the suite's).
EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "60"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    """A folder for the files the properties write (pytest's, so that it is removed with its other folders)."""
    return tmp_path_factory.mktemp("fuzz")


def _read(folder, name, payload):
    path = os.path.join(folder, name)
    with open(path, "wb") as fh:
        fh.write(payload)
    try:
        imu, meta = read_imu(path)
    except IMUFileError as exc:
        msg = str(exc)
        assert msg.startswith(path) and "\n" not in msg, msg
        return None
    assert np.isfinite(imu.t).all() and np.isfinite(imu.gyro).all() and np.isfinite(imu.accel).all()
    assert np.all(np.diff(imu.t) > 0)
    return imu


_cell = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**25, 10**25),
                  st.text(alphabet="0123456789.-+eEnaif ", max_size=8))


@SETTINGS
@given(st.lists(st.lists(_cell, min_size=0, max_size=8), min_size=0, max_size=12),
       st.sampled_from(["t,gx,gy,gz,ax,ay,az", "t,gx,gy,gz,ax,ay", "", "time,a,b"]))
def test_any_csv_is_read_or_refused_in_one_line(fuzz_dir, rows, header):
    text = header + "\n" + "\n".join(",".join(str(c) for c in r) for r in rows) + "\n"
    _read(fuzz_dir, "fuzz.csv", text.encode())


@SETTINGS
@given(st.binary(max_size=300))
def test_any_bytes_as_any_format_are_read_or_refused_in_one_line(fuzz_dir, payload):
    for name in ("fuzz.csv", "fuzz.imu", "fuzz.npz"):
        _read(fuzz_dir, name, payload)


_arrays = st.one_of(
    st.builds(lambda n, v: np.full((n, 3), v), st.integers(0, 5), st.floats(allow_nan=True, allow_infinity=True)),
    st.builds(lambda n: np.arange(n, dtype=float) * 0.01, st.integers(0, 5)),
    st.builds(lambda n: np.zeros((n, 2)), st.integers(0, 4)),
    st.just(np.array(["a", "b"])), st.just(np.zeros((3, 3), dtype=complex)), st.just(np.array(7)),
)


@SETTINGS
@given(st.dictionaries(st.sampled_from(["t", "gyro", "accel", "x"]), _arrays, max_size=4))
def test_any_npz_arrays_are_read_or_refused_in_one_line(fuzz_dir, arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    _read(fuzz_dir, "fuzz.npz", buf.getvalue())


@SETTINGS
@given(st.lists(st.lists(st.one_of(st.integers(-10**20, 10**20), st.floats(), st.text("0123456789.-e", max_size=6)),
                         min_size=0, max_size=7), min_size=0, max_size=8))
def test_any_psins_text_is_read_or_refused_in_one_line(fuzz_dir, rows):
    head = "0 0 0 0 0 0\n34 108 100 0 10 9.78\n0.01 0.01 0.01 10 10 10\n"
    _read(fuzz_dir, "fuzz.imu", (head + "\n".join(" ".join(str(c) for c in r) for r in rows) + "\n").encode())


def test_a_zip_that_is_not_an_npz_is_refused(tmp_path):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("t.npy", b"not an array")
    assert _read(tmp_path, "zip.npz", buf.getvalue()) is None


_values = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(),
                                 st.text(max_size=6)),
                       lambda inner: st.one_of(st.lists(inner, max_size=4),
                                               st.dictionaries(st.text(max_size=6), inner, max_size=3)), max_leaves=8)
_BASE = {"name": "f", "duration_s": 30.0, "rate_hz": 50.0, "runs": 2, "methods": ["coarse"], "site": {"lat_deg": 34.0}}
_KEYS = {
    "": ["duration_s", "rate_hz", "runs", "methods", "kind", "experiment", "name", "zzz"],
    "site": ["lat_deg", "lon_deg", "height_m"],
    "attitude": ["pitch_deg", "roll_deg", "heading_deg", "sway_amplitude_deg", "sway_frequency_hz", "sway_phase_deg"],
    "motion": ["start_s", "segments", "disturbance_rms_mps", "disturbance_band_hz"],
    "imu": ["preset", "gyro_bias_dph", "arw_dpsh", "schedule", "random"],
    "vref": ["sigma_mps", "schedule"],
    "init": ["misalignment_deg"],
    "metrics": ["settling_band_arcmin", "jump_window_s", "rmse_window_s", "amplitude_windows_s", "compare"],
    "quick": ["duration_s", "runs"],
    "paper": ["reference", "note", "settling_time_s"],
}


@settings(max_examples=5 * EXAMPLES, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(sorted(_KEYS)), st.integers(0, 9), _values), min_size=1, max_size=4))
def test_any_scenario_mapping_is_parsed_or_refused_in_one_line(edits):
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in _BASE.items()}
    for table, i, value in edits:
        keys = _KEYS[table]
        key = keys[i % len(keys)]
        if table:
            if not isinstance(data.get(table), dict):
                data[table] = {}
            data[table][key] = value
        else:
            data[key] = value
    try:
        scn = scenarios._parse_any(data, "fuzz.toml")
    except scenarios.ScenarioError as exc:
        assert str(exc).startswith("fuzz.toml") and "\n" not in str(exc), str(exc)
        return
    assert scn.name and scn.methods


@pytest.mark.parametrize("n", [0, 1])
def test_an_empty_or_one_sample_file_is_refused(tmp_path, n):
    p = tmp_path / "short.csv"
    p.write_text("t,gx,gy,gz,ax,ay,az\n" + "0.01,0,0,0,0,0,9.8\n" * n)
    with pytest.raises(IMUFileError, match="short.csv"):
        read_imu(p)


_shape = st.lists(st.integers(0, 4), min_size=0, max_size=3).map(tuple)


def _fits(shape, onto):
    """Whether an array of ``shape`` broadcasts to ``onto`` without widening it."""
    return len(shape) <= len(onto) and all(a in (1, b) for a, b in zip(shape[::-1], onto[::-1]))


@SETTINGS
@given(_shape, _shape, _shape, _shape)
def test_any_settling_shapes_give_one_value_per_history_or_one_line(t_shape, x_shape, band_shape, target_shape):
    t, x = np.arange(np.prod(t_shape, dtype=int), dtype=float).reshape(t_shape), np.zeros(x_shape)
    band, target = np.ones(band_shape), np.zeros(target_shape)
    histories = len(x_shape) >= 1 and x_shape[-1] >= 1 and _fits(band_shape, x_shape) and _fits(target_shape, x_shape)
    for call, args, ok in ((metrics.settling_time, (t, x, band, target), histories and t_shape == x_shape[-1:]),
                           (metrics.settled, (x, band, target), histories)):
        try:
            out = call(*args)
        except ValueError as exc:
            msg = str(exc)
            field = msg.split(":")[0]
            assert not ok and "\n" not in msg and "expected" in msg and "found shape" in msg, msg
            assert field in {f"{call.__name__} {a}" for a in ("t", "x", "band", "target")}, msg
            continue
        assert ok and np.shape(out) == x_shape[:-1], (call.__name__, t_shape, x_shape, np.shape(out))
