"""docs/scenarios.md is the scenario file format as the parsers read it; these tests keep the two in step.

* every key a parser accepts is documented, with a table row (the parsers' key sets, and every set of key names
  written inline in a parser's source), and every documented key is one the parsers accept;
* the ranges and defaults in the tables are those the parsers enforce (each numeric bound is probed: the bound is
  accepted, just beyond it is refused with a message naming the key; a literal default gives the same result as
  leaving the key out; a "required" key cannot be left out);
* the IMU preset table and the platform coefficient groups carry the figures of the code;
* the TOML examples load (complete files with ``scenarios.load``, fragments merged into the minimal example), their
  methods and variants can be built, and they parse to what the page says about them;
* every key of every built-in scenario is documented, and every built-in variant's options are constructor options.
"""

import ast
import copy
import inspect
import re
import tomllib
from importlib import resources
from pathlib import Path

import pytest

from baselines.rolling import experiment as rolling_experiment
from baselines.rolling import model as rolling_model
from baselines.rolling import scheme as rolling_scheme
from baselines.rolling import spec as rolling_spec
from fusionbench.bench import conformance_file, scenarios
from fusionbench.bench.experiment import available_experiments, load_experiment
from fusionbench.bench.scenarios import tables as scenario_tables
from fusionbench.features import compare as feat_compare, jump as feat_jump, paper as feat_paper, windows as feat_windows
from fusionbench.methods import aligner
from fusionbench.simulation import imu, units

ROOT = Path(__file__).parents[1]
DOC_PATH = ROOT / "docs" / "scenarios.md"
DOC = DOC_PATH.read_text()
PARSERS = (scenarios, scenario_tables, imu, conformance_file, rolling_spec, feat_jump, feat_windows, feat_compare,
           feat_paper)


# ----------------------------------------------------------------------------------------------- the page, read


def _sections():
    """``{heading text: body}`` of every heading (any level), code blocks skipped for headings."""
    out, head, body, fenced = {}, None, [], False
    for line in DOC.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        m = None if fenced else re.match(r"#{1,6} (.*)", line)
        if m:
            if head is not None:
                out[head] = "\n".join(body)
            head, body = m.group(1).strip(), []
        else:
            body.append(line)
    out[head] = "\n".join(body)
    return out


SECTIONS = _sections()


def _rows(body):
    """``{key: [cells after the key]}`` of the table rows whose first cell is a backquoted name."""
    rows = {}
    for line in body.splitlines():
        m = re.match(r"\| `([^`]+)`[^|]*\|(.*)\|\s*$", line)
        if m:
            rows[m.group(1)] = [c.strip() for c in m.group(2).split("|")]
    return rows


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


# ---------------------------------------------------------------------------------------- the parsers' keys


def _literal_strings(node):
    if isinstance(node, (ast.Set, ast.Tuple, ast.List)) and node.elts and all(
            isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts):
        return {e.value for e in node.elts}
    return set()


def parser_keys():
    """Every key a parser accepts: the key-set constants, plus every set of strings written in a parser's source
    (the inline key sets: a segment's, a schedule's, a scheme segment's, the conformance sub-tables')."""
    keys = (set(scenarios._TOP) | set().union(*scenarios.sections().values()) | set(imu.SPEC_KEYS)
            | set(conformance_file._TOP) | set(conformance_file._CONDITION_KEYS) | set(rolling_spec.PLATFORM_KEYS)
            | set(rolling_spec.GROUP_KEYS) | set(rolling_experiment.PlatformRolling.tables) | {"method"})  # a [variants.NAME] table's own key (the rest are options)
    for module in PARSERS:
        for node in ast.walk(ast.parse(inspect.getsource(module))):
            if isinstance(node, ast.Set):
                keys |= _literal_strings(node)
    return keys


