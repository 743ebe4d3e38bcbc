"""Aiding files: the rows a receiver (GNSS, odometer) delivered, read into a
:class:`fusionbench.simulation.aiding.Aiding`.

Every reader gives one recording's rows with ``source`` the file's path; :func:`read_aiding` adds what the command
line knows and the file does not (the lever arm, the latency, the offset of the file's clock to the IMU's).
Formats (docs/aiding.md, "Files"):

``csv`` (default)
    A header naming the columns, in any order, case ignored: ``t`` (s, the IMU file's clock), ``vE,vN`` with an
    optional ``vU`` (m/s, ENU) and/or ``lat,lon`` with an optional ``h`` (deg, deg, m above the ellipsoid),
    optional ``sigma_v`` (m/s, each axis) and ``sigma_p`` (m, each axis, ENU), optional ``zupt`` (1: the base is at
    rest in that row, 0 or empty: not known). Lines starting with ``#`` are comments. An empty field (or ``nan``)
    is "not measured"; ``vE`` and ``vN`` are given together or not at all in a row, so are ``lat`` and ``lon``. A
    ``zupt`` row's empty velocity is zero. A sigma is needed in every row that gives its measurement; elsewhere
    it may be empty. **Unknown columns are refused** (a misspelled optional column, ``sigma_vel`` for
    ``sigma_v``, would otherwise be dropped without a word and change the weights).
``kf-gins``
    i2Nav KF-GINS's GNSS file, whitespace separated: 7 columns (GPS seconds of week, latitude deg, longitude deg,
    ellipsoid height m, position std north, east, down m) or 13 (the same four, then the velocity north, east,
    down m/s, the position std north, east, down m, the velocity std north, east, down m/s: KF-GINS's loader
    reads the position std from columns 7-9 of such a file). NED is turned to ENU.
``nmea``
    NMEA 0183 RMC, GGA, VTG and GST sentences (:mod:`fusionbench.files.aidingnmea`).

Bad input raises :class:`AidingFileError`: one line naming the file, the row and line or the field, what was
expected and what was found.
"""

from __future__ import annotations

import csv
import os

import numpy as np

from fusionbench.files.aidingnmea import read_nmea_rows
from fusionbench.files.aidingtext import AidingFileError, text_lines
from fusionbench.files.imufiles import _cell, _is_number
from fusionbench.simulation.aiding import MAX_LEVER_ARM_M, Aiding

__all__ = ["AidingFileError", "FORMATS", "CSV_COLUMNS", "read_aiding", "read_csv_rows", "read_kf_gins_rows",
           "text_lines", "aiding_summary", "kinds", "check_lever_arm", "write_csv"]

#: The ``--aiding-format`` names.
FORMATS = ("csv", "kf-gins", "nmea")
#: The columns an aiding CSV may hold, as the docs spell them (the header's case is ignored).
CSV_COLUMNS = ("t", "vE", "vN", "vU", "lat", "lon", "h", "sigma_v", "sigma_p", "zupt")
_CSV_HINT = "expected a header of t and vE,vN[,vU] and/or lat,lon[,h], optional sigma_v, sigma_p, zupt"
#: KF-GINS GNSS files: 7 columns (position) or 13 (position and velocity).
KF_GINS_WIDTHS = (7, 13)


def read_aiding(path, fmt="csv", lever_arm=(0.0, 0.0, 0.0), delay=0.0, time_offset=0.0) -> Aiding:
    """Read an aiding file (module docstring) into rows for one recording.

    Parameters
    ----------
    path : str or path-like
        The file; it is the rows' ``source`` (messages name it).
    fmt : {"csv", "kf-gins", "nmea"}
        Its format.
    lever_arm : (3,) array_like
        From the IMU to the antenna, body frame RFU (x right, y forward, z up), m.
    delay : float
        The receiver's latency, s: a row stamped t measures the antenna at t - delay.
    time_offset : float
        Added to every time of the file, s, to put it on the IMU file's clock (e.g. the IMU clock's reading at
        00:00 UTC, for NMEA's times of day).

    Returns
    -------
    Aiding
        ``t`` (K,) s on the IMU's clock; ``velocity`` (K, 3) ENU m/s and/or ``position`` (K, 3) (lat rad, lon rad,
        h m), NaN where a row does not measure it; sigmas (K, 3) or None; ``at_rest`` (K,) or None.

    Raises
    ------
    AidingFileError
        The file cannot be read, a column or field is missing or not a number, the times do not increase, there
        is no row. A ``ValueError`` naming the file and the row for values
        :class:`~fusionbench.simulation.aiding.Aiding` refuses (a speed beyond any vehicle's, a latitude beyond 90
        deg, a sigma not positive).
    """
    if fmt not in FORMATS:
        raise ValueError(f"--aiding-format: expected one of {', '.join(FORMATS)}, found {fmt!r}")
    if not np.isfinite(time_offset):
        raise ValueError(f"{path}: time offset: expected a finite number of s, found {time_offset!r}")
    if fmt == "nmea":
        rows = read_nmea_rows(path)
    else:
        rows = (read_csv_rows if fmt == "csv" else read_kf_gins_rows)(path)
    t = rows.pop("t")
    _check_times(path, t, rows.pop("where"))
    return Aiding(t + float(time_offset), **rows, lever_arm=np.asarray(lever_arm, dtype=float), delay=float(delay),
                  source=os.fspath(path))


