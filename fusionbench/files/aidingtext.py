"""The aiding readers' common ground: their error type and the lines of a text file.

:mod:`fusionbench.files.aidingfiles` (CSV, KF-GINS) and :mod:`fusionbench.files.aidingnmea` (NMEA 0183) both read text
files of a receiver's rows; a problem with one is an :class:`AidingFileError` of one line naming the file.
"""

from __future__ import annotations

from fusionbench.files.imufiles import IMUFileError, _lines


class AidingFileError(IMUFileError):
    """A missing, unreadable or malformed aiding file; message ``"<path>: <problem>"`` on one line (an
    :class:`~fusionbench.files.imufiles.IMUFileError`, so what catches a bad input file catches it too)."""


def text_lines(path):
    """The non-blank lines of an aiding file not starting with ``#``, as (line number, text); a file that cannot be
    read is an :class:`AidingFileError`."""
    try:
        return _lines(path, "#")
    except IMUFileError as exc:
        raise AidingFileError(exc.path, exc.problem) from None
