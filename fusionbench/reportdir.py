"""A scenario's report folder, written all or nothing.

The report (metrics.json, report.md, report.html, the figures, the methods' own figures) is assembled in a
temporary folder beside its target (same parent, ``.<name>.tmp-<pid>-<hex>``) and moved into place by renames
inside that parent only when it is complete: a previous report there is renamed aside
(``.<name>.old-<pid>-<hex>``), the new one renamed in, the previous one removed. An error or Ctrl-C before then
removes the temporary folder and leaves the target as it was (one between the two renames puts the previous
report back), so a report folder never mixes two runs and is never half-written.

Only what fusionbench wrote is ever replaced: the target must be absent, an empty folder or a previous report
(:func:`is_report`: a folder holding a run's metrics.json and no sub-folder); anything else is refused with one
line, and nothing in it is touched.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import uuid
from pathlib import Path


def is_report(folder) -> bool:
    """Whether ``folder`` is a report fusionbench wrote: a metrics.json object with ``scenario`` and ``methods``,
    and no sub-folder (a report has none; a ``run all`` output or a user's project has)."""
    folder = Path(folder)
    try:
        with os.scandir(folder) as entries:
            if any(e.is_dir(follow_symlinks=False) for e in entries):
                return False
        metrics = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(metrics, dict) and "scenario" in metrics and "methods" in metrics


def check_replaceable(folder):
    """Raise ValueError (one line naming ``folder``) unless it is absent, an empty folder or a previous report."""
    folder = Path(folder)
    real, cwd = Path(os.path.realpath(folder)), Path(os.path.realpath(os.getcwd()))
    if real == real.parent or real == cwd or real in cwd.parents:
        raise ValueError(f"{folder}: expected a report folder, found the current folder or one holding it; "
                         f"give --out a folder of its own")
    if not os.path.lexists(real):
        return
    if not real.is_dir():
        raise ValueError(f"{folder}: expected a folder for the report, found a file")
    if not any(real.iterdir()) or is_report(real):
        return
    raise ValueError(f"{folder}: expected a new or empty folder or a previous fusionbench report (metrics.json, no "
                     f"sub-folder), found other files; nothing is replaced: give --out another folder")


def prepare(folders):
    """Check, before any work, that a report can be written to each of ``folders``: each is replaceable
    (:func:`check_replaceable`), its parent exists (created if needed) and a folder can be made there.

    Returns the folders it created, outermost first (:func:`remove_empty` takes them back after a failure).
    Raises ValueError, one line naming the folder and the problem."""
    created = []
    try:
        for folder in folders:
            folder = Path(folder)
            check_replaceable(folder)
            parent = Path(os.path.realpath(folder)).parent
            above = [parent, *parent.parents]
            existing = next(p for p in above if os.path.lexists(p))
            if not existing.is_dir():
                raise ValueError(f"{folder}: cannot make a report folder there: {existing} is a file, not a folder")
            created += above[:above.index(existing)][::-1]
            try:
                parent.mkdir(parents=True, exist_ok=True)
                os.rmdir(_temporary(parent, folder.name, "tmp", make=True))  # can a folder be made there?
            except OSError as exc:
                raise ValueError(f"{folder}: cannot write a report in {parent} ({exc.strerror or exc})") from None
    except BaseException:
        remove_empty(created)
        raise
    return created


def remove_empty(folders):
    """Remove those of ``folders`` (outermost first, as :func:`prepare` returns them) that are still empty."""
    for folder in reversed(folders):
        with contextlib.suppress(OSError):
            os.rmdir(folder)


def _temporary(parent, name, what, make=False):
    path = Path(parent) / f".{name}.{what}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    if make:
        os.mkdir(path, 0o777)  # mode honours the umask, like any new folder
    return path


@contextlib.contextmanager
def staged(folder):
    """Yield a new empty folder beside ``folder``; on success it replaces ``folder`` whole (see the module), on
    an error or an interrupt it is removed and ``folder`` is left as it was.

    Raises ValueError (one line) when ``folder`` is neither absent, nor empty, nor a previous report."""
    folder = Path(folder)
    check_replaceable(folder)
    target = Path(os.path.realpath(folder))
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary(target.parent, target.name, "tmp", make=True)
    try:
        yield tmp
        _swap(folder, tmp, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)  # gone after the swap; after a failure, the half-written report


def _swap(folder, tmp, target):
    """Rename ``tmp`` onto ``target``, the previous report there renamed aside first and removed after."""
    check_replaceable(folder)  # as it is now: a user may have put files there while the run went on
    old = None
    if os.path.lexists(target):
        old = _temporary(target.parent, target.name, "old")
        os.rename(target, old)
    try:
        os.rename(tmp, target)
    except BaseException:
        if old is not None:
            os.rename(old, target)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
