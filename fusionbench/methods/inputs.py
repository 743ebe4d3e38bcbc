"""The checks of an aligner's data arguments: the IMU data, the velocity reference and the initial attitude.

:func:`check_inputs` is the first step of the input policy of :class:`fusionbench.methods.aligner_base.AlignerBase`
(which every registered method uses): data of the wrong type or with NaN or inf, a reference or an initial
attitude of the wrong shape, with NaN or inf, or an attitude that is not a rotation is refused with one line
naming the method and the argument, before any work.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation.imudata import IMUData


#: Largest departure of a given initial attitude from a rotation matrix, abs(C C^T - I) (max element).
ROTATION_TOL = 1e-6


def check_imu(imu, name: str = "method"):
    """Raise ValueError (one line naming ``imu``) unless ``imu`` is an :class:`IMUData` with finite samples."""
    if not isinstance(imu, IMUData):
        raise ValueError(f"{name}: imu: expected an IMUData, found {type(imu).__name__}")
    for field, a in (("gyro", imu.gyro), ("accel", imu.accel)):
        if not np.isfinite(a).all():
            raise ValueError(f"{name}: imu {field}: expected finite samples, found NaN or inf")


def check_init(init, runs: int, name: str = "method", required: bool = False):
    """An initial attitude checked and broadcast over the runs.

    Parameters
    ----------
    init : array_like, shape (3, 3) or (runs, 3, 3), or None
        Initial attitude ``C_bn`` (body RFU to ENU): finite rotation matrices (orthonormal within
        :data:`ROTATION_TOL`, determinant +1).
    runs : int
        Number of recordings R.
    name : str
        The method, for the message.
    required : bool
        Refuse None (a navigator starts from an alignment).

    Returns
    -------
    ndarray, shape (runs, 3, 3), or None

    Raises
    ------
    ValueError
        One line naming ``init``, what was expected and what was found.
    """
    if init is None:
        if required:
            raise ValueError(f"{name}: init: expected an initial attitude C_bn (navigation starts from an alignment), "
                             f"found none")
        return None
    C = np.asarray(init, dtype=float)
    if C.shape not in ((3, 3), (runs, 3, 3)):
        raise ValueError(f"{name}: init: expected an attitude matrix of shape (3, 3) or ({runs}, 3, 3), found {C.shape}")
    if not np.isfinite(C).all():
        raise ValueError(f"{name}: init: expected finite values, found NaN or inf")
    C = np.broadcast_to(C, (runs, 3, 3)).copy()
    off = np.abs(C @ np.swapaxes(C, -1, -2) - np.eye(3)).max()
    if off > ROTATION_TOL or (np.linalg.det(C) < 0).any():
        raise ValueError(f"{name}: init: expected rotation matrices (orthonormal, determinant +1), found "
                         f"|C C^T - I| = {off:.2g}" + (" and a reflection" if (np.linalg.det(C) < 0).any() else ""))
    return C


def check_inputs(imu: IMUData, vref=None, init=None, name: str = "method", init_required: bool = False):
    """The data arguments of an aligner: checked types, shapes and values.

    Parameters
    ----------
    imu : IMUData
        The recording (R runs): finite samples.
    vref : array_like, shape (R, M, 3) or (M, 3), optional
        Reference velocity, ENU m/s, at the end of each of the M increments of ``imu.increments()``
        (M = N for increments, N - 1 for rates); finite; (M, 3) is the same reference for every run.
    init : array_like, shape (3, 3) or (R, 3, 3), optional
        Initial attitude ``C_bn`` (:func:`check_init`).
    name : str
        The method, for the message.
    init_required : bool
        Refuse ``init=None`` (:func:`check_init`).

    Returns
    -------
    vref : ndarray (R, M, 3) or None
    init : ndarray (R, 3, 3) or None
        Broadcast over the runs.

    Raises
    ------
    ValueError
        One line naming ``imu``, ``vref`` or ``init``, what was expected and what was found.
    """
    check_imu(imu, name)
    runs = imu.runs
    m = imu.samples if imu.kind == "increment" else imu.samples - 1
    if vref is not None:
        vref = np.asarray(vref, dtype=float)
        if vref.shape not in ((runs, m, 3), (m, 3)):
            raise ValueError(f"{name}: vref: expected shape ({runs}, {m}, 3) or ({m}, 3) (runs, increments, ENU), "
                             f"found {vref.shape}")
        if vref.ndim == 2:
            vref = np.repeat(vref[None], runs, axis=0)
        if not np.isfinite(vref).all():
            raise ValueError(f"{name}: vref: expected finite velocities, found NaN or inf")
    return vref, check_init(init, runs, name, init_required)
