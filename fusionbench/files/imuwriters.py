"""IMU file writers, atomic: CSV, NPZ and the PSINS ``.imu`` layout (formats: :mod:`fusionbench.files.imufiles`).

:mod:`fusionbench.files.imufiles` re-exports everything here, so ``from fusionbench.files.imufiles import write_csv``
works as before. Conventions: body frame RFU, SI, ``[pitch, roll, yaw]`` (rad) as in
:mod:`fusionbench.simulation.attitude`.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path

import numpy as np

from fusionbench.simulation.units import ARCSEC, DEG

__all__ = ["CSV_COLUMNS", "atomic_open", "write_csv", "write_npz", "write_psins"]

#: Required CSV columns, in the order the writer uses.
CSV_COLUMNS = ("t", "gx", "gy", "gz", "ax", "ay", "az")


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