def _check_times(path, t, where):
    """At least one row, finite and strictly increasing times (s); ``where(k)`` names row k."""
    if t.size == 0:
        raise AidingFileError(path, "no rows: expected at least one row of aiding, found none")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise AidingFileError(path, f"{where(bad[0])}: expected a finite time in s, found {t[bad[0]]}")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise AidingFileError(path, f"{where(k)}: expected strictly increasing times, found {t[k]:.10g} s after "
                                    f"{t[k - 1]:.10g} s ({where(k - 1)})")


# ------------------------------------------------------------------------------------------------------- csv
def read_csv_rows(path) -> dict:
    """The rows of an aiding CSV (module docstring) as the fields of :class:`~fusionbench.simulation.aiding.Aiding`
    (times not yet checked), with ``where(k)`` naming row k for messages."""
    lines = text_lines(path)
    if not lines:
        raise AidingFileError(path, f"no header line found ({_CSV_HINT})")
    header = [c.strip() for c in next(csv.reader([lines[0][1]]))]
    canonical = {c.lower(): c for c in CSV_COLUMNS}
    names = []
    for c in header:
        if c.lower() not in canonical:
            raise AidingFileError(path, f"unknown column {_cell(c)} in the header ({_CSV_HINT}; found "
                                        f"{','.join(header)})")
        names.append(canonical[c.lower()])
    for c in set(names):
        if names.count(c) > 1:
            raise AidingFileError(path, f"column '{c}' appears {names.count(c)} times in the header")
    for pair, third in ((("vE", "vN"), "vU"), (("lat", "lon"), "h")):  # a pair, with its optional third
        if any(c in names for c in (*pair, third)) and not all(c in names for c in pair):
            missing = next(c for c in pair if c not in names)
            raise AidingFileError(path, f"column '{missing}' missing ({_CSV_HINT}; found {','.join(header)})")
    if "t" not in names:
        raise AidingFileError(path, f"column 't' missing ({_CSV_HINT}; found {','.join(header)})")
    if not {"vE", "lat", "zupt"} & set(names):
        raise AidingFileError(path, f"no measurement column ({_CSV_HINT}; found {','.join(header)})")
    rows = lines[1:]
    fields = list(csv.reader([s for _, s in rows]))

    def where(k):
        return f"row {k} (line {rows[k][0]})"

    for k, f in enumerate(fields):
        if len(f) != len(names):
            raise AidingFileError(path, f"{where(k)} has {len(f)} fields, expected {len(names)} as in the header")
    cols = {c: _numbers(path, [f[names.index(c)] for f in fields], c, where) for c in names}
    K = len(fields)
    nan = np.full(K, np.nan)
    if np.isnan(cols["t"]).any():
        k = int(np.flatnonzero(np.isnan(cols["t"]))[0])
        raise AidingFileError(path, f"{where(k)}, column 't': expected a time in s, found an empty field")
    rest = None
    if "zupt" in cols:
        z = np.nan_to_num(cols["zupt"], nan=0.0)
        bad = np.flatnonzero((z != 0) & (z != 1))
        if bad.size:
            raise AidingFileError(path, f"{where(bad[0])}, column 'zupt': expected 1 (at rest), 0 or empty, found "
                                        f"{z[bad[0]]:g}")
        rest = z == 1
    out = {"t": cols["t"], "where": where, "at_rest": rest, "velocity": None, "position": None,
           "sigma_v": None, "sigma_p": None}
    given_v = _pair(path, cols, ("vE", "vN"), where)
    if given_v is not None or rest is not None:
        v = np.column_stack([cols.get(c, nan) for c in ("vE", "vN", "vU")])
        if rest is not None:  # a row at rest measures a zero velocity where the file leaves it empty
            v[rest] = np.where(np.isnan(v[rest]), 0.0, v[rest])
        out["velocity"] = v
    given_p = _pair(path, cols, ("lat", "lon"), where)
    if given_p is not None:
        out["position"] = np.column_stack([np.radians(cols["lat"]), np.radians(cols["lon"]), cols.get("h", nan)])
    for name, given, what in (("sigma_v", given_v, "a velocity"), ("sigma_p", given_p, "a position")):
        if name in cols:
            out[name] = _sigma(path, cols[name], given, name, what, where)
    return out


