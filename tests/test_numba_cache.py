"""numba's compiled kernels are cached in a per-user directory, never beside the installed modules (files left in
site-packages outlive an uninstall and shadow a later editable install)."""

import os
import subprocess
import sys
from pathlib import Path

import fusionbench

PACKAGES = [Path(fusionbench.__file__).parent.parent / p for p in fusionbench.compiled_packages()]
SCRIPT = """
import numpy as np
from fusionbench.methods.aligner import Site
from fusionbench.simulation import trajectory, imu
from baselines.gyrocompass import PIDGyrocompass
tr = trajectory.Trajectory(0.6, 1.9, 0.0, trajectory.EulerSway(mean=np.zeros(3)), duration=90.0)
data = imu.simulate(tr, imu.PRESETS["navigation"], 0.1, runs=1, seed=0)
PIDGyrocompass().align(data, Site(0.6, 1.9, 0.0))
import numba
print(numba.config.CACHE_DIR)
"""


def _cache_files(folders):
    return {p for f in folders if f.is_dir() for p in f.rglob("*.nb[ic]")}


def test_kernels_cached_in_the_user_cache_directory(tmp_path):
    before = _cache_files(PACKAGES)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=True)
    expect = tmp_path / "fusionbench" / "numba" / fusionbench.compiled_sources_key()
    assert out.stdout.strip().splitlines()[-1] == str(expect)
    assert _cache_files([expect]), "the strapdown kernel should have been cached there"
    assert _cache_files(PACKAGES) == before  # nothing new beside the modules


def test_an_explicit_numba_cache_dir_wins(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "mine"), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    code = "import fusionbench, numba; print(fusionbench.numba_cache_dir()); print(numba.config.CACHE_DIR)"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == [str(tmp_path / "mine")] * 2


def test_the_compiled_packages_are_the_core_and_every_registered_plug_in():
    """The core names no family: the packages whose kernels share a cache key come from the entry points."""
    assert fusionbench.compiled_packages() == ("fusionbench", "adrc", "baselines", "damping")


def test_a_change_to_any_compiled_source_starts_a_fresh_cache(tmp_path):
    """numba checks only a kernel's own file: a kernel calling the strapdown kernel from another file would keep its
    stale cache after an edit of strapdown.py. The cache folder is named by a digest of every compiled source, so an
    edit of any of them (and only of them) moves it."""
    for pkg, name, text in (("fusionbench", "strapdown.py", "import numba\nA = 1\n"),
                            ("adrc", "loop.py", "import numba\nfrom fusionbench.simulation.strapdown import A\n"),
                            ("fusionbench", "report.py", "B = 1\n")):
        (tmp_path / pkg).mkdir(exist_ok=True)
        (tmp_path / pkg / name).write_text(text)
    key = fusionbench.compiled_sources_key(tmp_path)
    assert len(key) == 12 and key == fusionbench.compiled_sources_key(tmp_path)
    (tmp_path / "fusionbench" / "report.py").write_text("B = 2\n")  # no numba in it: the same cache
    assert fusionbench.compiled_sources_key(tmp_path) == key
    (tmp_path / "fusionbench" / "strapdown.py").write_text("import numba\nA = 2\n")  # the callee changed
    assert fusionbench.compiled_sources_key(tmp_path) != key
