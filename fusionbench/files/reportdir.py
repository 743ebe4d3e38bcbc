"""An output folder (a scenario's report, ``identify``'s, ``consistency``'s), written all or nothing.

The folder is assembled in a temporary folder beside its target (same parent, ``.<name>.tmp-<pid>-<host>-<hex>``)
and moved into place by renames inside that parent only when it is complete: a previous output there is renamed
aside (``.<name>.old-<pid>-<host>-<hex>``), the new one renamed in, the previous one removed. An error or Ctrl-C
before then removes the temporary folder and leaves the target as it was (one between the two renames puts the
previous output back), so an output folder never mixes two runs and is never half-written.

A run killed outright (SIGKILL, a power cut) cannot clean up: its hidden folders stay. The next command writing the
same target removes them first (:func:`sweep`): those of a process of this host that is gone (``os.kill(pid,
0)``), never a live one's nor another host's; a set-aside previous output whose target is missing (the kill fell
between the two renames) is put back instead.

Only what fusionbench wrote is ever replaced: the target must be absent, an empty folder or a previous output of
the same command (an :class:`Output`: :data:`RUN` for ``run``, :func:`is_report`); anything else is refused with
one line, and nothing in it is touched.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import socket
import uuid
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Output:
    """What a command's output folder holds, by which a previous one is told from other folders.

    Attributes
    ----------
    marker : str
        The JSON file every output holds (an object).
    keys : tuple of str
        Keys that object holds.
    what : str
        The output in words, for the refusal (``"a previous fusionbench report (metrics.json, no sub-folder)"``).
    files : tuple of str or None
        Every file the command writes: a previous output holds no other (None: any file).
    values : dict
        Keys of the marker with the value they must have.
    """

    marker: str
    keys: tuple
    what: str
    files: tuple | None = None
    values: dict = field(default_factory=dict)

    def holds(self, folder) -> bool:
        """Whether ``folder`` is a previous output: the marker's object with its keys and values, no sub-folder and,
        when :attr:`files` is given, no other file."""
        try:
            with os.scandir(folder) as entries:
                for e in entries:
                    if e.is_dir(follow_symlinks=False) or (self.files is not None and e.name not in self.files):
                        return False
            content = json.loads((Path(folder) / self.marker).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        return (isinstance(content, dict) and all(k in content for k in self.keys)
                and all(content.get(k) == v for k, v in self.values.items()))


#: A scenario's report (``run``): a run's metrics.json; other files (figures of an older version) are its own.
RUN = Output("metrics.json", ("scenario", "methods"), "a previous fusionbench report (metrics.json, no sub-folder)")


def is_report(folder) -> bool:
    """Whether ``folder`` is a report fusionbench wrote: a metrics.json object with ``scenario`` and ``methods``,
    and no sub-folder (a report has none; a ``run all`` output or a user's project has)."""
    return RUN.holds(folder)


def _listing(folder, count=3):
    names = sorted(e.name + "/" * e.is_dir() for e in os.scandir(folder))
    return ", ".join(names[:count]) + (", ..." if len(names) > count else "")


def check_replaceable(folder, output: Output = RUN):
    """Raise ValueError (one line naming ``folder``) unless it is absent, an empty folder or a previous ``output``."""
    folder = Path(folder)
    real, cwd = Path(os.path.realpath(folder)), Path(os.path.realpath(os.getcwd()))
    if real == real.parent or real == cwd or real in cwd.parents:
        raise ValueError(f"{folder}: expected a report folder, found the current folder or one holding it; "
                         f"give --out a folder of its own")
    if not os.path.lexists(real):
        return
    if not real.is_dir():
        raise ValueError(f"{folder}: expected a folder for the report, found a file")
    if not any(real.iterdir()) or output.holds(real):
        return
    raise ValueError(f"{folder}: expected a new or empty folder or {output.what}, found other files "
                     f"({_listing(real)}); nothing is replaced: give --out another folder")


def prepare(folders, output: Output = RUN):
    """Check, before any work, that an ``output`` can be written to each of ``folders``: the leftovers of a killed
    run there are removed (:func:`sweep`), each is replaceable (:func:`check_replaceable`), its parent exists
    (created if needed) and a folder can be made there.

    Returns the folders it created, outermost first (:func:`remove_empty` takes them back after a failure).
    Raises ValueError, one line naming the folder and the problem."""
    created = []
    try:
        for folder in folders:
            folder = Path(folder)
            sweep(folder)
            check_replaceable(folder, output)
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


#: This host in the names of the hidden folders: a pid is only checked on the host that made the folder.
HOST = hashlib.sha1(socket.gethostname().encode()).hexdigest()[:6]


def _temporary(parent, name, what, make=False):
    path = Path(parent) / f".{name}.{what}-{os.getpid()}-{HOST}-{uuid.uuid4().hex[:8]}"
    if make:
        os.mkdir(path, 0o777)  # mode honours the umask, like any new folder
    return path


def _alive(pid):
    """Whether process ``pid`` of this host may be running (when in doubt, it is)."""
    if pid <= 0 or pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, OverflowError):  # another user's process (EPERM), or no such number: not ours to judge
        return True
    return True


