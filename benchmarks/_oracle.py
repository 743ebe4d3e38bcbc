"""The NumPy oracles of the compiled loops (``tests/oracles/``) in place of the library's kernels, for the benchmarks
that time the two side by side (the "before" of the compiled loops)."""

from __future__ import annotations

import contextlib
import importlib
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the repository: tests/ is not installed

#: The oracles by what they stand in for: module names under ``tests/oracles``.
ORACLES = ("strapdown", "coarse", "adrc_gyrocompass", "pid_gyrocompass", "eso_td")


def oracle_patch(name):
    """``(module, attribute, oracle)`` of ``tests/oracles/<name>.py`` (its ``PATCH``)."""
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    return importlib.import_module(f"tests.oracles.{name}").PATCH


@contextlib.contextmanager
def numpy_oracles(*names):
    """Within the block, the library calls the NumPy oracles ``names`` (default: all) instead of its kernels."""
    patches = [oracle_patch(n) for n in names or ORACLES]
    saved = []
    try:
        for mod, attr, fn in patches:
            m = importlib.import_module(mod)
            saved.append((m, attr, getattr(m, attr)))
            setattr(m, attr, fn)
        yield
    finally:
        for m, attr, fn in reversed(saved):
            setattr(m, attr, fn)
