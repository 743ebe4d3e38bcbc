"""Layouts of other people's text IMU logs: the :class:`Layout` description, its TOML format file, the built-ins.

:mod:`fusionbench.files.layouts` reads a log with a layout (and re-exports everything here). A layout is built in
Python, loaded from a TOML format file (:func:`load_layout`, one ``[layout]`` table) or taken by name from
:data:`BUILTIN_LAYOUTS`; :func:`layout_from_name_or_file` does whichever applies. Reference of the format
file: ``docs/layouts.md``.

Axes
----
``axes`` names what the file's x, y, z axes point to (R right, F forward, U up, L left, D down). A vector is
taken from file axes to RFU by ``v_RFU = M v_file``; column j of ``M`` is file axis j written in RFU::

    "RFU"        x right,   y forward, z up    M = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]   (fusionbench's own)
    "FRD"        x forward, y right,   z down  M = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]
    "FLU"        x forward, y left,    z up    M = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    "NED-style"  an alias of "FRD" (the body axes that go with a north-east-down navigation frame)

Each ``M`` is a signed permutation with determinant +1, so the rotation is exact in floating point.

Kinds
-----
``"rate"``: angular rate and specific force sampled at the row's time. ``"increment"``: the row at time t holds
the angle and velocity increments over ``(t - dt, t]`` (the convention of fusionbench and KF-GINS), so the
initial state belongs to ``t[0] - dt``.

Built-ins
---------
``"pyins"``: the CSV pyins (PyPI ``python-ins``) writes with ``imu_dataframe.to_csv(path)``, header
``time,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z``, s, rad/s, m/s^2, body FRD
(``sim.generate_imu(..., sensor_type="rate")``). ``"pyins-increment"``: the same with ``sensor_type="increment"``
(rad, m/s). pyins repeats the first increment at the first time stamp ("the first sample is duplicated for more
convenient future processing", pyins/sim.py); this layout drops that row (``skip_rows=1``), so row k holds the
increment over ``(t_{k-1}, t_k]`` and the initial state belongs to the first time stamp. ``"kf-gins"``: the i2Nav
KF-GINS IMU text file, no header, whitespace separated, GNSS seconds of week (s), angle increments x y z (rad),
velocity increments x y z (m/s), body FRD. ``"fusionbench-csv"``: fusionbench's own CSV as a layout.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusionbench.simulation import fields
from fusionbench.simulation.imudata import SAMPLE_KINDS
from fusionbench.simulation.units import ARCSEC, DEG, DEG_PER_H, DEG_PER_S, G0, MICROSECOND, MILLISECOND, NANOSECOND

__all__ = ["Layout", "load_layout", "layout_from_name_or_file", "BUILTIN_LAYOUTS", "LAYOUT_KEYS", "AXES", "ROLES",
           "DELIMITERS", "TIME_UNITS", "GYRO_UNITS", "ACCEL_UNITS"]

#: Accepted ``delimiter`` values: "auto" takes the first of , ; tab | found in the header (or the first row),
#: else whitespace; "whitespace" splits at runs of spaces and tabs.
DELIMITERS = ("auto", ",", ";", "\t", "|", "whitespace")
#: Time units, s per unit.
TIME_UNITS = {"s": 1.0, "ms": MILLISECOND, "us": MICROSECOND, "ns": NANOSECOND}
#: Gyro units per kind, SI (rad/s or rad) per unit; the first is the default.
GYRO_UNITS = {"rate": {"rad/s": 1.0, "deg/s": DEG_PER_S, "deg/h": DEG_PER_H},
              "increment": {"rad": 1.0, "deg": DEG, "arcsec": ARCSEC}}
#: Accelerometer units per kind, SI (m/s^2 or m/s) per unit; the first is the default; "g" is G0 = 9.80665 m/s^2.
ACCEL_UNITS = {"rate": {"m/s^2": 1.0, "g": G0}, "increment": {"m/s": 1.0}}


def _matrix(rows):
    m = np.array(rows, dtype=float)
    m.setflags(write=False)
    return m


_FRD = _matrix([[0, 1, 0], [1, 0, 0], [0, 0, -1]])
#: File axes -> RFU: ``v_RFU = AXES[name] @ v_file`` (module docstring).
AXES = {"RFU": _matrix(np.eye(3)), "FRD": _FRD, "FLU": _matrix([[0, -1, 0], [1, 0, 0], [0, 0, 1]]),
        "NED-style": _FRD}
#: What each of the seven columns holds, in error messages (x, y, z are the file's axes).
ROLES = ("time", "gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z")


@dataclass(frozen=True)
class Layout:
    """Where a delimited text IMU log keeps its channels, and in which units and axes.

    Parameters
    ----------
    time : int or str
        The time column: a 0-based index, or a header name (needs ``header``); default 0.
    gyro, accel : sequence of 3 int or str
        The x, y, z columns of the gyro and the accelerometer (file axes); default (1, 2, 3) and (4, 5, 6).
    kind : {"rate", "increment"}
        Rates at the row's time, or increments over ``(t - dt, t]``.
    time_unit : {"s", "ms", "us", "ns"}
    gyro_unit : str, optional
        "rad/s", "deg/s", "deg/h" (rates) or "rad", "deg", "arcsec" (increments); default rad/s or rad.
    accel_unit : str, optional
        "m/s^2", "g" (rates; g = 9.80665 m/s^2) or "m/s" (increments); default m/s^2 or m/s.
    axes : {"RFU", "FRD", "FLU", "NED-style"}
        What the file's x, y, z point to (module docstring); the reader rotates into RFU.
    delimiter : str
        One of :data:`DELIMITERS`; default "auto".
    header : bool
        The first non-comment line names the columns; default False.
    comment : str
        Lines starting with it (after leading blanks) are skipped; "" for none; default "#".
    skip_rows : int
        Data rows dropped at the start (after the header), e.g. pyins's duplicated first increment; default 0.
    name, description : str
        The layout's name (``meta["format"]`` of a read) and a sentence about it.

    Raises
    ------
    fields.FieldError
        An invalid value; one line naming the field.
    """

    time: int | str = 0
    gyro: tuple = (1, 2, 3)
    accel: tuple = (4, 5, 6)
    kind: str = "rate"
    time_unit: str = "s"
    gyro_unit: str | None = None
    accel_unit: str | None = None
    axes: str = "RFU"
    delimiter: str = "auto"
    header: bool = False
    comment: str = "#"
    skip_rows: int = 0
    name: str = "layout"
    description: str = ""

    def __post_init__(self):
        given = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for key, value in _validated(given, "Layout", "").items():
            object.__setattr__(self, key, value)

    @property
    def columns(self):
        """The seven column specs in the order of :data:`ROLES`."""
        return (self.time, *self.gyro, *self.accel)

    @property
    def matrix(self):
        """File axes -> RFU, (3, 3): ``v_RFU = matrix @ v_file``."""
        return AXES[self.axes]


#: Keys of a format file's ``[layout]`` table: the fields of :class:`Layout`.
LAYOUT_KEYS = tuple(f.name for f in dataclasses.fields(Layout))
_DEFAULTS = {f.name: f.default for f in dataclasses.fields(Layout)}


def _is_index(v):
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0


def _columns(d, key, n, header, src, label):
    """The ``n`` column specs of ``key`` (a tuple; a single spec for n = 1), 0-based indices or header names."""
    v = d.get(key, _DEFAULTS[key])
    specs = [v] if n == 1 else list(v) if isinstance(v, (list, tuple)) else None
    if specs is None or len(specs) != n or not all(_is_index(c) or (isinstance(c, str) and c.strip()) for c in specs):
        what = "a column" if n == 1 else f"{n} columns (x, y, z)"
        raise fields.FieldError(f"{fields.where(src, label)}: expected {what}, each a 0-based index or a header "
                                f"name, found {v!r}")
    named = [c for c in specs if isinstance(c, str)]
    if named and not header:
        raise fields.FieldError(f"{fields.where(src, label)}: a column name ({named[0]!r}) needs header = true; "
                                f"without a header give 0-based indices")
    specs = tuple(c.strip() if isinstance(c, str) else int(c) for c in specs)
    return specs[0] if n == 1 else specs


def _validated(d, src, label):
    """The checked and completed values of a layout given as a dict (a ``[layout]`` table, a Layout's fields)."""
    def lab(key):
        return f"{label}.{key}" if label else key

    def bad(key, expected, found):
        return fields.FieldError(f"{fields.where(src, lab(key))}: expected {expected}, found {found!r}")

    d = {k: v for k, v in d.items() if v is not None}
    out = {key: fields.string(d, key, src, _DEFAULTS[key], choices, label=lab(key))
           for key, choices in (("name", None), ("description", None), ("delimiter", DELIMITERS),
                                ("comment", None), ("kind", SAMPLE_KINDS), ("time_unit", TIME_UNITS), ("axes", AXES))}
    if any(ch.isspace() for ch in out["comment"]):
        raise bad("comment", "a comment prefix without blanks ('' for none)", out["comment"])
    kind = out["kind"]
    for key, units in (("gyro_unit", GYRO_UNITS[kind]), ("accel_unit", ACCEL_UNITS[kind])):
        out[key] = fields.string(d, key, src, next(iter(units)), units, label=lab(key))
    out["header"] = d.get("header", _DEFAULTS["header"])
    if not isinstance(out["header"], bool):
        raise bad("header", "true or false", out["header"])
    out["skip_rows"] = d.get("skip_rows", _DEFAULTS["skip_rows"])
    if not _is_index(out["skip_rows"]):
        raise bad("skip_rows", "a number of rows >= 0", out["skip_rows"])
    out["skip_rows"] = int(out["skip_rows"])
    for key, n in (("time", 1), ("gyro", 3), ("accel", 3)):
        out[key] = _columns(d, key, n, out["header"], src, lab(key))
    cols = (out["time"], *out["gyro"], *out["accel"])
    seen = [c.lower() if isinstance(c, str) else c for c in cols]
    for j, c in enumerate(seen):
        if c in seen[:j]:
            key = ("time", "gyro", "accel")[(j + 2) // 3]
            raise fields.FieldError(f"{fields.where(src, lab(key))}: column {cols[j]!r} is already the "
                                    f"{ROLES[seen.index(c)]} column (each channel needs its own column)")
    return out


def load_layout(path):
    """A :class:`Layout` from a TOML format file holding one ``[layout]`` table (keys: :data:`LAYOUT_KEYS`).

    Without ``name`` the layout is named after the file. Reference: ``docs/layouts.md``.

    Raises
    ------
    ValueError
        One line naming the file (and the key, as a :class:`fusionbench.simulation.fields.FieldError`): a missing or
        unreadable file, invalid TOML, an unknown key or table, an invalid value.
    """
    src = os.fspath(path)
    data = fields.read_toml(path, "layout file")
    extra = sorted(set(data) - {"layout"})
    if extra:
        raise fields.FieldError(f"{fields.where(src, extra[0])}: unknown (a layout file holds one [layout] table)")
    if not isinstance(data.get("layout"), dict):
        raise fields.FieldError(f"{fields.where(src, 'layout')}: expected a [layout] table, found "
                                f"{'none' if 'layout' not in data else repr(data['layout'])}")
    table = dict(fields.table(data, "layout", src, LAYOUT_KEYS))
    table.setdefault("name", Path(path).stem)
    return Layout(**_validated(table, src, "layout"))


def _pyins(kind, **kw):
    return Layout(time="time", gyro=("gyro_x", "gyro_y", "gyro_z"), accel=("accel_x", "accel_y", "accel_z"),
                  kind=kind, axes="FRD", delimiter=",", header=True, **kw)


#: Built-in layouts by name (docs/layouts.md).
BUILTIN_LAYOUTS = {
    "pyins": _pyins("rate", name="pyins", description=(
        "pyins (PyPI python-ins) IMU DataFrame written with to_csv: header time,gyro_x,gyro_y,gyro_z,accel_x,"
        "accel_y,accel_z; s, rad/s, m/s^2; body FRD (sim.generate_imu(..., sensor_type='rate'))")),
    "pyins-increment": _pyins("increment", skip_rows=1, name="pyins-increment", description=(
        "the same with sensor_type='increment' (rad, m/s over (t_prev, t]); pyins repeats the first increment "
        "at the first time stamp: that row is dropped")),
    "kf-gins": Layout(time=0, gyro=(1, 2, 3), accel=(4, 5, 6), kind="increment", axes="FRD", delimiter="whitespace",
                      name="kf-gins", description=(
                          "i2Nav KF-GINS IMU text file: no header, 7 columns: GNSS seconds of week (s), angle "
                          "increments x y z (rad), velocity increments x y z (m/s) over (t - dt, t]; body FRD")),
    "fusionbench-csv": Layout(time="t", gyro=("gx", "gy", "gz"), accel=("ax", "ay", "az"), kind="rate", axes="RFU",
                              delimiter=",", header=True, name="fusionbench-csv", description=(
                                  "fusionbench's own CSV: t,gx,gy,gz,ax,ay,az; s, rad/s, m/s^2; body RFU")),
}


def layout_from_name_or_file(spec):
    """A :class:`Layout` from a built-in name (:data:`BUILTIN_LAYOUTS`), a ``.toml`` format file, or a Layout.

    Raises
    ------
    ValueError
        One line: an unknown name, or the format file's problem (:func:`load_layout`).
    """
    if isinstance(spec, Layout):
        return spec
    if isinstance(spec, str) and spec in BUILTIN_LAYOUTS:
        return BUILTIN_LAYOUTS[spec]
    if isinstance(spec, (str, os.PathLike)) and Path(spec).suffix.lower() == ".toml":
        return load_layout(spec)
    shown = os.fspath(spec) if isinstance(spec, os.PathLike) else spec
    raise ValueError(f"format: expected a built-in layout ({', '.join(BUILTIN_LAYOUTS)}) or a layout .toml file, "
                     f"found {shown!r}")
