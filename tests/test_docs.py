"""docs/scenarios.md is the scenario file format as the parsers read it; these tests keep the page's names in step.

* every key a parser accepts is documented, with a table row (the parsers' key sets, and every set of key names
  written inline in a parser's source), and every documented key is one the parsers accept;
* the IMU preset table and the platform coefficient groups carry the figures of the code;
* every key of every built-in scenario is documented, and every built-in variant's options are constructor options;
* the page's in-page links resolve, and the contract, README and site link the page.

Its ranges and defaults are probed in test_docs_ranges.py, its TOML examples loaded in test_docs_scenario_examples.py.
"""

import ast
import inspect
import re
import tomllib
from importlib import resources

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
from tests.docs_helpers import DOC, ROOT, SECTIONS, _rows

PARSERS = (scenarios, scenario_tables, imu, conformance_file, rolling_spec, feat_jump, feat_windows, feat_compare,
           feat_paper)


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