def _numbers(path, cells, name, where):
    """A column's cells as floats, NaN where empty or ``nan``; a non-number or an infinity is refused."""
    cells = [s.strip() for s in cells]
    try:  # the common case at once; the loop below finds what is wrong
        vals = np.array([s or "nan" for s in cells], dtype=float).reshape(-1)
        if not np.isinf(vals).any():
            return vals
    except ValueError:
        pass
    vals = np.full(len(cells), np.nan)
    for k, s in enumerate(cells):
        if s == "":
            continue
        if not _is_number(s, float):
            raise AidingFileError(path, f"{where(k)}, column '{name}': expected a number, found {_cell(s)}")
        vals[k] = float(s)
        if np.isinf(vals[k]):
            raise AidingFileError(path, f"{where(k)}, column '{name}': expected a finite number (empty where not "
                                        f"measured), found {_cell(s)}")
    return vals


def _pair(path, cols, pair, where):
    """Rows (K,) bool that give both columns of ``pair`` (None without the columns); one without the other is
    refused."""
    a, b = pair
    if a not in cols:
        return None
    fa, fb = np.isfinite(cols[a]), np.isfinite(cols[b])
    bad = np.flatnonzero(fa != fb)
    if bad.size:
        k = int(bad[0])
        have, lack = (a, b) if fa[k] else (b, a)
        raise AidingFileError(path, f"{where(k)}: column '{have}' given but '{lack}' empty: expected both or "
                                    f"neither")
    return fa


def _sigma(path, s, given, name, what, where):
    """A per-row sigma (K,) for every row: required where the row gives ``what`` (``given``), elsewhere the median
    of the given ones (unused, or the figure of a row at rest)."""
    given = np.zeros(s.size, bool) if given is None else given
    need = np.flatnonzero(given & np.isnan(s))
    if need.size:
        raise AidingFileError(path, f"{where(need[0])}, column '{name}': expected a standard deviation where the "
                                    f"row gives {what}, found an empty field")
    known = s[np.isfinite(s)]
    if known.size == 0:
        return None
    bad = np.flatnonzero(np.isfinite(s) & (s <= 0))
    if bad.size:
        raise AidingFileError(path, f"{where(bad[0])}, column '{name}': expected a positive standard deviation, "
                                    f"found {s[bad[0]]:g}")
    return np.where(np.isnan(s), np.median(known), s)


# ------------------------------------------------------------------------------------------------------- kf-gins
def read_kf_gins_rows(path) -> dict:
    """The rows of a KF-GINS GNSS file (module docstring) as the fields of
    :class:`~fusionbench.simulation.aiding.Aiding` (ENU; times not yet checked), with ``where(k)``."""
    rows = text_lines(path)

    def where(k):
        return f"row {k} (line {rows[k][0]})"

    fields = [s.split() for _, s in rows]
    width = len(fields[0]) if fields else 7
    if width not in KF_GINS_WIDTHS:
        raise AidingFileError(path, f"{where(0)} has {width} fields, expected 7 (time, lat, lon, h, std N, E, D) or "
                                    f"13 (time, lat, lon, h, vN, vE, vD, std N, E, D, vstd N, E, D)")
    for k, f in enumerate(fields):
        if len(f) != width:
            raise AidingFileError(path, f"{where(k)} has {len(f)} fields, expected {width} as the first row")
    names = ["time", "lat", "lon", "h"] + (["vN", "vE", "vD"] if width == 13 else []) + \
        ["std_N", "std_E", "std_D"] + (["vstd_N", "vstd_E", "vstd_D"] if width == 13 else [])
    a = np.empty((len(fields), width))
    for j, name in enumerate(names):
        for k, f in enumerate(fields):
            if not _is_number(f[j], float) or not np.isfinite(float(f[j])):
                raise AidingFileError(path, f"{where(k)}, field {j + 1} ({name}): expected a finite number, found "
                                            f"{_cell(f[j])}")
            a[k, j] = float(f[j])
    ned_to_enu = [1, 0, 2]
    out = {"t": a[:, 0], "where": where, "position": np.column_stack([np.radians(a[:, 1]), np.radians(a[:, 2]),
                                                                      a[:, 3]])}
    p_std = a[:, 4:7] if width == 7 else a[:, 7:10]
    out["sigma_p"] = p_std[:, ned_to_enu]
    if width == 13:
        v = a[:, 4:7][:, ned_to_enu]
        v[:, 2] *= -1.0  # down to up
        out["velocity"] = v
        out["sigma_v"] = a[:, 10:13][:, ned_to_enu]
    return out


