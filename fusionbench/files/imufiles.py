"""IMU file readers with validation: CSV, NPZ and the PSINS ``.imu`` layout (the writers, re-exported here, are in
:mod:`fusionbench.files.imuwriters`).

Conventions (see the contract): body frame b is Right-Front-Up (x right, y forward, z up);
navigation frame n is East-North-Up; Euler angles are ``[pitch, roll, yaw]`` (rad) with
``C_bn = Rz(yaw) Rx(pitch) Ry(roll)``, yaw counter-clockwise from north. Arrays are SI.

Formats
-------
CSV
    Header ``t,gx,gy,gz,ax,ay,az`` (any order, extra columns ignored, ``#`` lines are comments):
    time s, angular rate rad/s, specific force m/s^2. Read as ``IMUData(kind="rate")``.
NPZ
    Arrays ``t`` (N,), ``gyro`` (N, 3), ``accel`` (N, 3) in the same units; kind "rate".
PSINS ``.imu``
    ``%`` comment and blank lines, then three header rows
    ``[pitch0 roll0 yaw0 (deg) VE0 VN0 VU0 (m/s)]``,
    ``[lat0 lon0 (deg) h0 (m) t0 (s) sampling interval (ms) g (m/s^2)]``,
    ``[gyro scale (arcsec/count) x3, accel scale (ug*s/count) x3]``, then one row of six integer
    counts per sample (gyro x, y, z, accel x, y, z). Read as ``IMUData(kind="increment")``.
    PSINS's own writer (``imufile.m``) also makes a 7-column variant when the sampling times
    jitter: each header row ends with a 0, and each sample row with the integer time dither in
    microseconds; sample k is then at ``t0 + (k + 1) dt + 1e-6 * (dither_0 + ... + dither_k)``.

Times (all formats)
    Uniform (to 1e-3 of the step), the samples are read as they are. Times that jitter (every step
    within 0.5 to 1.5 nominal steps) are read at their actual times and put on a uniform grid of
    the same span, kind "increment" (:mod:`fusionbench.files.resample`: the scheme, its error bound and
    the limits). A duplicate time, a reversal, a gap (a step of 1.5 nominal steps or more: a sample
    or more missing) or too short a step is refused, naming the row.

Paths are a str, a bytes path or an ``os.PathLike``. Problems with a file raise :class:`IMUFileError`
(one line). Writers are atomic.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from fusionbench.files.imuwriters import CSV_COLUMNS, atomic_open, write_csv, write_npz, write_psins
from fusionbench.files.resample import intervals, timing_defect, uniform_imu
from fusionbench.simulation.imudata import MAX_RATE_RADPS, MAX_SPECIFIC_FORCE_MPS2, sample_defect
from fusionbench.simulation.units import ARCSEC, DEG

__all__ = ["IMUFileError", "read_imu", "read_csv", "read_npz", "read_psins",
           "write_csv", "write_npz", "write_psins", "atomic_open", "CSV_COLUMNS", "EXTENSIONS"]

#: Accepted file extensions.
EXTENSIONS = (".csv", ".npz", ".imu")
_HINT = "expected header " + ",".join(CSV_COLUMNS)
_PSINS_FIELDS = (("pitch0", "roll0", "yaw0", "VE0", "VN0", "VU0"),
                 ("lat0", "lon0", "h0", "t0", "dt_ms", "g"),
                 ("gyro_scale_x", "gyro_scale_y", "gyro_scale_z",
                  "accel_scale_x", "accel_scale_y", "accel_scale_z"))


class IMUFileError(ValueError):
    """A missing, unreadable or malformed IMU file; message ``"<path>: <problem>"`` on one line."""

    def __init__(self, path, problem=None):
        if problem is None:  # rebuilt from its message (unpickling)
            path, _, problem = str(path).partition(": ")
        self.path = os.fspath(path)
        self.problem = " ".join(str(problem).split())
        super().__init__(f"{self.path}: {self.problem}")


def _fspath(path):
    """``path`` as a str: a str, a bytes path (decoded as the file system does) or an ``os.PathLike``; anything else
    is a one-line TypeError."""
    try:
        return os.fsdecode(path)
    except TypeError:
        raise TypeError(f"IMU file path: expected a str, bytes or os.PathLike, found {type(path).__name__} "
                        f"{_cell(repr(path))}") from None


def _cell(s, limit=40):
    return repr(s if len(s) <= limit else s[:limit] + "...")


def _open_error(path, e):
    if isinstance(e, FileNotFoundError):
        return IMUFileError(path, "file not found")
    if isinstance(e, IsADirectoryError):
        return IMUFileError(path, "is a directory, expected a file")
    return IMUFileError(path, f"cannot read file ({e.strerror or e})")


def _lines(path, comment):
    """Non-blank, non-comment lines as (line number, text)."""
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise IMUFileError(path, f"not a text file (undecodable byte at offset {e.start})") from None
    except OSError as e:
        raise _open_error(path, e) from None
    return [(i + 1, s) for i, s in enumerate(text.splitlines())
            if s.strip() and not s.lstrip().startswith(comment)]


def _is_number(s, kind):
    try:
        kind(s)
        return True
    except (ValueError, OverflowError):
        return False


def _too_short(path, n, min_samples):
    need = max(int(min_samples), 2)
    if n < need:
        raise IMUFileError(path, f"too short: {n} samples, the method needs at least {need}")


def _check_samples(path, t, gyro, accel, min_samples, where, kind="rate", t_start=None):
    """Finite values within an IMU's range, enough samples, and times that are uniform or jitter (no duplicate,
    reversal, gap or too short a step: :func:`fusionbench.files.resample.timing_defect`); ``where(k)`` names row k; an
    increment is checked as a rate over its interval (the first from ``t_start``)."""
    bad = timing_defect(t, t_start)
    if bad and not np.isfinite(t[bad[0]]):  # a non-finite time first, like a non-finite sample
        raise IMUFileError(path, f"{bad[1]} at {where(bad[0])}, column 't'")
    scale = _per_row(intervals(t, t_start)) if kind == "increment" else 1.0
    for key, arr, limit, unit in (("g", gyro, MAX_RATE_RADPS, "rad/s"), ("a", accel, MAX_SPECIFIC_FORCE_MPS2, "m/s^2")):
        found = sample_defect(arr[None] / scale, limit, unit)
        if found:
            (_, k, axis), text = found
            raise IMUFileError(path, f"{text} at {where(k)}, column '{key}{axis}'"
                                     + (" (an increment over its interval, as a rate)" if kind == "increment" else ""))
    _too_short(path, t.size, min_samples)
    if bad:
        k, what, detail = bad
        raise IMUFileError(path, f"{what} at {where(k)}" + (f": {detail}" if detail else ""))


def _per_row(scale):
    """Row intervals (N,) as a divisor of (runs, N, 3) samples; a scalar as it is."""
    scale = np.asarray(scale, dtype=float)
    return scale[:, None] if scale.ndim else float(scale)


def _result(path, fmt, t, gyro, accel, kind="rate", t_start=None):
    """The checked samples as one run on a uniform grid (:func:`fusionbench.files.resample.uniform_imu`) and their
    meta."""
    try:
        imu, info = uniform_imu(t, gyro, accel, kind, t_start)
    except ValueError as e:  # what the container refuses after the checks above: one line, naming the file
        raise IMUFileError(path, str(e)) from None
    return imu, {"path": os.fspath(path), "format": fmt, "samples": imu.samples, "dt": imu.dt, **info}


def read_csv(path, min_samples=2):
    """Read a CSV IMU log (layout: module docstring).

    Parameters
    ----------
    path : str, bytes or path-like
        Columns t (s), gx, gy, gz (rad/s), ax, ay, az (m/s^2), body frame RFU.
    min_samples : int
        Fewest samples accepted (at least 2).

    Returns
    -------
    imu : IMUData
        ``kind="rate"``, one run; ``kind="increment"`` on a uniform grid when the times jitter
        (module docstring).
    meta : dict
        ``path``, ``format`` ("csv"), ``samples``, ``dt`` (s), ``resampled``, ``jitter_s``, ``resampling_c_s2``.
    """
    path = _fspath(path)
    lines = _lines(path, "#")
    if not lines:
        raise IMUFileError(path, f"no header line found ({_HINT})")
    names = [c.strip().lower() for c in lines[0][1].split(",")]
    for c in CSV_COLUMNS:
        if c not in names:
            raise IMUFileError(path, f"column '{c}' missing ({_HINT}; found {','.join(names)})")
        if names.count(c) > 1:
            raise IMUFileError(path, f"column '{c}' appears {names.count(c)} times in the header")
    rows = lines[1:]
    fields = [s.split(",") for _, s in rows]
    for k, f in enumerate(fields):
        if len(f) != len(names):
            raise IMUFileError(path, f"row {k} (line {rows[k][0]}) has {len(f)} fields, "
                                     f"expected {len(names)} as in the header")
    cols = {}
    for c in CSV_COLUMNS:
        cells = [f[names.index(c)] for f in fields]
        try:
            cols[c] = np.array(cells, dtype=float).reshape(-1)
        except ValueError:
            k = next(k for k, s in enumerate(cells) if not _is_number(s, float))
            raise IMUFileError(path, f"non-numeric value {_cell(cells[k].strip())} at row {k} "
                                     f"(line {rows[k][0]}), column '{c}'") from None
    t = cols["t"]
    gyro = np.column_stack([cols[c] for c in ("gx", "gy", "gz")]).reshape(-1, 3)
    accel = np.column_stack([cols[c] for c in ("ax", "ay", "az")]).reshape(-1, 3)
    _check_samples(path, t, gyro, accel, min_samples, lambda k: f"row {k} (line {rows[k][0]})")
    return _result(path, "csv", t, gyro, accel)


def read_npz(path, min_samples=2):
    """Read an NPZ IMU archive.

    Parameters
    ----------
    path : str, bytes or path-like
        Arrays ``t`` (N,) s, ``gyro`` (N, 3) rad/s, ``accel`` (N, 3) m/s^2, body frame RFU.
    min_samples : int
        Fewest samples accepted (at least 2).

    Returns
    -------
    imu : IMUData
        ``kind="rate"``, one run; ``kind="increment"`` on a uniform grid when the times jitter
        (module docstring).
    meta : dict
        ``path``, ``format`` ("npz"), ``samples``, ``dt`` (s), ``resampled``, ``jitter_s``, ``resampling_c_s2``.
    """
    path = _fspath(path)
    arrays = {}
    try:
        z = np.load(path, allow_pickle=False)
        if not hasattr(z, "files"):
            raise IMUFileError(path, "not an NPZ archive (found a single .npy array)")
        with z:
            for name in ("t", "gyro", "accel"):
                if name not in z.files:
                    raise IMUFileError(path, f"array '{name}' missing (expected arrays t (N,), gyro (N, 3), "
                                             f"accel (N, 3); found {', '.join(z.files) or 'none'})")
                arrays[name] = z[name]
    except IMUFileError:
        raise
    except OSError as e:
        raise _open_error(path, e) from None
    except ValueError as e:
        if "allow_pickle" in str(e):  # numpy refuses object arrays without unpickling them; so do we, always
            raise IMUFileError(path, "holds object (pickled) arrays, expected numeric arrays t, gyro and accel "
                                     "(fusionbench never unpickles a file)") from None
        raise IMUFileError(path, f"not a valid NPZ archive ({type(e).__name__}: {e})") from None
    except Exception as e:  # zipfile.BadZipFile, corrupt headers
        raise IMUFileError(path, f"not a valid NPZ archive ({type(e).__name__}: {e})") from None
    for name, a in arrays.items():
        if a.dtype.kind not in "iuf":
            raise IMUFileError(path, f"array '{name}' has dtype {a.dtype}, expected real numbers")
    n = arrays["t"].size
    if arrays["t"].ndim != 1:
        raise IMUFileError(path, f"array 't' has shape {arrays['t'].shape}, expected (N,)")
    for name in ("gyro", "accel"):
        if arrays[name].shape != (n, 3):
            raise IMUFileError(path, f"array '{name}' has shape {arrays[name].shape}, expected ({n}, 3)")
    t, gyro, accel = (np.asarray(arrays[k], dtype=float) for k in ("t", "gyro", "accel"))
    _check_samples(path, t, gyro, accel, min_samples, lambda k: f"index {k}")
    return _result(path, "npz", t, gyro, accel)


def read_psins(path, min_samples=2):
    """Read a PSINS-layout ``.imu`` file of quantised increments (layout: module docstring).

    Parameters
    ----------
    path : str, bytes or path-like
        The file; body frame x right, y forward, z up.
    min_samples : int
        Fewest samples accepted (at least 2).

    Returns
    -------
    imu : IMUData
        ``kind="increment"``, one run: ``t = t0 + (k + 1) dt`` s for row k; ``gyro`` =
        ``counts * scale * arcsec`` (rad); ``accel`` = ``counts * scale * 1e-6 * g`` (m/s).
        In the 7-column variant the time dither (us) summed up to row k is added to its ``t``; times
        that jitter beyond :data:`fusionbench.simulation.imudata.STEP_TOLERANCE` are resampled onto the uniform
        grid from t0 to the last time (:func:`fusionbench.files.resample.uniform_imu`, the first interval
        starting at t0).
    meta : dict
        ``path``, ``format`` ("psins"), ``attitude0`` [pitch, roll, yaw] rad, ``v0`` [VE, VN, VU]
        m/s, ``lat``, ``lon`` rad, ``h`` m (the site of the recording), ``t0``, ``dt`` s, ``g``
        m/s^2, ``gyro_scale_arcsec``, ``accel_scale_ugs`` (3 each), ``samples``, ``columns`` (6 or 7),
        ``resampled``, ``jitter_s``, ``resampling_c_s2`` (:func:`fusionbench.files.resample.uniform_imu`).
    """
    path = _fspath(path)
    lines = _lines(path, "%")
    if len(lines) < 3:
        raise IMUFileError(path, f"expected 3 header rows after the '%' comments, found {len(lines)}")
    head = []
    for r, (ln, s) in enumerate(lines[:3]):
        f, names = s.split(), _PSINS_FIELDS[r]
        where = f"header row {r + 1} (line {ln})"
        if len(f) not in (6, 7):
            raise IMUFileError(path, f"{where} has {len(f)} fields, expected 6 ({' '.join(names)}), or 7 with "
                                     f"PSINS's trailing 0")
        for x, name in zip(f, (*names, "(7th)")):
            if not _is_number(x, float):
                raise IMUFileError(path, f"{where}: field '{name}' is {_cell(x)}, expected a number")
            pos = (r == 2 or name in ("dt_ms", "g")) and name != "(7th)"
            if not np.isfinite(float(x)) or (pos and float(x) <= 0):
                raise IMUFileError(path, f"{where}: field '{name}' is {x}, expected a "
                                         f"{'positive ' if pos else ''}finite number")
            if name != "(7th)":
                head.append(float(x))
    rows = lines[3:]
    fields = [s.split() for _, s in rows]
    width = len(fields[0]) if fields and len(fields[0]) in (6, 7) else 6
    for k, f in enumerate(fields):
        if len(f) != width:
            raise IMUFileError(path, f"sample row {k} (line {rows[k][0]}) has {len(f)} fields, expected {width} "
                                     f"integers (gyro x y z, accel x y z{', time dither (us)' * (width == 7)}"
                                     f"{' as in sample row 0' * (k > 0)})")
    try:
        counts = np.array(fields, dtype=np.int64).reshape(-1, width)
    except (ValueError, OverflowError):
        k, x = next((k, x) for k, f in enumerate(fields) for x in f
                    if not _is_number(x, int) or not -2**63 <= int(x) < 2**63)
        raise IMUFileError(path, f"sample row {k} (line {rows[k][0]}): {_cell(x)} is not an "
                                 f"integer count (64-bit)") from None
    _too_short(path, counts.shape[0], min_samples)
    h = np.array(head)
    dt, g = float(h[10]) * 1e-3, float(h[11])
    # PSINS's time rule (imufile.m): row k ends at t0 + (k + 1) dt, plus the dither summed so far (us)
    t = h[9] + dt * np.arange(1, counts.shape[0] + 1)
    if width == 7:
        t = t + np.cumsum(counts[:, 6]) * 1e-6
    gyro = counts[:, :3] * (h[12:15] * ARCSEC)
    accel = counts[:, 3:6] * (h[15:18] * 1e-6 * g)
    _check_samples(path, t, gyro, accel, min_samples, lambda k: f"sample row {k} (line {rows[k][0]})"
                   + (" (time from t0, dt and the dither column)" * (width == 7)), kind="increment", t_start=h[9])
    imu, meta = _result(path, "psins", t, gyro, accel, "increment", t_start=h[9])
    h = h.tolist()
    meta.update({"attitude0": [a * DEG for a in h[0:3]], "v0": h[3:6], "lat": h[6] * DEG, "lon": h[7] * DEG,
                 "h": h[8], "t0": h[9], "dt": dt, "g": g, "gyro_scale_arcsec": h[12:15],
                 "accel_scale_ugs": h[15:18], "columns": width})
    return imu, meta


_READERS = {".csv": read_csv, ".npz": read_npz, ".imu": read_psins}


def read_imu(path, min_samples=2):
    """Read an IMU recording, choosing the reader by extension (.csv, .npz, .imu).

    Parameters
    ----------
    path : str, bytes or path-like
        See :func:`read_csv`, :func:`read_npz`, :func:`read_psins`.
    min_samples : int
        Fewest samples the caller (e.g. an alignment method) needs.

    Returns
    -------
    imu : IMUData
        One run, body RFU: kind "rate" (CSV, NPZ: rad/s, m/s^2) or "increment" (.imu: rad, m/s);
        "increment" on a uniform grid for any file whose times jitter (module docstring).
    meta : dict
        At least ``path`` (a str), ``format``, ``samples``, ``dt`` s, ``resampled``, ``jitter_s``
        s and ``resampling_c_s2`` s^2; for .imu also the header (``attitude0`` rad, ``v0`` m/s,
        ``lat``, ``lon`` rad, ``h`` m, ``t0``, ``dt`` s, ``g`` m/s^2).

    Raises
    ------
    IMUFileError
        Unknown extension, unreadable file, missing column/array, bad field count, non-numeric
        or non-finite value, wrong shape, too few samples, a duplicate time, a reversal, a gap or
        too short a time step, malformed PSINS header or data row.
    TypeError
        A path that is not a str, bytes or os.PathLike (one line).
    """
    path = _fspath(path)
    ext = Path(path).suffix.lower()
    if ext not in _READERS:
        raise IMUFileError(path, f"unknown file extension '{ext or '(none)'}' "
                                 f"(accepted: {', '.join(EXTENSIONS)})")
    return _READERS[ext](path, min_samples=min_samples)