def parser_values():
    """The names a parser accepts as values: kinds, experiments, presets, bases, axes, and inline ``choices``."""
    values = (set(scenarios.SCENARIO_KINDS) | set(available_experiments()) | set(imu.PRESETS)
              | set(conformance_file.BASE_MOTIONS) | set(rolling_scheme.AXES) | set(imu._SENSORS))
    for module in PARSERS:
        for node in ast.walk(ast.parse(inspect.getsource(module))):
            if isinstance(node, ast.keyword) and node.arg == "choices":
                values |= _literal_strings(node.value)
    return values


def test_the_key_sets_are_found():
    # the source walk finds the inline key sets (if they became constants, add those to parser_keys)
    keys = parser_keys()
    assert {"accel_mps2", "start_s", "end_s", "factor", "sensors", "axis", "rate_dps", "level_tolerance_arcmin",
            "efficiency"} <= keys
    assert {"align", "refuse"} <= parser_values()


def test_every_key_the_parsers_accept_has_a_row():
    missing = sorted(k for k in parser_keys() if f"| `{k}` |" not in DOC)
    assert not missing, f"docs/scenarios.md has no table row for {missing}"


def test_every_value_name_the_parsers_accept_is_named():
    missing = sorted(v for v in parser_values() if f"`{v}`" not in DOC and f'"{v}"' not in DOC)
    assert not missing, f"docs/scenarios.md never names {missing}"


def test_every_documented_row_is_a_key_or_a_value_the_parsers_know():
    known = parser_keys() | parser_values()
    unknown = sorted({k for body in SECTIONS.values() for k in _rows(body)} - known)
    assert not unknown, f"docs/scenarios.md documents rows the parsers do not know: {unknown}"


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


# ---------------------------------------------------------------------------------- tables of figures


def _cells_to_float(cells):
    return [float(c) for c in cells]


def test_preset_table_is_the_presets():
    rows = _rows(SECTIONS["IMU presets"])
    assert set(rows) == set(imu.PRESETS)
    for name, spec in imu.PRESETS.items():
        g, a = spec.gyro, spec.accel
        want = [g.bias[0] / units.DEG_PER_H, g.bias_sigma[0] / units.DEG_PER_H, g.white[0] / units.DEG_PER_SQRT_H,
                g.instability[0] / units.DEG_PER_H, g.scale[0] / units.PPM, a.bias[0] / units.UG,
                a.bias_sigma[0] / units.UG, a.white[0] / units.UG_PER_SQRT_HZ, a.instability[0] / units.UG,
                a.scale[0] / units.PPM, g.tau]
        assert g.tau == a.tau
        for axis_values in (g.bias, g.bias_sigma, g.white, g.instability, g.scale, a.bias, a.bias_sigma, a.white,
                            a.instability, a.scale):
            assert len(set(axis_values)) == 1  # "the same on the three axes"
        assert not any(g.random_walk) and not any(a.random_walk) and g.quantum == 0 == a.quantum
        assert _cells_to_float(rows[name]) == pytest.approx(want, rel=1e-9, abs=1e-12), name


def test_override_units_are_the_key_suffixes_the_page_names():
    rows = _rows(SECTIONS["Overrides in datasheet units"])
    unit_of = {"_dph": ("deg/h", units.DEG_PER_H), "_dpsh": ("deg/sqrt(h)", units.DEG_PER_SQRT_H),
               "_dph_rth": ("deg/h/sqrt(h)", units.DEG_PER_H_SQRT_H), "_ppm": ("ppm", units.PPM),
               "_ug": ("ug", units.UG), "_ug_rthz": ("ug/sqrt(Hz)", units.UG_PER_SQRT_HZ),
               "_ug_rts": ("ug/sqrt(s)", units.UG_PER_SQRT_S), "_s": ("s", 1.0), "_arcsec": ("arcsec", units.ARCSEC),
               "_mps": ("m/s", 1.0)}
    assert set(rows) == set(imu.SPEC_OVERRIDES) | set(imu.SPEC_SCALARS)
    factors = {**{k: v[2] for k, v in imu.SPEC_OVERRIDES.items()}, **{k: v[2] for k, v in imu.SPEC_SCALARS.items()}}
    for key, factor in factors.items():
        suffix = next(s for s in sorted(unit_of, key=len, reverse=True) if key.endswith(s))
        text, value = unit_of[suffix]
        assert rows[key][1] == text and factor == value, key
        assert rows[key][0] == ("number" if key in imu.SPEC_SCALARS else "3-vector"), key


