"""The NumPy oracles of the compiled loops (``tests/oracles/``) in place of the library's kernels, for the benchmarks
that time the two side by side (the "before" of the compiled loops)."""

from __future__ import annotations

import contextlib
import importlib
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the repository: tests/ is not installed

#: The oracles by what they stand in for: module names under ``tests/oracles``.
ORACLES = ("strapdown", "coarse", "adrc_gyrocompass", "pid_gyrocompass", "eso_td", "graph_rotations",
           "graph_posterior")


def oracle_patches(name):
    """The ``(module, attribute, oracle)`` triples of ``tests/oracles/<name>.py`` (its ``PATCH``: one triple, or a
    list of them where the oracle stands in for several functions)."""
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    patch = importlib.import_module(f"tests.oracles.{name}").PATCH
    return [patch] if isinstance(patch[0], str) else list(patch)


def oracle_users(name):
    """The modules whose methods run the kernels ``tests/oracles/<name>.py`` replaces: its ``USED_BY``, else the
    modules it patches."""
    patches = oracle_patches(name)  # puts the repository on the path
    mod = importlib.import_module(f"tests.oracles.{name}")
    return tuple(getattr(mod, "USED_BY", ())) or tuple(m for m, _, _ in patches)


@contextlib.contextmanager
def numpy_oracles(*names):
    """Within the block, the library calls the NumPy oracles ``names`` (default: all) instead of its kernels."""
    patches = [p for n in names or ORACLES for p in oracle_patches(n)]
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
