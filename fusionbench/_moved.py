"""Deprecation aliases for the modules that moved into the core's sub-packages in version 0.2.

``import fusionbench.imufiles`` (0.1) gives ``fusionbench.files.imufiles`` with a ``FutureWarning`` naming the new
path; the alias is the same module object, so its functions, classes and pickles are the new ones. The aliases are
removed in 0.3.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: The sub-package of every module that moved: ``fusionbench.<module>`` is now ``fusionbench.<package>.<module>``.
MOVED = {module: package for package, modules in {
    "simulation": "aiding aiding_geometry aidingsim attitude drive earth fields imu imu_model imudata imusim "
                  "strapdown strapdown_compiled trajectory translation units",
    "scoring": "bound bound_model metrics",
    "files": "aidingfiles aidingnmea aidingtext imufiles imuwriters layout_format layouts pages progress provenance "
             "reportdir resample",
    "methods": "aligner aligner_base claims coarse coarse_aided coarse_inertial coarse_kernel coarse_level "
               "coarse_position compass compass_compiled discovery init_check inputs motion",
    "bench": "check claim_check cluster conformance_file experiment run_metrics runner scenarios streaming",
    "reports": "conformance_report figure_events figures report",
    "experiments": "alignment conformance overview",
    "recording": "allan allanfit allanplot consistency consistency_report identify identify_core identify_report",
}.items() for module in modules.split()}


class _Alias(importlib.abc.Loader):
    def __init__(self, target: str):
        self.target = target

    def create_module(self, spec):
        module = importlib.import_module(self.target)
        self.spec = module.__spec__
        return module

    def exec_module(self, module):
        module.__spec__ = self.spec  # the import system set it to the alias's: the module keeps its own


class MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds ``fusionbench.<module>`` for a module of :data:`MOVED` and loads its new path, with a FutureWarning."""

    def find_spec(self, fullname, path=None, target=None):
        parent, _, name = fullname.rpartition(".")
        if parent != "fusionbench" or name not in MOVED:
            return None
        new = f"fusionbench.{MOVED[name]}.{name}"
        warnings.warn(f"{fullname} moved to {new} in fusionbench 0.2; the old path goes in 0.3", FutureWarning,
                      stacklevel=2)
        return importlib.util.spec_from_loader(fullname, _Alias(new))


def install():
    """Put the finder at the end of ``sys.meta_path`` (once): it is asked only when no module has the old name."""
    if not any(isinstance(f, MovedModuleFinder) for f in sys.meta_path):
        sys.meta_path.append(MovedModuleFinder())
