"""fusionbench: a shared, exact IMU and trajectory simulator and a benchmark of INS initial-alignment methods.

Frames: navigation n = East-North-Up, body b = Right-Front-Up. Attitude is C_bn (b to n) with
Euler angles C_bn = Rz(yaw) Rx(pitch) Ry(roll). SI units in every array.
"""

import os as _os
import sys as _sys

__version__ = "0.2.0"


#: The entry-point groups through which plug-ins (the method families, a user's own package) reach the core.
PLUGIN_GROUPS = ("fusionbench.methods", "fusionbench.experiments", "fusionbench.features", "fusionbench.calibrators")


def compiled_packages() -> tuple:
    """``fusionbench`` and the top-level package of every plug-in registered in :data:`PLUGIN_GROUPS` (read from the
    installed distributions' metadata, nothing imported): the packages whose numba kernels may call each other's."""
    from importlib.metadata import entry_points

    every = entry_points()  # one scan of the installed distributions, then a selection per group
    found = {ep.value.split(":")[0].split(".")[0] for group in PLUGIN_GROUPS for ep in every.select(group=group)}
    return tuple(["fusionbench"] + sorted(found - {"fusionbench"}))


def compiled_sources_key(root=None):
    """A digest (12 hex digits) of the source of every module of :func:`compiled_packages` that uses numba: each
    package's folder under ``root``, or (default) where it is installed.

    numba invalidates a cached kernel when its own file changes, not when a compiled function it calls from another
    file does (the strapdown kernel inside the compass loops, say): a kernel cached before such an edit would run
    the old code. The cache folder is therefore named by this digest, so any change to compiled code, or a new
    version, starts a fresh cache."""
    import hashlib
    import importlib.util

    digest = hashlib.sha256()
    for pkg in compiled_packages():
        if root is not None:
            folder0 = _os.path.join(str(root), pkg)
        elif pkg == __name__:
            folder0 = _os.path.dirname(_os.path.abspath(__file__))
        else:
            spec = importlib.util.find_spec(pkg)
            if spec is None or not spec.submodule_search_locations:
                continue  # a single-module plug-in, or one not importable here: nothing of ours to cache
            folder0 = list(spec.submodule_search_locations)[0]
        base = _os.path.dirname(folder0)
        for folder, dirs, files in sorted(_os.walk(folder0)):
            dirs.sort()
            for name in sorted(f for f in files if f.endswith(".py")):
                with open(_os.path.join(folder, name), "rb") as fh:
                    text = fh.read()
                if b"numba" in text:
                    digest.update(_os.path.relpath(_os.path.join(folder, name), base).encode() + b"\0" + text)
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
    "align": "api", "load_method": "methods.aligner", "available_methods": "methods.aligner", "Site": "methods.aligner",
    "AlignmentResult": "methods.aligner",
    # data: simulate, read, hold
    "simulate": "simulation.imu", "IMUSpec": "simulation.imu", "SensorErrors": "simulation.imu",
    "PRESETS": "simulation.imu", "load_spec": "simulation.imu", "IMUData": "simulation.imudata",
    "read_imu": "files.imufiles", "read_aiding": "files.aidingfiles", "AidingSpec": "simulation.aidingsim",
    "simulate_aiding": "simulation.aidingsim", "Trajectory": "simulation.trajectory",
    "EulerSway": "simulation.trajectory", "car_drive": "simulation.drive",
    # modules: scoring, frames, units, motion
    "metrics": "scoring.metrics", "attitude": "simulation.attitude", "units": "simulation.units",
    "earth": "simulation.earth", "trajectory": "simulation.trajectory", "drive": "simulation.drive",
    "imu": "simulation.imu",
}


def __getattr__(name):
    if name not in API:
        raise AttributeError(f"module 'fusionbench' has no attribute {name!r}")
    import importlib

    module = importlib.import_module(f"{__name__}.{API[name]}")
    value = module if API[name].rsplit(".", 1)[-1] == name else getattr(module, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(API))


from fusionbench import _moved  # noqa: E402 (the 0.1 module paths, with a FutureWarning)

_moved.install()
