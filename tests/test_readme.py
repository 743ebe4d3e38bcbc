"""The README's Python example runs as printed and its coarse alignment lands on the limits."""

import re
from pathlib import Path

import numpy as np
import pytest


def test_readme_example_runs_and_levels_on_the_limit(capsys):
    text = (Path(__file__).parents[1] / "README.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    ns = {}
    exec(compile(code, "README.md", "exec"), ns)
    mean = ns["phi"].mean(axis=0)
    # level: accelerometer bias / g, up to the white noise averaged over 20 runs x 300 s (~0.001 arcmin)
    assert mean[:2] == pytest.approx(ns["limit"][:2], abs=0.01)
    assert "limit" in capsys.readouterr().out


def test_readme_damping_example_runs(capsys):
    text = (Path(__file__).parents[1] / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    code = next(b for b in blocks if "DampedNavigator" in b)
    ns = {}
    exec(compile(code, "README.md", "exec"), ns)
    assert ns["phi"].shape == (2, 4000, 3)
    assert "q now" in capsys.readouterr().out


def test_readme_platform_example_runs_and_meets_its_bound(capsys):
    text = (Path(__file__).parents[1] / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    code = next(b for b in blocks if "information_rank" in b)
    ns = {}
    exec(compile(code, "README.md", "exec"), ns)
    assert "rank 45" in capsys.readouterr().out
    # the torquer errors within 3 of the filter's sigmas, and those within 2 of the information bound
    pf = ns["pf"]
    sig = pf.to_customary(ns["res"].sigma[-1, :42])[pf.KT]
    bound = pf.to_customary(ns["bound"][:42])[pf.KT]
    assert np.all(np.abs(ns["err"][pf.KT]) < 3 * sig) and np.all(sig < 2 * bound)
