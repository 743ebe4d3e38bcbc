"""Column-mapped text IMU logs: other people's layouts read into fusionbench's
:class:`~fusionbench.simulation.imudata.IMUData`.

A :class:`~fusionbench.files.layout_format.Layout` says which columns of a delimited text log hold the time, the three
gyro and the three accelerometer channels, in which units, whether they are rates or increments and where the
file's body axes point (definitions and matrices: :mod:`fusionbench.files.layout_format`, ``docs/layouts.md``).
:func:`read_layout` reads such a file into one run in SI and fusionbench's body frame RFU (x right, y forward,
z up), with the validation and one-line :class:`~fusionbench.files.imufiles.IMUFileError` messages of
:mod:`fusionbench.files.imufiles`. Everything public of :mod:`fusionbench.files.layout_format` is re-exported here, so::

    from fusionbench.files.layouts import layout_from_name_or_file, read_layout
    imu, meta = read_layout(path, layout_from_name_or_file("kf-gins"))   # or a .toml format file

Increments: the row at time t holds the angle and velocity increments over ``(t - dt, t]`` (the convention of
fusionbench and KF-GINS), so the initial state belongs to ``t[0] - dt``. Times that jitter are read at their actual
times and put on a uniform grid, as by :mod:`fusionbench.files.imufiles` (:mod:`fusionbench.files.resample`); a
duplicate time, a reversal, a gap or too short a step is refused, naming the row.
"""

from __future__ import annotations

import numpy as np

from fusionbench.files.imufiles import (IMUFileError, _cell, _check_samples, _fspath, _is_number, _lines, _per_row,
                                        _result, _too_short)
from fusionbench.files.layout_format import (ACCEL_UNITS, AXES, BUILTIN_LAYOUTS, DELIMITERS, GYRO_UNITS, LAYOUT_KEYS,
                                             ROLES, TIME_UNITS, Layout, layout_from_name_or_file, load_layout)
from fusionbench.files.resample import intervals
from fusionbench.simulation.imudata import MAX_RATE_RADPS, MAX_SPECIFIC_FORCE_MPS2, sample_defect

__all__ = ["read_layout", "Layout", "load_layout", "layout_from_name_or_file", "BUILTIN_LAYOUTS", "LAYOUT_KEYS",
           "AXES", "ROLES", "DELIMITERS", "TIME_UNITS", "GYRO_UNITS", "ACCEL_UNITS"]


def _splitter(delimiter, sample):
    """A function splitting a line into fields; "auto" decides from the line ``sample``."""
    if delimiter == "auto":
        delimiter = next((c for c in DELIMITERS[1:-1] if c in sample), "whitespace")
    sep = None if delimiter == "whitespace" else delimiter
    return lambda s: s.split(sep)


def _field_indices(path, layout, names, width, source):
    """The field index of each of the seven columns; ``names`` the header's (lower case) or None."""
    out = []
    for c, role in zip(layout.columns, ROLES):
        if isinstance(c, str):
            count = names.count(c.lower())
            if count != 1:
                problem = "missing from the header" if count == 0 else f"appears {count} times in the header"
                raise IMUFileError(path, f"column '{c}' ({role}) {problem} (layout '{layout.name}'; found "
                                         f"{','.join(names)})")
            out.append(names.index(c.lower()))
        elif c >= width:
            raise IMUFileError(path, f"column {c} ({role}) out of range: {source} has {width} fields "
                                     f"(indices 0 to {width - 1}; layout '{layout.name}')")
        else:
            out.append(c)
    return out


def _check_channels(path, layout, gyro, accel, where, scale):
    """Finite samples within an IMU's range, SI but still in the file's axes, so the column named is the file's."""
    channels = {1: (gyro, MAX_RATE_RADPS, "rad/s", layout.gyro_unit),
                4: (accel, MAX_SPECIFIC_FORCE_MPS2, "m/s^2", layout.accel_unit)}
    note = ", an increment over its interval as a rate" if layout.kind == "increment" else ""
    for first, (block, limit, unit, read_as) in channels.items():
        defect = sample_defect(block[None] / scale, limit, unit)
        if defect is not None:
            (_, k, axis), text = defect
            j = first + "xyz".index(axis)
            raise IMUFileError(path, f"{text} at {where(k)}, column {layout.columns[j]!r} ({ROLES[j]}, read in "
                                     f"{read_as}{note})")


