"""The ranges, defaults and rules docs/scenarios.md states are those the scenario parsers enforce: each bound and
"required" of the tables probed, each literal default compared with leaving the key out, and the rules in prose."""

import copy
import re
import tomllib

import pytest

from fusionbench.bench import scenarios
from tests.docs_helpers import SECTIONS, _rows


# -------------------------------------------------------------------------------- ranges and defaults, probed

SCENARIO = {"name": "probe", "duration_s": 600.0, "rate_hz": 100.0, "site": {"lat_deg": 34.0}}
PLATFORM = {"name": "probe", "experiment": "platform-rolling", "duration_s": 20.0, "rate_hz": 5.0,
            "site": {"lat_deg": 34.0}, "methods": ["rolling-ekf"],
            "platform": {"scheme": [{"axis": "south", "rate_dps": 0.1, "duration_s": 20.0}]}}
MATRIX = {"name": "probe", "experiment": "conformance", "duration_s": 60.0, "rate_hz": 10.0,
          "conformance": {"efficiency": {"default": 3.0}},
          "condition": [{"name": "c", "base": "static", "lat_deg": 34.0, "heading_deg": 0.0, "imu": "navigation"}]}


def _place(data, path, table):
    """Put (merge) ``table`` at ``path`` of ``data``, creating the tables and one-element lists on the way."""
    node = data
    for step, nxt in zip(path, path[1:]):
        node = node[step] if isinstance(step, int) else node.setdefault(step, [{}] if isinstance(nxt, int) else {})
    last = path[-1]
    node[last] = {**(node[last] if isinstance(last, int) else node.get(last, {})), **table}
    return data


def _target(data, path):
    node = data
    for step in path:
        node = node[step]
    return node


#: heading of a table in the page -> (base file, path of the table in it, the table's starting content)
PROBED = {
    "Top-level keys": (SCENARIO, (), {}),
    "`[quick]` and what `--quick` changes": (SCENARIO, ("quick",), {}),
    "`[site]`": (SCENARIO, ("site",), {"lat_deg": 34.0}),
    "`[attitude]`": (SCENARIO, ("attitude",), {}),
    "`[motion]`": (SCENARIO, ("motion",), {"disturbance_rms_mps": 0.01}),  # band and seed are read with it
    "Segments": (SCENARIO, ("motion", "segments", 0), {"accel_mps2": [0.1, 0.0, 0.0], "duration_s": 10.0}),
    "A drive": (SCENARIO, ("motion",), {"legs": [{"duration_s": 10.0}]}),
    "Legs": (SCENARIO, ("motion", "legs", 0), {"duration_s": 10.0}),
    "`[aiding]`": (SCENARIO, ("aiding",), {"rate_hz": 10.0, "velocity_sigma_mps": 0.05}),
    "`[imu]`": (SCENARIO, ("imu",), {}),
    "Overrides in datasheet units": (SCENARIO, ("imu",), {}),
    "Noise schedules": (SCENARIO, ("imu", "schedule", 0), {"start_s": 1.0, "end_s": 2.0, "factor": 1.0}),
    "`[vref]`": (SCENARIO, ("vref",), {}),
    "`[init]`": (SCENARIO, ("init",), {}),
    "`[metrics]`": (SCENARIO, ("metrics",), {}),
    "`[variants.NAME]`: a method with options": (SCENARIO, ("variants", "v"), {"method": "coarse"}),
    "`[paper]`": (SCENARIO, ("paper",), {}),
    "Platform self-calibration: `[platform]`": (PLATFORM, ("platform",), {}),
    "Scheme segments": (PLATFORM, ("platform", "scheme", 0), {"axis": "south", "rate_dps": 0.1, "duration_s": 20.0}),
    "Conformance: top-level keys": (MATRIX, (), {}),
    "Conformance `[quick]`": (MATRIX, ("quick",), {}),
    "Conformance `[metrics]`": (MATRIX, ("metrics",), {}),
    "`[conformance]`": (MATRIX, ("conformance",), {}),
    "`[[condition]]`": (MATRIX, ("condition", 0), MATRIX["condition"][0]),
    "The aiding of a moving condition": (MATRIX, ("condition", 0), {**MATRIX["condition"][0], "base": "drive"}),
}
_NUM = r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?"


def _parse(data):
    return scenarios._parse_any(data, "probe.toml")  # what load() does with a file's mapping


