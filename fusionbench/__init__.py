"""fusionbench: a shared, exact IMU and trajectory simulator and a benchmark of INS initial-alignment methods.

Frames: navigation n = East-North-Up, body b = Right-Front-Up. Attitude is C_bn (b to n) with
Euler angles C_bn = Rz(yaw) Rx(pitch) Ry(roll). SI units in every array.
"""

import os as _os
import sys as _sys

__version__ = "0.1.0"


#: The packages whose numba kernels are cached (they call each other's compiled functions).
COMPILED_PACKAGES = ("fusionbench", "adrc", "baselines", "damping")


def compiled_sources_key(root=None):
    """A digest (12 hex digits) of the source of every module of :data:`COMPILED_PACKAGES` under ``root`` (default:
    where this package is installed) that uses numba.

    numba invalidates a cached kernel when its own file changes, not when a compiled function it calls from another
    file does (the strapdown kernel inside the compass loops, say): a kernel cached before such an edit would run
    the old code. The cache folder is therefore named by this digest, so any change to compiled code, or a new
    version, starts a fresh cache."""
    import hashlib

    root = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__))) if root is None else str(root)
    digest = hashlib.sha256()
    for pkg in COMPILED_PACKAGES:
        for folder, dirs, files in sorted(_os.walk(_os.path.join(root, pkg))):
            dirs.sort()
            for name in sorted(f for f in files if f.endswith(".py")):
                with open(_os.path.join(folder, name), "rb") as fh:
                    text = fh.read()
                if b"numba" in text:
                    digest.update(_os.path.relpath(_os.path.join(folder, name), root).encode() + b"\0" + text)
    return digest.hexdigest()[:12]


def numba_cache_dir():
    """Where numba keeps its compiled kernels (``cache=True``): ``$NUMBA_CACHE_DIR`` if set, else the per-user
    ``$XDG_CACHE_HOME/fusionbench/numba/<key>`` (``~/.cache/fusionbench/numba/<key>``), ``<key>`` the digest of the
    compiled sources (:func:`compiled_sources_key`)."""
    base = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"), ".cache")
    return _os.environ.get("NUMBA_CACHE_DIR") or _os.path.join(base, "fusionbench", "numba", compiled_sources_key())


# numba's on-disk cache goes to a per-user directory, not beside the installed modules: cache files left in
# site-packages outlive an uninstall, and the folder they keep turns the package into a namespace package that
# shadows a later editable install. Set before numba is imported (baselines, adrc and damping import this first).
_os.environ.setdefault("NUMBA_CACHE_DIR", numba_cache_dir())
if "numba" in _sys.modules:  # imported before us: make it read the directory again
    _sys.modules["numba"].core.config.reload_config()


#: The top-level API (``import fusionbench as fb``): each name and the module it comes from, imported on first use so
#: that ``import fusionbench`` stays light (the command line, numba's cache set-up). Submodules are names too.
API = {
    # align and the methods
    "align": "api", "load_method": "aligner", "available_methods": "aligner", "Site": "aligner",
    "AlignmentResult": "aligner",
    # data: simulate, read, hold
    "simulate": "imu", "IMUSpec": "imu", "SensorErrors": "imu", "PRESETS": "imu", "load_spec": "imu",
    "IMUData": "imudata", "read_imu": "imufiles", "read_aiding": "aidingfiles", "AidingSpec": "aidingsim",
    "simulate_aiding": "aidingsim", "Trajectory": "trajectory", "EulerSway": "trajectory", "car_drive": "drive",
    # modules: scoring, frames, units, motion
    "metrics": None, "attitude": None, "units": None, "earth": None, "trajectory": None, "drive": None, "imu": None,
}


def __getattr__(name):
    if name not in API:
        raise AttributeError(f"module 'fusionbench' has no attribute {name!r}")
    import importlib

    module = importlib.import_module(f"{__name__}.{API[name] or name}")
    value = module if API[name] is None else getattr(module, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(API))