def sweep(folder):
    """Remove the hidden folders a killed run left beside ``folder``: ``.<name>.tmp-<pid>-...`` and
    ``.<name>.old-<pid>-...`` of this host whose process is gone. When ``folder`` is missing, the latest such
    ``.old`` folder (a previous output set aside, the kill between the two renames) is renamed back to it first.

    Returns the paths removed. A live process's folders, another host's and anything else are left; on a system
    without POSIX signals nothing is done (``os.kill`` would end the process)."""
    if os.name != "posix":
        return []
    target = Path(os.path.realpath(folder))
    pattern = re.compile(rf"\.{re.escape(target.name)}\.(tmp|old)-(\d+)-(?:([0-9a-f]{{6}})-)?[0-9a-f]{{8}}")
    stale = {"tmp": [], "old": []}
    try:
        with os.scandir(target.parent) as entries:
            for e in entries:
                m = pattern.fullmatch(e.name)
                if (m and m.group(3) in (None, HOST) and e.is_dir(follow_symlinks=False)
                        and not _alive(int(m.group(2)))):
                    stale[m.group(1)].append(Path(e.path))
    except OSError:  # no parent yet: nothing left there
        return []
    if stale["old"] and not os.path.lexists(target):
        with contextlib.suppress(OSError):  # another run's sweep may be at it too
            latest = max(stale["old"], key=lambda p: p.stat().st_mtime)
            os.rename(latest, target)
            stale["old"].remove(latest)
    removed = []
    for path in stale["tmp"] + stale["old"]:
        shutil.rmtree(path, ignore_errors=True)
        if not os.path.lexists(path):
            removed.append(path)
    return removed


@contextlib.contextmanager
def staged(folder, output: Output = RUN):
    """Yield a new empty folder beside ``folder``; on success it replaces ``folder`` whole (see the module), on
    an error or an interrupt it is removed and ``folder`` is left as it was. A killed run's leftovers beside it are
    removed first (:func:`sweep`).

    Raises ValueError (one line) when ``folder`` is neither absent, nor empty, nor a previous ``output``."""
    folder = Path(folder)
    sweep(folder)
    check_replaceable(folder, output)
    target = Path(os.path.realpath(folder))
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary(target.parent, target.name, "tmp", make=True)
    try:
        yield tmp
        _swap(folder, tmp, target, output)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)  # gone after the swap; after a failure, the half-written output


@contextlib.contextmanager
def written(folder, output: Output = RUN):
    """:func:`prepare` then :func:`staged` for one ``folder``: yield the folder to write ``output`` into, which
    replaces ``folder`` whole on success; after a failure the parents :func:`prepare` made are removed again."""
    created = prepare([folder], output)
    try:
        with staged(folder, output) as tmp:
            yield tmp
    except BaseException:
        remove_empty(created)
        raise


def _swap(folder, tmp, target, output=RUN):
    """Rename ``tmp`` onto ``target``, the previous output there renamed aside first and removed after."""
    check_replaceable(folder, output)  # as it is now: a user may have put files there while the run went on
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
