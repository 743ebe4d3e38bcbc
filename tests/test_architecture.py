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
            f'name = "reversed"\ntype = "layers"\ncontainers = {layers["containers"]!r}\n'
            f'layers = {layers["layers"][::-1]!r}\n').replace("'", '"')
    (tmp_path / "pyproject.toml").write_text(text)
    monkeypatch.chdir(ROOT)
    assert lint(config_filename=str(tmp_path / "pyproject.toml"), no_cache=True, no_logo=True) == 1
    out = " ".join(capsys.readouterr().out.split())
    assert "reversed BROKEN" in out and "fusionbench.cli is not allowed to import" in out  # the real imports read


def test_the_core_is_its_sub_packages_and_the_entry_modules():
    """Every module of the core belongs to a layer of the contract: the sub-packages, and on top the command line
    and the API (a new top-level module must be placed in a layer, not added beside them)."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    layers = next(c for c in conf["contracts"] if c["type"] == "layers")
    named = {n.strip() for layer in layers["layers"] for n in layer.replace("|", ":").split(":")}
    core = ROOT / "fusionbench"
    found = {p.stem for p in core.glob("*.py") if p.stem not in ("__init__", "_moved")}
    found |= {p.parent.name for p in core.glob("*/__init__.py")}
    assert found == named


def test_a_moved_module_is_found_at_its_old_path_with_a_warning():
    """``fusionbench.imufiles`` (0.1) is ``fusionbench.files.imufiles``, the same module object, with a
    FutureWarning."""
    import importlib
    import sys

    from fusionbench.files import imufiles

    sys.modules.pop("fusionbench.imufiles", None)
    with pytest.warns(FutureWarning, match="fusionbench.imufiles moved to fusionbench.files.imufiles"):
        old = importlib.import_module("fusionbench.imufiles")
    assert old is imufiles and old.__spec__.name == "fusionbench.files.imufiles"
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("fusionbench.no_such_module")
