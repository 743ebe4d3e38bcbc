"""The README's Python example runs as printed and its coarse alignment lands on the limits."""

import re
from pathlib import Path

import numpy as np
import pytest


def _run_block(marker=None):
    """Execute the README's first Python block (or the first containing ``marker``); its namespace."""
    text = (Path(__file__).parents[1] / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    code = next(b for b in blocks if marker is None or marker in b)
    ns = {}
    exec(compile(code, "README.md", "exec"), ns)
    return ns


def test_readme_example_runs_and_levels_on_the_limit(capsys):
    ns = _run_block()
    mean = ns["phi"].mean(axis=0)
    # level: accelerometer bias / g, up to the white noise averaged over 20 runs x 300 s (~0.001 arcmin)
    assert mean[:2] == pytest.approx(ns["limit"][:2], abs=0.01)
    assert "limit" in capsys.readouterr().out


def test_readme_damping_example_runs(capsys):
    ns = _run_block("DampedNavigator")
    assert ns["phi"].shape == (2, 4000, 3)
    assert "q now" in capsys.readouterr().out


def test_readme_platform_example_runs_and_meets_its_bound(capsys):
    ns = _run_block("information_rank")
    assert "rank 45" in capsys.readouterr().out
    # the torquer errors within 3 of the filter's sigmas, and those within 2 of the information bound
    model = ns["model"]
    sig = model.to_customary(ns["res"].sigma[-1, :42])[model.KT]
    bound = model.to_customary(ns["bound"][:42])[model.KT]
    assert np.all(np.abs(ns["err"][model.KT]) < 3 * sig) and np.all(sig < 2 * bound)
