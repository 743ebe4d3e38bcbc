"""The TOML examples of docs/scenarios.md load (complete files with ``scenarios.load``, fragments merged into the
minimal example), their methods and variants can be built, and they parse to what the page says about them."""

import re
import tomllib

import pytest

from fusionbench.bench import scenarios
from fusionbench.simulation import imu
from tests.docs_helpers import DOC


def _toml_blocks():
    return re.findall(r"```toml\n(.*?)```", DOC, re.S)


def _examples():
    """``{name: text}`` of the complete example files (a top-level ``name``) of the page."""
    out = {}
    for text in _toml_blocks():
        data = tomllib.loads(text)
        if "name" in data:
            out[data["name"]] = text
    return out


def _fragments():
    return [t for t in _toml_blocks() if "name" not in tomllib.loads(t)]


# ---------------------------------------------------------------------------------------- the examples

#: What the page says each complete example parses to.
EXPECTED = {
    "my-static": dict(kind="alignment", sized=((300.0, 10), (120.0, 3))),
    "my-gyro-jump": dict(kind="alignment", sized=((600.0, 20), (600.0, 3))),
    "my-rolling": dict(kind="calibration", sized=((1800.0, 4), (600.0, 2))),
    "my-matrix": dict(kind="conformance", sized=((300.0, 20), (300.0, 3))),
}


def _load(tmp_path, name):
    path = tmp_path / f"{name}.toml"
    path.write_text(_examples()[name])
    return scenarios.load(path)


def test_every_example_is_valid_toml_and_expected():
    for text in _toml_blocks():
        tomllib.loads(text)
    assert set(_examples()) == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_loads_as_the_page_says(tmp_path, name):
    scn = _load(tmp_path, name)
    want = EXPECTED[name]
    assert scn.name == name
    assert scn.kind == want["kind"]
    assert (scn.sized(False), scn.sized(True)) == want["sized"]
    if scn.experiment == "alignment":
        for m in scn.methods:
            scn.method(m)
    elif scn.experiment == "platform-rolling":
        for m in scn.methods:
            scn.method(m)


def test_minimal_example_is_what_the_page_says(tmp_path):
    scn = _load(tmp_path, "my-static")
    assert "kind" not in scn.raw  # inferred
    assert scn.site.lon == 0.0 and scn.site.h == 0.0
    assert scn.imu_spec == imu.PRESETS["navigation"]  # noisy: random = true
    assert scn.init_misalignment is None and not any(scn.vref_spec.sigma)
    assert scn.euler_mean[:2] == (0.0, 0.0)


def test_noise_jump_example_is_what_the_page_says(tmp_path):
    scn = _load(tmp_path, "my-gyro-jump")
    assert scn.imu_spec.schedules == (imu.NoiseSchedule(200.0, 400.0, 100.0, ("gyro",)),)
    assert (scn.feature("jump").start_s, scn.feature("jump").end_s) == (200.0, 400.0)
    assert scn.feature("jump").end_s < scn.sized(True)[0]  # the jump window inside the --quick record
    assert scn.vref_spec.sigma == (0.01, 0.01, 0.01)
    assert scn.variants["akf-fast"] == {"method": "akf", "b": 0.95}


def test_platform_example_is_what_the_page_says(tmp_path):
    scn = _load(tmp_path, "my-rolling")
    assert sum(s.duration for s in scn.platform.scheme.segments) == scn.duration_s
    quick = scn.platform.scaled(scn.sized(True)[0])
    assert sum(s.duration for s in quick.scheme.segments) == 600.0
    assert quick.readout_s == 60.0  # capped at a tenth of the quick duration


def test_matrix_example_is_what_the_page_says(tmp_path):
    matrix = _load(tmp_path, "my-matrix")
    assert [c.name for c in matrix.conditions] == ["static-45s", "table1-60n"]
    assert matrix.threshold("kf") == 1.5 and matrix.threshold("coarse-i0") == 3.0


@pytest.mark.parametrize("text", _fragments(), ids=lambda t: t.splitlines()[0])
def test_fragment_parses_in_the_minimal_example(text):
    data = {**tomllib.loads(_examples()["my-static"]), **tomllib.loads(text)}
    scn = scenarios.parse(data, "fragment.toml")
    for m in scn.methods:
        scn.method(m)
    if "rmse_window_s" in data.get("metrics", {}):
        assert scn.kind == "navigation"
