"""IMU file readers and writers with validation: CSV, NPZ and the PSINS ``.imu`` layout.

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

Problems with a file raise :class:`IMUFileError` (one line). Writers are atomic.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path

import numpy as np

from .imudata import MAX_RATE_RADPS, MAX_SPECIFIC_FORCE_MPS2, IMUData, sample_defect, time_defect
from .units import ARCSEC, DEG

__all__ = ["IMUFileError", "read_imu", "read_csv", "read_npz", "read_psins",
           "write_csv", "write_npz", "write_psins", "atomic_open", "CSV_COLUMNS", "EXTENSIONS"]

#: Required CSV columns, in the order the writer uses.
CSV_COLUMNS = ("t", "gx", "gy", "gz", "ax", "ay", "az")
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


def _check_samples(path, t, gyro, accel, min_samples, where, scale=1.0):
    """Finite values within an IMU's range, enough samples, strictly increasing and uniform time; ``where(k)``
    names row k; ``scale`` turns a sample into a rate (the interval of an increment, 1 for rates)."""
    bad = time_defect(t)
    if bad and not np.isfinite(t[bad[0]]):  # a non-finite time first, like a non-finite sample
        raise IMUFileError(path, f"{bad[1]} at {where(bad[0])}, column 't'")
    for key, arr, limit, unit in (("g", gyro, MAX_RATE_RADPS, "rad/s"), ("a", accel, MAX_SPECIFIC_FORCE_MPS2, "m/s^2")):
        found = sample_defect(arr[None] / scale, limit, unit)
        if found:
            (_, k, axis), text = found
            raise IMUFileError(path, f"{text} at {where(k)}, column '{key}{axis}'"
                                     + (" (an increment over its interval, as a rate)" if scale != 1.0 else ""))
    _too_short(path, t.size, min_samples)
    if bad:
        k, what, detail = bad
        raise IMUFileError(path, f"{what} at {where(k)}: {detail}")


def _rate_result(path, fmt, t, gyro, accel):
    imu = IMUData(t, gyro[None], accel[None], kind="rate")
    return imu, {"path": os.fspath(path), "format": fmt, "samples": imu.samples, "dt": imu.dt}


def read_csv(path, min_samples=2):
    """Read a CSV IMU log (layout: module docstring).

    Parameters
    ----------
    path : str or path-like
        Columns t (s), gx, gy, gz (rad/s), ax, ay, az (m/s^2), body frame RFU.
    min_samples : int
        Fewest samples accepted (at least 2).

    Returns
    -------
    imu : IMUData
        ``kind="rate"``, one run.
    meta : dict
        ``path``, ``format`` ("csv"), ``samples``, ``dt`` (s).
    """
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
    return _rate_result(path, "csv", t, gyro, accel)


def read_npz(path, min_samples=2):
    """Read an NPZ IMU archive.

    Parameters
    ----------
    path : str or path-like
        Arrays ``t`` (N,) s, ``gyro`` (N, 3) rad/s, ``accel`` (N, 3) m/s^2, body frame RFU.
    min_samples : int
        Fewest samples accepted (at least 2).

    Returns
    -------
    imu : IMUData
        ``kind="rate"``, one run.
    meta : dict
        ``path``, ``format`` ("npz"), ``samples``, ``dt`` (s).
    """
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
    return _rate_result(path, "npz", t, gyro, accel)


def read_psins(path, min_samples=2):
    """Read a PSINS-layout ``.imu`` file of quantised increments (layout: module docstring).

    Parameters
    ----------
    path : str or path-like
        The file; body frame x right, y forward, z up.
    min_samples : int
        Fewest samples accepted (at least 2).

    Returns
    -------
    imu : IMUData
        ``kind="increment"``, one run: ``t = t0 + (k + 1) dt`` s for row k; ``gyro`` =
        ``counts * scale * arcsec`` (rad); ``accel`` = ``counts * scale * 1e-6 * g`` (m/s).
        In the 7-column variant the time dither (us) summed up to row k is added to its ``t``; the
        times must still be uniform to :data:`fusionbench.imudata.STEP_TOLERANCE`.
    meta : dict
        ``path``, ``format`` ("psins"), ``attitude0`` [pitch, roll, yaw] rad, ``v0`` [VE, VN, VU]
        m/s, ``lat``, ``lon`` rad, ``h`` m (the site of the recording), ``t0``, ``dt`` s, ``g``
        m/s^2, ``gyro_scale_arcsec``, ``accel_scale_ugs`` (3 each), ``samples``, ``columns`` (6 or 7).
    """
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
                   + (" (time from t0, dt and the dither column)" * (width == 7)), scale=dt)
    h = h.tolist()
    meta = {"path": os.fspath(path), "format": "psins", "attitude0": [a * DEG for a in h[0:3]],
            "v0": h[3:6], "lat": h[6] * DEG, "lon": h[7] * DEG, "h": h[8], "t0": h[9], "dt": dt,
            "g": g, "gyro_scale_arcsec": h[12:15], "accel_scale_ugs": h[15:18], "samples": len(t),
            "columns": width}
    return IMUData(t, gyro[None], accel[None], kind="increment"), meta


_READERS = {".csv": read_csv, ".npz": read_npz, ".imu": read_psins}


def read_imu(path, min_samples=2):
    """Read an IMU recording, choosing the reader by extension (.csv, .npz, .imu).

    Parameters
    ----------
    path : str or path-like
        See :func:`read_csv`, :func:`read_npz`, :func:`read_psins`.
    min_samples : int
        Fewest samples the caller (e.g. an alignment method) needs.

    Returns
    -------
    imu : IMUData
        One run, body RFU: kind "rate" (CSV, NPZ: rad/s, m/s^2) or "increment" (.imu: rad, m/s).
    meta : dict
        At least ``path`` and ``format``; for .imu also the header (``attitude0`` rad, ``v0``
        m/s, ``lat``, ``lon`` rad, ``h`` m, ``t0``, ``dt`` s, ``g`` m/s^2).

    Raises
    ------
    IMUFileError
        Unknown extension, unreadable file, missing column/array, bad field count, non-numeric
        or non-finite value, wrong shape, too few samples, non-increasing or non-uniform time,
        malformed PSINS header or data row.
    """
    ext = Path(path).suffix.lower()
    if ext not in _READERS:
        raise IMUFileError(path, f"unknown file extension '{ext or '(none)'}' "
                                 f"(accepted: {', '.join(EXTENSIONS)})")
    return _READERS[ext](path, min_samples=min_samples)


@contextlib.contextmanager
def atomic_open(path, binary=False):
    """Yield a temporary file next to ``path``; on success ``os.replace`` it onto ``path``."""
    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"{path}: cannot write it: its folder {path.parent} does not exist")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # mode honours the umask
    try:
        with (os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="\n")) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _rate_arrays(imu, run):
    """Times (s), angular rate (rad/s), specific force (m/s^2) of one run, checked finite."""
    if imu.kind == "rate":
        t, gyro, accel = imu.t, imu.gyro[run], imu.accel[run]
    else:  # the average rate over (t - dt, t] belongs to the interval's midpoint
        t, gyro, accel = imu.t - 0.5 * imu.dt, imu.gyro[run] / imu.dt, imu.accel[run] / imu.dt
    if not (np.isfinite(t).all() and np.isfinite(gyro).all() and np.isfinite(accel).all()):
        raise ValueError(f"run {run} holds non-finite values; nothing written")
    return t, gyro, accel


def write_csv(path, imu, run=0):
    """Write one run as a CSV IMU log, atomically; returns the path.

    Parameters
    ----------
    path : str or path-like
        Target file, replaced only once completely written.
    imu : IMUData
        Kind "rate" is written as it is; kind "increment" as average rates ``increment / dt``
        at the interval midpoints ``t - dt/2``. Columns ``t,gx,gy,gz,ax,ay,az`` in s, rad/s,
        m/s^2, body frame RFU, ``%.17g`` so reading back gives the same floats.
    run : int
        Which recording of the batch.
    """
    t, gyro, accel = _rate_arrays(imu, run)
    with atomic_open(path) as f:
        f.write(",".join(CSV_COLUMNS) + "\n")
        np.savetxt(f, np.column_stack([t, gyro, accel]), fmt="%.17g", delimiter=",")
    return Path(path)


def write_npz(path, imu, run=0):
    """Write one run as an NPZ archive, atomically; returns the path.

    Parameters
    ----------
    path : str or path-like
        Target file (no ``.npz`` is appended).
    imu : IMUData
        As in :func:`write_csv`: ``t`` (N,) s, ``gyro`` (N, 3) rad/s, ``accel`` (N, 3) m/s^2, RFU.
    run : int
        Which recording of the batch.
    """
    t, gyro, accel = _rate_arrays(imu, run)
    with atomic_open(path, binary=True) as f:
        np.savez(f, t=t, gyro=gyro, accel=accel)
    return Path(path)


def write_psins(path, imu, attitude0, v0=(0.0, 0.0, 0.0), *, lat, lon=0.0, h=0.0, g=9.780325,
                gyro_scale_arcsec=0.01, accel_scale_ugs=10.0, run=0):
    """Write one run as a PSINS-layout ``.imu`` file of integer counts, atomically.

    Parameters
    ----------
    path : str or path-like
        Target file.
    imu : IMUData
        Increments (rad, m/s, body RFU) as they are; rates are integrated first by
        :meth:`IMUData.increments` (trapezoid), so the initial state belongs to ``t[0]``.
    attitude0, v0 : sequence of 3 float
        Initial ``[pitch, roll, yaw]`` (rad, written in deg) and ``[VE, VN, VU]`` (m/s).
    lat, lon, h : float
        Latitude, longitude (rad, written in deg) and height (m).
    g : float
        Header gravity, m/s^2: an accelerometer count is ``accel_scale_ugs * 1e-6 * g`` m/s.
    gyro_scale_arcsec, accel_scale_ugs : float or sequence of 3
        Count sizes: arcsec per gyro count, ug*s per accelerometer count.
    run : int
        Which recording of the batch.

    Notes
    -----
    Quantisation carries each sample's fractional remainder into the next, so every cumulative
    sum of the counts stays within half a count of the exact one.
    """
    def vec3(name, v):  # what read_psins will ask of the header, asked before anything is written
        a = np.asarray(v, dtype=float)
        if a.shape != (3,) or not np.isfinite(a).all():
            raise ValueError(f"write_psins {name}: expected 3 finite numbers, found {v!r}")
        return a

    attitude0, v0 = vec3("attitude0", attitude0), vec3("v0", v0)
    for name, value, lo, hi in (("lat", lat, -np.pi / 2, np.pi / 2), ("lon", lon, -2 * np.pi, 2 * np.pi),
                                ("h", h, -1e4, 1e5), ("g", g, 1.0, 20.0)):
        if not (np.isfinite(value) and lo <= value <= hi):
            raise ValueError(f"write_psins {name}: expected a finite number in [{lo:g}, {hi:g}], found {value!r}")
    if not (isinstance(run, (int, np.integer)) and 0 <= run < imu.runs):
        raise ValueError(f"write_psins run: expected a recording index in [0, {imu.runs - 1}], found {run!r}")
    t_end, dth, dv = imu.increments()
    dt = float((t_end[-1] - t_end[0]) / (t_end.size - 1)) if t_end.size > 1 else imu.dt
    gs = np.broadcast_to(np.asarray(gyro_scale_arcsec, dtype=float), (3,))
    acs = np.broadcast_to(np.asarray(accel_scale_ugs, dtype=float), (3,))
    if not (np.all(gs > 0) and np.all(acs > 0)):
        raise ValueError(f"write_psins gyro_scale_arcsec, accel_scale_ugs: expected positive count sizes, found "
                         f"{gyro_scale_arcsec!r}, {accel_scale_ugs!r}")
    x = np.column_stack([dth[run] / (gs * ARCSEC), dv[run] / (acs * 1e-6 * g)])
    if not np.isfinite(x).all() or np.abs(x).sum(axis=0).max() > 2.0 ** 62:
        raise ValueError(f"run {run} holds non-finite or out-of-range values; nothing written")
    # Residual carry (counts[k] = round(x[k] + remainder[k-1])) = differences of rounded cumsums.
    cum = np.rint(np.cumsum(x, axis=0)).astype(np.int64)
    counts = np.diff(cum, axis=0, prepend=np.zeros((1, 6), dtype=np.int64))
    rows = [[*(attitude0 / DEG), *v0],
            [lat / DEG, lon / DEG, h, t_end[0] - dt, dt * 1e3, g], [*gs, *acs]]
    with atomic_open(path) as f:
        f.write("% PSINS-format SIMU log file written by fusionbench.\n"
                "% 1st: [pitch0 roll0 yaw0 (deg) VE0 VN0 VU0 (m/s)]\n"
                "% 2nd: [lat0 lon0 (deg) h0 (m) t0 (s) sampling interval (ms) g (m/s^2)]\n"
                "% 3rd: [gyro scale (arcsec/count) x3, accel scale (ug*s/count) x3]\n\n")
        for r in rows:
            f.write(" ".join("%.17g" % v for v in r) + "\n")
        np.savetxt(f, counts, fmt="%d", delimiter=" ")
    return Path(path)
