"""The NumPy oracles of the compiled loops (tests/oracles/) stand in for a kernel the library still calls.

Each oracle's ``PATCH`` names the module attribute a test replaces with ``monkeypatch.setattr``; if the library renamed
or stopped calling that kernel, the agreement tests would compare the kernel with itself and pass without checking
anything. This holds every oracle to a compiled function the library module really holds and calls."""

import importlib
import inspect
import pathlib

import pytest

ORACLES = sorted(p.stem for p in (pathlib.Path(__file__).parent / "oracles").glob("*.py") if p.stem != "__init__")


def test_every_oracle_is_listed_for_the_benchmarks():
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).parents[1] / "benchmarks"))
    try:
        from _oracle import ORACLES as BENCH
    finally:
        sys.path.pop(0)
    assert sorted(BENCH) == ORACLES


def _patches(name):
    patch = importlib.import_module(f"tests.oracles.{name}").PATCH
    return [patch] if isinstance(patch[0], str) else list(patch)


@pytest.mark.parametrize("name, mod_name, attr, oracle",
                         [(n, *p) for n in ORACLES for p in _patches(n)])
def test_an_oracle_replaces_a_compiled_kernel_its_module_calls(name, mod_name, attr, oracle):
    mod = importlib.import_module(mod_name)
    kernel = getattr(mod, attr)
    assert hasattr(kernel, "py_func") or inspect.getmodule(kernel).__name__.endswith("_compiled"), \
        f"{mod_name}.{attr} is not a compiled kernel"
    assert f"{attr}(" in inspect.getsource(mod), f"{mod_name} does not call {attr}"
    assert callable(oracle) and inspect.getmodule(oracle).__name__ == f"tests.oracles.{name}"
