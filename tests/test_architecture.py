"""The architecture's contracts (pyproject.toml, ``[tool.importlinter]``; docs/architecture.md, "Layers"): the core
names no family, the families are independent, the core's modules import only their own layer and those below it
(indirect imports and imports inside functions included)."""

import pathlib
import tomllib

import pytest

lint = pytest.importorskip("importlinter.cli").lint_imports

ROOT = pathlib.Path(__file__).parents[1]


def test_the_import_contracts_hold():
    assert lint(config_filename=str(ROOT / "pyproject.toml"), no_cache=True, no_logo=True) == 0


def test_a_layer_importing_one_above_it_breaks_the_contract(tmp_path, monkeypatch, capsys):
    """The same contracts with the layers' order reversed must break (the check reads the real imports)."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    layers = next(c for c in conf["contracts"] if c["type"] == "layers")
    text = (f'[tool.importlinter]\nroot_packages = {conf["root_packages"]!r}\n\n[[tool.importlinter.contracts]]\n'
            f'name = "reversed"\ntype = "layers"\nlayers = {layers["layers"][::-1]!r}\n'
            f'ignore_imports = {layers["ignore_imports"]!r}\n').replace("'", '"')
    (tmp_path / "pyproject.toml").write_text(text)
    monkeypatch.chdir(ROOT)
    assert lint(config_filename=str(tmp_path / "pyproject.toml"), no_cache=True, no_logo=True) == 1
    out = " ".join(capsys.readouterr().out.split())
    assert "reversed BROKEN" in out and "fusionbench.cli is not allowed to import" in out  # the real imports read