# ------------------------------------------------------------------------------------------------------- describe
def kinds(aiding: Aiding) -> list:
    """What the rows measure, of ``["velocity", "position", "at_rest"]``: a horizontal velocity in some row not at
    rest, a horizontal position, rows at rest."""
    rest = np.zeros(aiding.t.size, bool) if aiding.at_rest is None else aiding.at_rest
    moving_v = aiding.velocity is not None and bool(
        (np.all(np.isfinite(aiding.velocity[..., :2]), axis=-1).reshape(-1, aiding.t.size) & ~rest).any())
    return [name for name, on in (("velocity", moving_v), ("position", aiding.has_position),
                                  ("at_rest", bool(rest.any()))) if on]


def aiding_summary(aiding: Aiding) -> dict:
    """The rows in a few JSON-ready figures: ``file``, ``rows``, ``kinds`` (:func:`kinds`), ``lever_arm_m`` (body
    RFU), ``delay_s``, ``t_first_s`` and ``t_last_s`` (the stamps on the IMU's clock)."""
    return {"file": aiding.source, "rows": int(aiding.t.size), "kinds": kinds(aiding),
            "lever_arm_m": [float(x) for x in aiding.lever_arm], "delay_s": float(aiding.delay),
            "t_first_s": float(aiding.t[0]), "t_last_s": float(aiding.t[-1])}


def write_csv(path, aiding: Aiding, run=0):
    """Write the rows of recording ``run`` as an aiding CSV (the ``csv`` format), atomically; returns the path.

    Columns: ``t`` (the stamps, s), ``vE,vN,vU`` (m/s) where the rows have a velocity, ``lat,lon,h`` (deg, deg, m)
    where they have a position, ``sigma_v`` and ``sigma_p`` (the largest axis of each row's sigmas: the format has
    one per row) where given, ``zupt`` where rows are at rest; NaN is written as an empty field. The lever arm and the
    latency are not in the file: they are the command line's (``--lever-arm``, ``--aiding-delay``).
    """
    from fusionbench.files.imufiles import atomic_open

    runs = aiding.runs
    aid = aiding if runs is None else aiding.select_runs([run])
    cols, data = ["t"], [aid.t]
    if aid.velocity is not None:
        cols += ["vE", "vN", "vU"]
        data += list(aid.velocity.reshape(-1, aid.t.size, 3)[0].T)
    if aid.position is not None:
        p = aid.position.reshape(-1, aid.t.size, 3)[0]
        cols += ["lat", "lon", "h"]
        data += [np.degrees(p[:, 0]), np.degrees(p[:, 1]), p[:, 2]]
    for name, sig in (("sigma_v", aid.sigma_v), ("sigma_p", aid.sigma_p)):
        if sig is not None:
            cols.append(name)
            data.append(sig.max(axis=1))
    if aid.at_rest is not None:
        cols.append("zupt")
        data.append(aid.at_rest.astype(float))
    lines = [",".join(cols)] + [",".join("" if np.isnan(x) else f"{x:.12g}" for x in row)
                                for row in np.column_stack(data)]
    with atomic_open(path) as fh:
        fh.write("\n".join(lines) + "\n")
    return path


def check_lever_arm(values, what="--lever-arm"):
    """Three finite numbers (m, body right, front, up) no longer than the aiding's limit, as an array; a one-line
    ValueError naming ``what`` otherwise."""
    v = np.asarray(values, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{what}: expected three numbers X,Y,Z in m (body right, front, up), found {values!r}")
    if np.linalg.norm(v) > MAX_LEVER_ARM_M:
        raise ValueError(f"{what}: expected at most {MAX_LEVER_ARM_M:g} m from the IMU to the antenna, found "
                         f"{np.linalg.norm(v):.6g} m (mm or cm read as m?)")
    return v
