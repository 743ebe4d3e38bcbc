"""The metrics.json schema in docs/ is what the runner writes: every reference file (each experiment kind, both
sizes) and a fresh run through the command line validate against docs/metrics.schema.json, and the schema is
strict enough to fail on a figure nobody documented."""

import copy
import json
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

from fusionbench.bench.check import packaged_reference

SCHEMA = json.loads((Path(__file__).parents[1] / "docs" / "metrics.schema.json").read_text())
VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)

TINY = Path(__file__).parent / "data" / "tiny-jump.toml"  # static, reference noise x100 from 40 to 60 s


def test_the_schema_is_a_valid_json_schema():
    jsonschema.Draft202012Validator.check_schema(SCHEMA)


@pytest.mark.parametrize("quick", [True, False])
def test_every_reference_metrics_file_follows_the_schema(quick):
    files = sorted(packaged_reference(quick).glob("*.json"))
    assert len(files) >= 13
    for path in files:
        errors = [f"{'/'.join(map(str, e.path))}: {e.message}" for e in VALIDATOR.iter_errors(json.loads(path.read_text()))]
        assert not errors, f"{path.name}: {errors[:3]}"


def test_a_fresh_run_through_the_command_line_follows_the_schema(tmp_path):
    r = subprocess.run([sys.executable, "-m", "fusionbench", "run", str(TINY), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert {"provenance", "diverged"} <= set(m) and "jump" in m["methods"]["kf"]
    VALIDATOR.validate(m)


def test_the_schema_fails_an_undocumented_or_missing_figure():
    m = json.loads((packaged_reference(True) / "static-r-jump.json").read_text())
    bad = copy.deepcopy(m)
    bad["methods"]["kf"]["new_figure"] = {"E": 1.0}  # a structured key nobody documented
    assert not VALIDATOR.is_valid(bad)
    bad = copy.deepcopy(m)
    del bad["methods"]["kf"]["final_error_arcmin"]["U"]["rms"]
    assert not VALIDATOR.is_valid(bad)
    bad = copy.deepcopy(m)
    bad["methods"]["kf"]["settling_time_s"]["band_arcmin"] = "ten"
    assert not VALIDATOR.is_valid(bad)