def read_layout(path, layout, min_samples=2):
    """Read a delimited text IMU log described by ``layout``.

    Parameters
    ----------
    path : str, bytes or path-like
        The log.
    layout : Layout or str
        A :class:`Layout`, a built-in name or a ``.toml`` format file (:func:`layout_from_name_or_file`).
    min_samples : int
        Fewest samples accepted (at least 2), counted after ``skip_rows``.

    Returns
    -------
    imu : IMUData
        One run, SI, body RFU: ``kind="rate"`` (rad/s, m/s^2 at ``t``) or ``"increment"`` (rad, m/s over
        ``(t - dt, t]``); ``t`` in s as in the file (times scaled by ``time_unit``, not shifted). Times that jitter:
        ``kind="increment"`` on the uniform grid from the first to the last time (an increment file's first interval
        one mean step long), :func:`fusionbench.files.resample.uniform_imu`.
    meta : dict
        ``path``, ``format`` (the layout's name), ``samples``, ``dt`` (s), ``resampled``, ``jitter_s`` (s),
        ``resampling_c_s2`` (s^2), ``kind`` (the file's), ``axes``, ``skipped_rows``.

    Raises
    ------
    IMUFileError
        One line naming the file and, where it applies, the row, line and column: no header, a column name
        missing or repeated in the header, a column index beyond the fields of a row, a row with another number
        of fields, a non-numeric, non-finite or out-of-range value, too few samples, a duplicate time, a reversal,
        a gap or too short a time step.
    """
    path = _fspath(path)
    layout = layout_from_name_or_file(layout)
    lines = _lines(path, layout.comment or ())
    names = None
    if layout.header:
        if not lines:
            raise IMUFileError(path, f"no header line found (layout '{layout.name}' names its columns "
                                     f"{','.join(str(c) for c in layout.columns)})")
        (head_no, head), lines = lines[0], lines[1:]
        split = _splitter(layout.delimiter, head)
        names = [c.strip().strip('"').lower() for c in split(head)]
        width, source = len(names), f"the header (line {head_no})"
    elif lines:
        split = _splitter(layout.delimiter, lines[0][1])
        width, source = len(split(lines[0][1])), f"row 0 (line {lines[0][0]})"
    else:
        _too_short(path, 0, min_samples)  # raises: no samples at all
    cells = [split(s) for _, s in lines]
    index = _field_indices(path, layout, names, width, source)
    for k, f in enumerate(cells):
        if len(f) != width:
            raise IMUFileError(path, f"row {k} (line {lines[k][0]}) has {len(f)} fields, expected {width} as in "
                                     f"{source}")
    skip = layout.skip_rows
    lines, cells = lines[skip:], cells[skip:]

    def where(k):
        return f"row {k + skip} (line {lines[k][0]})"

    picked = [[f[i] for i in index] for f in cells]  # the seven columns of each row, in the order of ROLES
    try:
        data = np.array(picked, dtype=float).reshape(-1, 7)
    except ValueError:  # the first offending cell, row by row
        k, j = next((k, j) for k, row in enumerate(picked) for j, x in enumerate(row) if not _is_number(x, float))
        hint = " (a header line? the layout says header = false)" if k + skip == 0 and not layout.header else ""
        raise IMUFileError(path, f"non-numeric value {_cell(picked[k][j].strip())} at {where(k)}, column "
                                 f"{layout.columns[j]!r} ({ROLES[j]}){hint}") from None
    t = data[:, 0] * TIME_UNITS[layout.time_unit]
    gyro = data[:, 1:4] * GYRO_UNITS[layout.kind][layout.gyro_unit]
    accel = data[:, 4:7] * ACCEL_UNITS[layout.kind][layout.accel_unit]
    scale = _per_row(intervals(t)) if layout.kind == "increment" and t.size else 1.0
    _check_channels(path, layout, gyro, accel, where, scale)
    gyro, accel = gyro @ layout.matrix.T, accel @ layout.matrix.T
    _check_samples(path, t, gyro, accel, min_samples, where, kind=layout.kind)
    imu, meta = _result(path, layout.name, t, gyro, accel, layout.kind)
    meta.update(kind=layout.kind, axes=layout.axes, skipped_rows=skip)
    return imu, meta
