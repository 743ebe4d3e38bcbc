"""Where a run's numbers came from: the ``provenance`` block of metrics.json.

A reader of a report months later needs the code (fusionbench version and, from a git checkout, the commit and
whether the tree had local changes), the moment (UTC), the interpreter and the libraries that compute the numbers,
the machine, the command, and the size of the run (seed, runs, duration, quick) with its wall time.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

from fusionbench import __version__

#: Distributions whose versions can change the numbers or the figures.
LIBRARIES = ("numpy", "scipy", "numba", "filterpy", "gtsam", "scikit-learn", "joblib", "matplotlib")


def git_commit(path=None):
    """``(commit, dirty)`` of the git checkout holding ``path`` (default: this package), or ``(None, None)`` when
    it is not in one (an installed package) or git is missing."""
    where = Path(path or Path(__file__).resolve().parent)
    try:
        head = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return None, None
        status = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None, None
    return head.stdout.strip(), bool(status.stdout.strip()) if status.returncode == 0 else None


def library_versions(names=LIBRARIES):
    """Installed version of each distribution (None when it is not installed)."""
    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def _program(arg0):
    """The program's name as a user types it (``python -m fusionbench`` runs ``__main__.py``)."""
    name = Path(arg0).name
    return "fusionbench" if name == "__main__.py" else name


def collect(*, seed, runs, duration_s, quick, wall_s, argv=None):
    """The provenance mapping of one run.

    Parameters
    ----------
    seed, runs : int
        Seed and Monte Carlo runs of the run.
    duration_s : float
        Record length of each run, s.
    quick : bool
        Whether the run was at ``--quick`` size.
    wall_s : float
        Wall time of the run, s.
    argv : list of str, optional
        The command line (default ``sys.argv``).
    """
    commit, dirty = git_commit()
    argv = sys.argv if argv is None else argv
    return {
        "fusionbench": __version__,
        "git_commit": commit,
        "git_dirty": dirty,
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "libraries": library_versions(),
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "command": " ".join([_program(argv[0]), *argv[1:]]) if argv else "",
        "seed": int(seed),
        "runs": int(runs),
        "duration_s": float(duration_s),
        "quick": bool(quick),
        "wall_s": float(wall_s),
    }