def test_platform_groups_table_is_the_model():
    rows = _rows(SECTIONS["Coefficient groups"])
    assert set(rows) == set(rolling_spec.GROUP_KEYS)
    for name, sl in rolling_spec.GROUP_KEYS.items():
        count, unit = rows[name][1], rows[name][2]
        assert int(count) == sl.stop - sl.start, name
        assert unit == rolling_model.COEFF_CUSTOMARY_UNITS[sl.start], name


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


# ------------------------------------------------------------------------------------ the built-in scenarios

#: Tables whose keys are names of the file's own choosing (method names, window labels), not schema keys.
_NAMED = {("paper", "settling_time_s"), ("metrics", "amplitude_windows_s"), ("conformance", "efficiency")}


def _schema_keys(node, path=()):
    """Every schema key of a scenario mapping; a variant's options are the method's, not the format's."""
    if isinstance(node, list):
        for item in node:
            yield from _schema_keys(item, path)
        return
    if not isinstance(node, dict):
        return
    for key, value in node.items():
        if path == ("variants",):  # the variant's name, then its `method` only
            yield "method"
            continue
        if path in _NAMED:
            if key == "default":
                yield key
            continue
        yield key
        yield from _schema_keys(value, path + (key,))


def _builtins():
    folder = resources.files(scenarios)
    return {n: tomllib.loads((folder / f"{n}.toml").read_text()) for n in scenarios.builtin_names()}


def test_every_key_of_the_builtin_scenarios_is_documented():
    missing = {}
    for name, data in _builtins().items():
        keys = set(_schema_keys(data))
        gone = sorted(k for k in keys if f"`{k}`" not in DOC)
        if gone:
            missing[name] = gone
    assert not missing, f"keys of built-in scenarios not in docs/scenarios.md: {missing}"


def test_builtin_variant_options_are_constructor_options():
    for name, data in _builtins().items():
        group = load_experiment(data.get("experiment", "alignment")).method_group
        for vname, opts in data.get("variants", {}).items():
            cls = aligner.entry_class(group, opts["method"], "method")
            params = inspect.signature(cls).parameters
            if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
                assert set(opts) - {"method"} <= set(params), f"{name}: variants.{vname}"


# ------------------------------------------------------------------------------------------------ links


def _slug(heading):
    s = re.sub(r"[^\w\- ]", "", heading.lower())
    return s.replace(" ", "-")


def test_in_page_links_resolve():
    anchors = {_slug(h) for h in SECTIONS if h}
    targets = set(re.findall(r"\]\(#([^)]+)\)", DOC))
    assert targets and not sorted(targets - anchors)


def test_contract_readme_and_site_link_the_page():
    assert "scenarios.md" in (ROOT / "docs" / "contract.md").read_text()
    assert "](docs/scenarios.md)" in (ROOT / "README.md").read_text()
    assert "\nscenarios\n" in (ROOT / "docs" / "index.md").read_text()  # in the site's table of contents


def test_module_docstring_example_parses():
    text = scenarios.__doc__.split("::\n", 1)[1]
    block = "\n".join(line[4:] for line in text.splitlines() if line.startswith("    ") or not line.strip())
    scn = scenarios.parse(tomllib.loads(block), "docstring")
    assert "docs/scenarios.md" in scenarios.__doc__ and scn.kind == "alignment"
