"""fusionbench: a shared, exact IMU and trajectory simulator and a benchmark of INS initial-alignment methods.

Frames: navigation n = East-North-Up, body b = Right-Front-Up. Attitude is C_bn (b to n) with
Euler angles C_bn = Rz(yaw) Rx(pitch) Ry(roll). SI units in every array.
"""

import os as _os
import sys as _sys

__version__ = "0.1.0"


def numba_cache_dir():
    """Where numba keeps its compiled kernels (``cache=True``): ``$NUMBA_CACHE_DIR`` if set, else the per-user
    ``$XDG_CACHE_HOME/fusionbench/numba`` (``~/.cache/fusionbench/numba``)."""
    base = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"), ".cache")
    return _os.environ.get("NUMBA_CACHE_DIR") or _os.path.join(base, "fusionbench", "numba")


# numba's on-disk cache goes to a per-user directory, not beside the installed modules: cache files left in
# site-packages outlive an uninstall, and the folder they keep turns the package into a namespace package that
# shadows a later editable install. Set before numba is imported (baselines, adrc and damping import this first).
_os.environ.setdefault("NUMBA_CACHE_DIR", numba_cache_dir())
if "numba" in _sys.modules:  # imported before us: make it read the directory again
    _sys.modules["numba"].core.config.reload_config()
