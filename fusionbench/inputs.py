"""The one input policy of every aligner for the velocity reference and the initial attitude.

:func:`check_inputs` is called first in each method's ``align``: a reference or an initial attitude of the
wrong shape, with NaN or inf, or not a rotation, is refused with one line naming the argument.
"""

from __future__ import annotations

import numpy as np

from .aligner import initial_attitude
from .imudata import IMUData


#: Largest departure of a given initial attitude from a rotation matrix, |C C^T - I| (max element).
ROTATION_TOL = 1e-6


def check_inputs(imu: IMUData, vref=None, init=None, name: str = "method"):
    """The one input policy of every aligner for ``vref`` and ``init``: checked shapes and values.

    Parameters
    ----------
    imu : IMUData
        The recording (R runs).
    vref : array_like, shape (R, M, 3) or (M, 3), optional
        Reference velocity, ENU m/s, at the end of each of the M increments of ``imu.increments()``
        (M = N for increments, N - 1 for rates); finite; (M, 3) is the same reference for every run.
    init : array_like, shape (3, 3) or (R, 3, 3), optional
        Initial attitude ``C_bn`` (body RFU to ENU): finite rotation matrices (orthonormal within
        :data:`ROTATION_TOL`, determinant +1).
    name : str
        The method, for the message.

    Returns
    -------
    vref : ndarray (R, M, 3) or None
    init : ndarray (R, 3, 3) or None
        Broadcast over the runs.

    Raises
    ------
    ValueError
        One line naming ``vref`` or ``init``, what was expected and what was found.
    """
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
    if init is not None:
        C = np.asarray(init, dtype=float)
        if C.shape not in ((3, 3), (runs, 3, 3)):
            raise ValueError(f"{name}: init: expected an attitude matrix of shape (3, 3) or ({runs}, 3, 3), "
                             f"found {C.shape}")
        if not np.isfinite(C).all():
            raise ValueError(f"{name}: init: expected finite values, found NaN or inf")
        C = initial_attitude(C, runs)
        off = np.abs(C @ np.swapaxes(C, -1, -2) - np.eye(3)).max()
        if off > ROTATION_TOL or (np.linalg.det(C) < 0).any():
            raise ValueError(f"{name}: init: expected rotation matrices (orthonormal, determinant +1), found "
                             f"|C C^T - I| = {off:.2g}" + (" and a reflection" if (np.linalg.det(C) < 0).any() else ""))
        init = C
    return vref, init