def _cases():
    """(heading, key, default cell, range cell) of every row of the probed tables."""
    out = []
    for head in PROBED:
        assert head in SECTIONS, f"docs/scenarios.md lost its section {head!r}"
        for key, cells in _rows(SECTIONS[head]).items():
            assert len(cells) == 5, f"{head}: row {key!r} should have type, unit, default, range, meaning"
            out.append((head, key, cells[2], cells[3]))
    return out


CASES = _cases()
_RANGE = rf"({_NUM}) to ({_NUM})|≥ ({_NUM})"


def _params(keep):
    return [pytest.param(*c, id=f"{c[0]}:{c[1]}") for c in CASES if keep(c)]


def _probe_base(head):
    base, path, table = PROBED[head]
    data = copy.deepcopy(base)
    return _place(data, path, copy.deepcopy(table)) if path else data


def _probe_data(head, key, value=None, drop=False):
    data = _probe_base(head)
    node = _target(data, PROBED[head][1])
    if drop:
        del node[key]
    else:
        node[key] = value
    return data


def test_every_probed_table_has_rows():
    assert {head for head, *_ in CASES} == set(PROBED)
    assert len(CASES) > 80


def test_the_probe_bases_are_valid():
    for head in PROBED:
        _parse(_probe_base(head))


@pytest.mark.parametrize("head, key, default, rng", _params(lambda c: re.fullmatch(_RANGE, c[3])))
def test_documented_range_is_enforced(head, key, default, rng):
    m = re.fullmatch(_RANGE, rng)
    lo = float(m.group(1) or m.group(3))
    hi = float(m.group(2)) if m.group(2) else None
    for v in [lo] + ([hi] if hi is not None else []):
        _parse(_probe_data(head, key, v))  # the bounds are accepted
    beyond = [lo - max(abs(lo) * 0.01, 1e-9)] + ([hi + max(abs(hi) * 0.01, 1e-9)] if hi is not None else [])
    for v in beyond:
        with pytest.raises(scenarios.ScenarioError, match=re.escape(key)):
            _parse(_probe_data(head, key, v))


@pytest.mark.parametrize("head, key, default, rng", _params(lambda c: c[2] == "required"))
def test_documented_required_key_cannot_be_left_out(head, key, default, rng):
    with pytest.raises(scenarios.ScenarioError, match=re.escape(key)):
        _parse(_probe_data(head, key, drop=True))


@pytest.mark.parametrize("head, key, default, rng", _params(lambda c: re.fullmatch(r"`[^`]+`", c[2])))
def test_documented_default_is_the_parsers(head, key, default, rng):
    value = tomllib.loads(f"v = {default[1:-1]}")["v"]
    absent = _probe_base(head)
    _target(absent, PROBED[head][1]).pop(key, None)
    assert repr(_parse(_probe_data(head, key, value))) == repr(_parse(absent))


# ---------------------------------------------------------------------------------- rules stated in prose


def test_kind_inference_as_documented():
    seg = {"segments": [{"accel_mps2": [0.1, 0.0, 0.0], "duration_s": 10.0}]}
    assert _parse(SCENARIO).kind == "alignment"
    assert _parse({**SCENARIO, "motion": {"disturbance_rms_mps": 0.01}}).kind == "alignment"
    assert _parse({**SCENARIO, "motion": seg}).kind == "moving-alignment"
    assert _parse({**SCENARIO, "motion": seg, "metrics": {"rmse_window_s": [0.0, 10.0]}}).kind == "navigation"
    assert _parse(PLATFORM).kind == "calibration"
    assert _parse(MATRIX).kind == "conformance"
    assert _parse({**SCENARIO, "motion": seg, "kind": "alignment"}).kind == "alignment"  # taken as it is


def test_quick_defaults_as_documented():
    assert _parse({**SCENARIO, "runs": 10}).sized(True) == (120.0, 3)
    assert _parse({**SCENARIO, "duration_s": 60.0, "runs": 2}).sized(True) == (60.0, 2)
    assert _parse({**MATRIX, "runs": 10}).sized(True) == (60.0, 3)


def test_three_vectors_take_one_number_platform_angles_do_not():
    scn = _parse({**SCENARIO, "vref": {"sigma_mps": 0.01}, "init": {"misalignment_deg": 3}})
    assert scn.vref_spec.sigma == (0.01,) * 3 and scn.init_misalignment == (3.0,) * 3
    with pytest.raises(scenarios.ScenarioError, match="initial_angles_deg"):
        _parse(_place(copy.deepcopy(PLATFORM), ("platform",), {"initial_angles_deg": 2.0}))
