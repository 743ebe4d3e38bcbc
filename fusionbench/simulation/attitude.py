"""Attitude conventions on top of :class:`scipy.spatial.transform.Rotation`.

Frames
------
n : navigation frame, East-North-Up (ENU).
b : body frame, Right-Front-Up (x right, y forward, z up).

Attitude is the direction cosine matrix ``C_bn`` (written C_b^n), which takes a vector from b to n:
``v_n = C_bn @ v_b``.

Euler angles (Chinese-textbook / PSINS convention)
--------------------------------------------------
``C_bn = Rz(yaw) @ Rx(pitch) @ Ry(roll)``: yaw about up, then pitch about the new right axis,
then roll about the new forward axis. Yaw is counter-clockwise from north; the heading
(clockwise from north) is ``(-yaw) mod 2 pi``. Angle triples are ordered ``[pitch, roll, yaw]``
(rad) like PSINS' ``att``.

Misalignment
------------
``phi = [phiE, phiN, phiU]`` is defined by ``C_bn_est = (I - [phi x]) C_bn_true``. For finite
angles the exact form ``C_bn_est = exp(-[phi x]) C_bn_true`` is used, so phi is the rotation
vector of ``C_bn_true C_bn_est^T`` (rad).

Euler platform error angles (seed 000, Zhou 2011, ADRC gyrocompass)
-------------------------------------------------------------------
The computed frame n' is reached from n by three rotations z, x, y through
``alpha = [ax, ay, az]``: ``C_n'n = Rz(az) Rx(ax) Ry(ay)``, i.e. the paper's matrix
``C_n^n' = C_n'n^T``, and ``C_bn' = C_n^n' C_bn``. For small angles alpha equals phi.

Every function is batched over leading axes.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

_ORDER = "ZXY"  # scipy intrinsic sequence: R = Rz(a) Rx(b) Ry(c)


def _flat(x, tail):
    x = np.asarray(x, dtype=float)
    return x.reshape((-1,) + tail), x.shape[: x.ndim - len(tail)]


def euler_to_dcm(angles):
    """C_bn from Euler angles ``[pitch, roll, yaw]`` (rad), shape ``(..., 3)`` -> ``(..., 3, 3)``.

    Closed form of ``Rz(yaw) Rx(pitch) Ry(roll)`` (equal to scipy's intrinsic "ZXY" rotation, and
    some 20 times faster for the millions of samples the simulator evaluates).
    """
    a = np.asarray(angles, dtype=float)
    sp, cp = np.sin(a[..., 0]), np.cos(a[..., 0])
    sr, cr = np.sin(a[..., 1]), np.cos(a[..., 1])
    sy, cy = np.sin(a[..., 2]), np.cos(a[..., 2])
    C = np.empty(a.shape[:-1] + (3, 3))
    C[..., 0, 0] = cy * cr - sy * sp * sr
    C[..., 0, 1] = -sy * cp
    C[..., 0, 2] = cy * sr + sy * sp * cr
    C[..., 1, 0] = sy * cr + cy * sp * sr
    C[..., 1, 1] = cy * cp
    C[..., 1, 2] = sy * sr - cy * sp * cr
    C[..., 2, 0] = -cp * sr
    C[..., 2, 1] = sp
    C[..., 2, 2] = cp * cr
    return C


def dcm_to_euler(C_bn):
    """Euler angles ``[pitch, roll, yaw]`` (rad) of ``C_bn``, shape ``(..., 3, 3)`` -> ``(..., 3)``.

    Pitch lies in [-pi/2, pi/2], roll and yaw in (-pi, pi].
    """
    c, lead = _flat(C_bn, (3, 3))
    # Direct formulas keep full precision near level (scipy's generic path loses ~1e-9).
    pitch = np.arcsin(np.clip(c[:, 2, 1], -1.0, 1.0))
    roll = np.arctan2(-c[:, 2, 0], c[:, 2, 2])
    yaw = np.arctan2(-c[:, 0, 1], c[:, 1, 1])
    return np.stack([pitch, roll, yaw], axis=-1).reshape(lead + (3,))


def heading(yaw):
    """Heading clockwise from north, rad in [0, 2 pi), from yaw (counter-clockwise from north, rad)."""
    return np.mod(-np.asarray(yaw, dtype=float), 2 * np.pi)


def dcm_to_quat(C_bn):
    """Quaternion ``[w, x, y, z]`` (scalar first, w >= 0) of ``C_bn``, shape ``(..., 4)``."""
    c, lead = _flat(C_bn, (3, 3))
    q = Rotation.from_matrix(c).as_quat(canonical=True, scalar_first=True)
    return q.reshape(lead + (4,))


def quat_to_dcm(q):
    """C_bn from a unit quaternion ``[w, x, y, z]`` (scalar first), ``(..., 4)`` -> ``(..., 3, 3)``."""
    qq, lead = _flat(q, (4,))
    return Rotation.from_quat(qq, scalar_first=True).as_matrix().reshape(lead + (3, 3))


def rotvec_to_dcm(rv):
    """Rotation matrix exp([rv x]) of rotation vectors ``rv`` (rad), ``(..., 3)`` -> ``(..., 3, 3)``."""
    r, lead = _flat(rv, (3,))
    return Rotation.from_rotvec(r).as_matrix().reshape(lead + (3, 3))


def dcm_to_rotvec(C):
    """Rotation vector (rad) of rotation matrices, ``(..., 3, 3)`` -> ``(..., 3)``."""
    c, lead = _flat(C, (3, 3))
    return Rotation.from_matrix(c).as_rotvec().reshape(lead + (3,))


def skew(v):
    """Cross-product matrix [v x] of ``v``, ``(..., 3)`` -> ``(..., 3, 3)``."""
    v = np.asarray(v, dtype=float)
    K = np.zeros(v.shape + (3,))
    K[..., 0, 1], K[..., 0, 2] = -v[..., 2], v[..., 1]
    K[..., 1, 0], K[..., 1, 2] = v[..., 2], -v[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -v[..., 1], v[..., 0]
    return K


def misalignment(C_bn_est, C_bn_true):
    """Misalignment phi (rad, ENU) with ``C_bn_est = exp(-[phi x]) C_bn_true``, shape ``(..., 3)``.

    Parameters
    ----------
    C_bn_est, C_bn_true : array_like, shape (..., 3, 3)
        Estimated and true attitude (body RFU to ENU); broadcast against each other.
    """
    C_est = np.asarray(C_bn_est, dtype=float)
    C_true = np.asarray(C_bn_true, dtype=float)
    return dcm_to_rotvec(C_true @ np.swapaxes(C_est, -1, -2))


def apply_misalignment(C_bn_true, phi):
    """Attitude ``exp(-[phi x]) C_bn_true`` carrying misalignment ``phi`` (rad, ENU)."""
    return np.swapaxes(rotvec_to_dcm(phi), -1, -2) @ np.asarray(C_bn_true, dtype=float)


def euler_platform_to_dcm(alpha):
    """The paper's C_n^n' (seed 000, eq. 1) from Euler platform error angles.

    Parameters
    ----------
    alpha : array_like, shape (..., 3)
        ``[ax, ay, az]``, rad, rotation order z, x, y from n to the computed frame n'.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        C_n^n', which takes a vector from n to n'; ``C_bn' = C_n^n' @ C_bn``.
    """
    a = np.asarray(alpha, dtype=float)
    C_n_prime_to_n = euler_to_dcm(a[..., [0, 1, 2]])  # Rz(az) Rx(ax) Ry(ay)
    return np.swapaxes(C_n_prime_to_n, -1, -2)


def dcm_to_euler_platform(C_n_nprime):
    """Euler platform error angles ``[ax, ay, az]`` (rad) of C_n^n' (inverse of euler_platform_to_dcm)."""
    return dcm_to_euler(np.swapaxes(np.asarray(C_n_nprime, dtype=float), -1, -2))


def euler_platform_angles(C_bn_est, C_bn_true):
    """Euler platform error angles ``[ax, ay, az]`` (rad) of an estimated attitude against truth."""
    C_est = np.asarray(C_bn_est, dtype=float)
    return dcm_to_euler_platform(C_est @ np.swapaxes(np.asarray(C_bn_true, dtype=float), -1, -2))


def euler_platform_to_phi(alpha):
    """Misalignment phi (rad) equivalent to Euler platform error angles alpha (rad)."""
    C = euler_platform_to_dcm(alpha)  # C_n^n' = exp(-[phi x])
    return -dcm_to_rotvec(C)


def phi_to_euler_platform(phi):
    """Euler platform error angles alpha (rad) equivalent to misalignment phi (rad)."""
    return dcm_to_euler_platform(np.swapaxes(rotvec_to_dcm(phi), -1, -2))


def orthonormalize(C):
    """Nearest rotation matrices to ``C`` (SVD projection), ``(..., 3, 3)``."""
    u, _, vt = np.linalg.svd(np.asarray(C, dtype=float))
    return u @ vt
