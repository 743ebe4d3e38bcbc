"""Floated (ball) inertial platform: error model, rolling torquing schemes and a fast simulator.

Seed 002 (Ding, Cai, Yang, Lian: continuous rolling self-calibration and self-alignment of a floated
inertial platform). The inner sphere (platform frame p) carries three gyros and three accelerometers;
its stabilisation loops make it turn at the torquer-commanded rates plus the gyro drifts. While the
sphere rolls in the gravity field, a 45-state EKF estimates 42 error coefficients and 3 attitude angles
from the accelerometer outputs. This module is the model that both the truth generation
(:func:`simulate`) and that filter (:func:`state_derivative`, :func:`measurement`) use.

Frames
------
n : navigation frame, East-North-Up (ENU). NUE is the same frame with its axes listed North-Up-East:
    ``v_NUE = P v_ENU`` with ``P = [[0, 1, 0], [0, 0, 1], [1, 0, 0]]`` (:data:`P_NUE`).
p : platform frame. ``x_p`` along the X accelerometer's sensitive axis; ``y_p`` in the plane of the
    X and Y accelerometer axes, perpendicular to ``x_p``; ``z_p = x_p x y_p``.

Attitude is ``C_pn`` (p to n, ``v_n = C_pn @ v_p``). The base is static (no lever arm: the offset of
the accelerometers from the sphere's centre is optional in the paper and left out here).

Attitude angles (the EKF's three attitude states)
--------------------------------------------------
Three angles ``[phi, theta, psi]`` (rad), measured from the North-Up-East axes, in the 3-2-1 order:
``psi`` about East (NUE z), then ``theta`` about Up (NUE y), then ``phi`` about North (NUE x), each
about the *fixed* NUE axes::

    P @ C_pn = Rx(phi) @ Ry(theta) @ Rz(psi)
             = scipy Rotation.from_euler("zyx", [psi, theta, phi]).as_matrix()   # lower case: extrinsic

(``Rx, Ry, Rz`` the usual right-handed rotation matrices). Equivalently, the n-to-p transformation
matrix is ``C_np P^T = Rz(psi)^T Ry(theta)^T Rx(phi)^T``, the classical 3-2-1 product of elementary
*coordinate transformations* about z, y, x.

Why this sequence: the rolling scheme turns the platform about geographic south and east, fixed axes
of n, i.e. left-multiplies ``C_pn`` by rotations about NUE x and NUE z. A rotation about North adds to
``phi`` (the left-most factor); a rotation about East commutes through ``Rx(phi)`` and adds to ``psi``
whenever ``phi`` is 0 or 180 deg, which is where every 180-deg south segment of the paper's scheme
ends. So from the nominal start (platform axes on North-Up-East, all angles zero) the middle angle
``theta`` (about Up) stays at zero along the whole scheme and near its initial value when the start is
off by small angles: far from its singularity at +-90 deg. The *intrinsic* reading
``P @ C_pn = Rz(psi) Ry(theta) Rx(phi)`` (scipy ``"ZYX"``) does not have this property: after the
first 90-deg east turn, a turn about south becomes a turn about the intermediate y axis, and
``theta`` runs through 90 deg (gimbal lock) in the third segment (tests/test_platform.py measures
both).

Euler-angle rates. With ``w = w_np^p`` (rate of p relative to n, in p), from ``C_pn^T dC_pn/dt = [w x]``::

    w = B(angles) @ [phi', theta', psi'],   B = [Rz(psi)^T Ry(theta)^T e1 | Rz(psi)^T e2 | e3]
      = [[cos psi cos theta, sin psi, 0], [-sin psi cos theta, cos psi, 0], [sin theta, 0, 1]]
    phi'   = (cos psi w_x - sin psi w_y) / cos theta
    theta' =  sin psi w_x + cos psi w_y
    psi'   =  w_z - sin theta phi'

Error coefficients (42, order of :data:`COEFF_NAMES`)
------------------------------------------------------
Gyro axes (input I, output O, spin S), nominal and cyclic: X gyro (x_p, y_p, z_p), Y gyro
(y_p, z_p, x_p), Z gyro (z_p, x_p, y_p).

=======  ======================================  =====================  ==============
index    coefficients                             SI unit                reported in
=======  ======================================  =====================  ==============
0-2      gyro bias D0 (X, Y, Z)                   rad/s                  deg/h
3-11     D_I, D_O, D_S of gyro X, then Y, then Z  rad/s / (m/s^2)        deg/h/g
12-20    D_IO, D_IS, D_OS of gyro X, Y, Z         rad/s / (m/s^2)^2      deg/h/g^2
21-26    gyro input-axis angles gxy, gxz, gyx,    rad                    arcsec
         gyz, gzx, gzy
27-29    accelerometer bias K0 (X, Y, Z)          m/s^2                  ug
30-32    accelerometer scale-factor error K1      1                      ppm
33-35    accelerometer quadratic term K2          1 / (m/s^2)            ug/g^2
36-38    accelerometer axis angles ayx, azx, azy  rad                    arcsec
39-41    torquer scale-factor error KT (X, Y, Z)  1                      ppm
=======  ======================================  =====================  ==============

``COEFF_SCALE`` holds the SI value of one reporting unit (g is the unit 9.80665 m/s^2 of
:mod:`fusionbench.units`): ``coeffs_SI = values_customary * COEFF_SCALE``.

Model equations
---------------
Specific force in p (static base, g = :func:`fusionbench.earth.gravity` (lat, h))::

    f^n = [0, 0, g],   f^p = C_pn^T f^n

Gyro drift of gyro i, from the specific force along its nominal I, O, S axes (the mounting angles
would change these terms only to second order, so they are ignored here)::

    eps_i = D0_i + D_I f_I + D_O f_O + D_S f_S + D_IO f_I f_O + D_IS f_I f_S + D_OS f_O f_S  (+ noise)

Gyro input-axis matrix (rows: the gyros' input axes in p; each gyro's two angles tilt its input axis
toward the two other p axes) and the stabilisation loop (each gyro's pick-off nulled: its input-axis
rate equals its torque command times ``1 + KT_i`` plus its drift)::

    G = [[1, gxy, gxz], [gyx, 1, gyz], [gzx, gzy, 1]]
    G @ w_ip^p = (I + diag(KT)) @ w_cmd^p + eps
    w_ip^p = G^-1 @ ((I + diag(KT)) @ w_cmd^p + eps)                   (exact: the simulator)
    w_ip^p ~= w_cmd^p + KT * w_cmd^p - M_g @ w_cmd^p + eps,  M_g = G - I  (first order: the filter)

The first-order form is the paper's eq. 19 ("small products ignored"): it drops
``M_g^2 w_cmd - M_g (KT w_cmd + eps)`` and higher powers of M_g, about 5e-10 rad/s (1e-4 deg/h) for
30-arcsec angles, 100-ppm scale factors and 1-deg/h drifts at 0.1 deg/s.

Attitude kinematics (w_ie^n = [0, Omega cos L, Omega sin L], Omega = :data:`earth.OMEGA_IE`)::

    w_np^p = w_ip^p - C_pn^T w_ie^n
    dC_pn/dt = C_pn [w_np^p x] = C_pn [w_ip^p x] - [w_ie^n x] C_pn

Accelerometer outputs (m/s^2), sensitive-axis matrix A (the X axis defines p)::

    A = [[1, 0, 0], [ayx, 1, 0], [azx, azy, 1]],   f_acc = A @ f^p
    y_j = K0_j + (1 + K1_j) f_acc_j + K2_j f_acc_j^2  (+ noise)

The EKF's model (45-vector ``x = [42 coefficients, phi, theta, psi]``)::

    h(x) = y(coeffs, C_pn(angles)^T f^n)                                  (:func:`measurement`)
    f(x) = [0 (42), Euler rates of w_np^p (first-order platform rate)]  (:func:`state_derivative`)

Torquing scheme and commands
----------------------------
A :class:`Scheme` is a sequence of segments, each a rotation of the platform *relative to n* about a
fixed ENU unit axis ``u`` at rate ``r`` (rad/s) for a duration (s, a whole number of command
periods); rate 0 holds the platform still relative to n (the command is then the earth rate alone).
The commanded path from the initial attitude ``C0``::

    C_path(t) = Rot_n(u, r (t - t_seg)) @ C_path(t_seg),   C_path(0) = C0

The torque command is held over each command period k (1 s) and computed from the path at the
period's middle: ``w_cmd^p = C_path(t_mid)^T (w_ie^n + r u)``, the absolute rate the platform needs
to follow the path. :data:`PAPER_SCHEME`: 0.1 deg/s about geographic south for 1800 s, about east
900 s, south 1800 s, east 900 s (5400 s; every rotation axis horizontal, so gravity sweeps through
the platform, and each platform axis turns through about 180 deg).

Holding the command constant over 1 s departs from the path by second-order terms (the earth-rate
part of the needed rate turns with the platform): of order ``r^2 Omega T^3 / 12`` per period,
coherent along a segment. Measured over the 5400-s paper scheme: 0.008 arcsec at most (0.006 at the
end); it scales with T^2 (6e-7 arcsec with 10-ms commands).

Simulator
---------
:func:`simulate` integrates the unit quaternion ``q`` of ``C_pn`` (Hamilton, scalar first,
``v_n = q v_p q*``) with the classical 4th-order Runge-Kutta method at ``sample_s`` (2 ms)::

    dq/dt = 1/2 q (x) [0, w_ip^p] - 1/2 [0, w_ie^n] (x) q

normalising ``q`` after every step. The command is held over its period; the drift is evaluated from
the current attitude at every Runge-Kutta stage (exact ``G^-1``). Noise:

* gyro: white drift, an independent normal value of standard deviation ``gyro_noise`` (rad/s) per
  sample, held over that sample (equivalent angle random walk ``gyro_noise * sqrt(sample_s)``,
  rad/sqrt(s)); the paper's "0.05 deg/h white" is read as that sigma per 2-ms sample
  (:data:`PAPER_GYRO_NOISE`);
* accelerometer: an independent normal value of standard deviation ``accel_noise`` (m/s^2) added to
  each filter output (the paper's 1 ug, :data:`PAPER_ACCEL_NOISE`).

Outputs come every ``filter_s`` (0.2 s) at ``t_k = k filter_s``, k = 1, 2, ...: the accelerometer
outputs *sampled at t_k* (instantaneous, so ``y_k = h(x(t_k)) + v_k`` holds exactly; an average over
the 0.2 s would equal the sample at the interval's middle to within ``g (r filter_s)^2 / 24``, 0.005 ug
at 0.1 deg/s), the true attitude at t_k, and the command that was held over ``(t_{k-1}, t_k]``.
The loop is compiled with numba and runs over a leading Monte Carlo axis (threads over runs); the
gyro noise is drawn with NumPy, one independent stream per run (``SeedSequence(seed).spawn``), in
chunks of about 50,000 samples, so run r's numbers do not depend on the batch size.

Every function validates its input and raises one ``ValueError`` line naming the field.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numba
import numpy as np
from scipy.spatial.transform import Rotation

from . import earth, units

# --------------------------------------------------------------------------------------------------
# constants, names and units

#: ``v_NUE = P_NUE @ v_ENU``.
P_NUE = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

N_COEFFS = 42
N_STATES = 45

#: Index ranges of the coefficient groups in the 42- (and 45-) vector.
D0 = slice(0, 3)
D1 = slice(3, 12)
D2 = slice(12, 21)
GYRO_MOUNT = slice(21, 27)
K0 = slice(27, 30)
K1 = slice(30, 33)
K2 = slice(33, 36)
ACCEL_MOUNT = slice(36, 39)
KT = slice(39, 42)
ANGLES = slice(42, 45)

_AX = ("X", "Y", "Z")
#: Names of the 42 coefficients, in vector order.
COEFF_NAMES = (
    [f"D0_{a}" for a in _AX]
    + [f"{t}_{a}" for a in _AX for t in ("DI", "DO", "DS")]
    + [f"{t}_{a}" for a in _AX for t in ("DIO", "DIS", "DOS")]
    + ["G_XY", "G_XZ", "G_YX", "G_YZ", "G_ZX", "G_ZY"]
    + [f"K0_{a}" for a in _AX]
    + [f"K1_{a}" for a in _AX]
    + [f"K2_{a}" for a in _AX]
    + ["A_YX", "A_ZX", "A_ZY"]
    + [f"KT_{a}" for a in _AX]
)
#: Names of the 45 EKF states: the coefficients, then the attitude angles.
STATE_NAMES = COEFF_NAMES + ["phi", "theta", "psi"]

_GROUPS = (  # (count, SI unit, reporting unit, SI value of one reporting unit)
    (3, "rad/s", "deg/h", units.DEG_PER_H),
    (9, "rad/s/(m/s^2)", "deg/h/g", units.DEG_PER_H / units.G0),
    (9, "rad/s/(m/s^2)^2", "deg/h/g^2", units.DEG_PER_H / units.G0**2),
    (6, "rad", "arcsec", units.ARCSEC),
    (3, "m/s^2", "ug", units.UG),
    (3, "1", "ppm", units.PPM),
    (3, "1/(m/s^2)", "ug/g^2", units.UG / units.G0**2),
    (3, "rad", "arcsec", units.ARCSEC),
    (3, "1", "ppm", units.PPM),
)
#: SI unit of each coefficient.
COEFF_UNITS = [u for n, u, _, _ in _GROUPS for _ in range(n)]
#: Customary (reporting) unit of each coefficient.
COEFF_CUSTOMARY_UNITS = [u for n, _, u, _ in _GROUPS for _ in range(n)]
#: SI value of one customary unit, per coefficient: ``si = customary * COEFF_SCALE``.
COEFF_SCALE = np.array([s for n, _, _, s in _GROUPS for _ in range(n)])

#: The paper's gyro white drift, 0.05 deg/h (rad/s, standard deviation per 2-ms sample).
PAPER_GYRO_NOISE = 0.05 * units.DEG_PER_H
#: The paper's accelerometer noise, 1 ug (m/s^2, standard deviation per output).
PAPER_ACCEL_NOISE = 1.0 * units.UG


def coeff_vector(customary: bool = False, **named) -> np.ndarray:
    """A 42-vector of coefficients from keyword values, the others zero.

    Parameters
    ----------
    customary : bool, optional
        If True the values are in :data:`COEFF_CUSTOMARY_UNITS` (deg/h, arcsec, ug, ppm, ...),
        otherwise SI (:data:`COEFF_UNITS`).
    **named : float
        Values by name from :data:`COEFF_NAMES`, e.g. ``coeff_vector(True, D0_X=0.1, KT_Z=50)``.

    Returns
    -------
    ndarray, shape (42,)
        Coefficients in SI units.
    """
    c = np.zeros(N_COEFFS)
    for name, value in named.items():
        if name not in COEFF_NAMES:
            raise ValueError(f"{name}: expected a coefficient name from COEFF_NAMES, found {name!r}")
        c[COEFF_NAMES.index(name)] = float(value)
    if not np.all(np.isfinite(c)):
        raise ValueError("coeffs: expected finite values, found NaN or inf")
    return c * COEFF_SCALE if customary else c


def to_customary(coeffs):
    """Coefficients (..., 42) in SI to the reporting units of :data:`COEFF_CUSTOMARY_UNITS`."""
    return _check_coeffs(coeffs) / COEFF_SCALE


def from_customary(values):
    """Coefficients (..., 42) in the reporting units to SI."""
    return _check_coeffs(values) * COEFF_SCALE


# --------------------------------------------------------------------------------------------------
# validation helpers


def _check_coeffs(c, name="coeffs", size=N_COEFFS):
    c = np.asarray(c, dtype=float)
    if c.ndim < 1 or c.shape[-1] != size:
        raise ValueError(f"{name}: expected shape (..., {size}), found {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError(f"{name}: expected finite values, found NaN or inf")
    return c


def _check_vec(v, name):
    v = np.asarray(v, dtype=float)
    if v.ndim < 1 or v.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape (..., 3), found {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: expected finite values, found NaN or inf")
    return v


def _check_dcm(C, name="C_pn"):
    C = np.asarray(C, dtype=float)
    if C.ndim < 2 or C.shape[-2:] != (3, 3):
        raise ValueError(f"{name}: expected shape (..., 3, 3), found {C.shape}")
    if not np.all(np.isfinite(C)):
        raise ValueError(f"{name}: expected finite values, found NaN or inf")
    err = np.abs(np.swapaxes(C, -1, -2) @ C - np.eye(3)).max(initial=0.0)
    if err > 1e-6 or np.any(np.linalg.det(C) < 0):
        raise ValueError(f"{name}: expected a rotation matrix (C^T C = I, det +1), found |C^T C - I| = {err:.3g}")
    return C


def _check_site(lat, h):
    earth.check_latitude(lat, "lat")
    h = float(h)
    if not np.isfinite(h) or abs(h) > 1e5:
        raise ValueError(f"h: expected a finite height within 100 km of the ellipsoid, found {h} m")
    return float(lat), h


# --------------------------------------------------------------------------------------------------
# attitude angles


def angles_to_dcm(angles):
    """``C_pn`` from the attitude angles ``[phi, theta, psi]`` (rad), ``(..., 3)`` -> ``(..., 3, 3)``.

    ``P_NUE @ C_pn = Rx(phi) Ry(theta) Rz(psi)`` (see the module notes).
    """
    return _angles_dcm(_check_vec(angles, "angles"))


def _angles_dcm(a):
    """:func:`angles_to_dcm` without input checks (for the filter's inner loop)."""
    sf, cf = np.sin(a[..., 0]), np.cos(a[..., 0])
    st, ct = np.sin(a[..., 1]), np.cos(a[..., 1])
    ss, cs = np.sin(a[..., 2]), np.cos(a[..., 2])
    M = np.empty(a.shape[:-1] + (3, 3))  # Rx(phi) Ry(theta) Rz(psi)
    M[..., 0, 0] = ct * cs
    M[..., 0, 1] = -ct * ss
    M[..., 0, 2] = st
    M[..., 1, 0] = cf * ss + sf * st * cs
    M[..., 1, 1] = cf * cs - sf * st * ss
    M[..., 1, 2] = -sf * ct
    M[..., 2, 0] = sf * ss - cf * st * cs
    M[..., 2, 1] = sf * cs + cf * st * ss
    M[..., 2, 2] = cf * ct
    return P_NUE.T @ M


def dcm_to_angles(C_pn):
    """Attitude angles ``[phi, theta, psi]`` (rad) of ``C_pn``, ``(..., 3, 3)`` -> ``(..., 3)``.

    ``theta`` lies in [-pi/2, pi/2], ``phi`` and ``psi`` in (-pi, pi].
    """
    C = np.asarray(C_pn, dtype=float)
    if C.ndim < 2 or C.shape[-2:] != (3, 3):
        raise ValueError(f"C_pn: expected shape (..., 3, 3), found {C.shape}")
    M = P_NUE @ C
    theta = np.arctan2(M[..., 0, 2], np.hypot(M[..., 0, 0], M[..., 0, 1]))
    psi = np.arctan2(-M[..., 0, 1], M[..., 0, 0])
    phi = np.arctan2(-M[..., 1, 2], M[..., 2, 2])
    return np.stack([phi, theta, psi], axis=-1)


def euler_rate_matrix(angles):
    """``B`` with ``w_np^p = B @ [phi', theta', psi']`` (see the module notes), ``(..., 3, 3)``."""
    a = _check_vec(angles, "angles")
    st, ct = np.sin(a[..., 1]), np.cos(a[..., 1])
    ss, cs = np.sin(a[..., 2]), np.cos(a[..., 2])
    B = np.zeros(a.shape[:-1] + (3, 3))
    B[..., 0, 0], B[..., 0, 1] = cs * ct, ss
    B[..., 1, 0], B[..., 1, 1] = -ss * ct, cs
    B[..., 2, 0], B[..., 2, 2] = st, 1.0
    return B


def angle_rates(angles, w_np_p):
    """Rates ``[phi', theta', psi']`` (rad/s) of the attitude angles for the relative rate ``w_np^p``.

    Parameters
    ----------
    angles : array_like, shape (..., 3)
        ``[phi, theta, psi]``, rad (``|theta|`` < 90 deg).
    w_np_p : array_like, shape (..., 3)
        Angular rate of p relative to n, resolved in p, rad/s.
    """
    return _angle_rates(_check_vec(angles, "angles"), _check_vec(w_np_p, "w_np_p"))


def _angle_rates(a, w):
    """:func:`angle_rates` without input checks."""
    st, ct = np.sin(a[..., 1]), np.cos(a[..., 1])
    ss, cs = np.sin(a[..., 2]), np.cos(a[..., 2])
    dphi = (cs * w[..., 0] - ss * w[..., 1]) / ct
    dtheta = ss * w[..., 0] + cs * w[..., 1]
    dpsi = w[..., 2] - st * dphi
    return np.stack([dphi, dtheta, dpsi], axis=-1)


# --------------------------------------------------------------------------------------------------
# the error model (plain arithmetic shared with the compiled simulator)


def _drift_terms(c, f0, f1, f2):
    """Gyro drifts (eps_X, eps_Y, eps_Z) from coefficients ``c`` (indexable 0..41) and f^p components.

    Plain arithmetic: ``c[i]`` may be a float (compiled loop) or an array (NumPy, leading axes).
    """
    # X gyro (I, O, S) = (x, y, z); Y gyro = (y, z, x); Z gyro = (z, x, y)
    ex = c[0] + c[3] * f0 + c[4] * f1 + c[5] * f2 + c[12] * f0 * f1 + c[13] * f0 * f2 + c[14] * f1 * f2
    ey = c[1] + c[6] * f1 + c[7] * f2 + c[8] * f0 + c[15] * f1 * f2 + c[16] * f1 * f0 + c[17] * f2 * f0
    ez = c[2] + c[9] * f2 + c[10] * f0 + c[11] * f1 + c[18] * f2 * f0 + c[19] * f2 * f1 + c[20] * f0 * f1
    return ex, ey, ez


def _accel_terms(c, f0, f1, f2):
    """Accelerometer outputs (y_X, y_Y, y_Z) from coefficients ``c`` and f^p components; plain arithmetic."""
    a0 = f0
    a1 = c[36] * f0 + f1
    a2 = c[37] * f0 + c[38] * f1 + f2
    y0 = c[27] + (1.0 + c[30]) * a0 + c[33] * a0 * a0
    y1 = c[28] + (1.0 + c[31]) * a1 + c[34] * a1 * a1
    y2 = c[29] + (1.0 + c[32]) * a2 + c[35] * a2 * a2
    return y0, y1, y2


def specific_force_p(C_pn, lat, h=0.0):
    """Specific force of the static base in p, ``C_pn^T [0, 0, g]`` (m/s^2), shape ``(..., 3)``."""
    C = _check_dcm(C_pn)
    lat, h = _check_site(lat, h)
    return float(earth.gravity(lat, h)) * C[..., 2, :]


def gyro_matrix(coeffs):
    """Gyro input-axis matrix ``G`` (rows: input axes in p), ``(..., 42)`` -> ``(..., 3, 3)``."""
    c = _check_coeffs(coeffs)
    G = np.broadcast_to(np.eye(3), c.shape[:-1] + (3, 3)).copy()
    G[..., 0, 1], G[..., 0, 2] = c[..., 21], c[..., 22]
    G[..., 1, 0], G[..., 1, 2] = c[..., 23], c[..., 24]
    G[..., 2, 0], G[..., 2, 1] = c[..., 25], c[..., 26]
    return G


def accel_matrix(coeffs):
    """Accelerometer sensitive-axis matrix ``A``, ``(..., 42)`` -> ``(..., 3, 3)``."""
    c = _check_coeffs(coeffs)
    A = np.broadcast_to(np.eye(3), c.shape[:-1] + (3, 3)).copy()
    A[..., 1, 0] = c[..., 36]
    A[..., 2, 0], A[..., 2, 1] = c[..., 37], c[..., 38]
    return A


def gyro_drift(coeffs, f_p):
    """Gyro drifts ``eps`` (rad/s, one per gyro X, Y, Z) at specific force ``f_p`` (m/s^2, p frame).

    Parameters
    ----------
    coeffs : array_like, shape (..., 42)
        Coefficients, SI.
    f_p : array_like, shape (..., 3)
        Specific force in p, m/s^2.

    Returns
    -------
    ndarray, shape (..., 3)
        Drift of each gyro about its input axis, rad/s (no noise).
    """
    c = np.moveaxis(_check_coeffs(coeffs), -1, 0)
    f = _check_vec(f_p, "f_p")
    out = _drift_terms(c, f[..., 0], f[..., 1], f[..., 2])
    return np.stack(np.broadcast_arrays(*out), axis=-1)


def platform_rate(coeffs, w_cmd_p, f_p, exact=True):
    """Absolute angular rate of the platform ``w_ip^p`` (rad/s) under a torque command.

    Parameters
    ----------
    coeffs : array_like, shape (..., 42)
        Coefficients, SI.
    w_cmd_p : array_like, shape (..., 3)
        Torque-commanded rate, rad/s, one per gyro (X, Y, Z).
    f_p : array_like, shape (..., 3)
        Specific force in p, m/s^2 (for the g-sensitive drift).
    exact : bool, optional
        ``G^-1 ((I + diag KT) w_cmd + eps)`` (default), or the first-order form
        ``w_cmd + KT w_cmd - (G - I) w_cmd + eps`` (the paper's eq. 19, used by the filter).

    Returns
    -------
    ndarray, shape (..., 3)
        ``w_ip^p``, rad/s.
    """
    c = _check_coeffs(coeffs)
    w = _check_vec(w_cmd_p, "w_cmd_p")
    eps = gyro_drift(c, f_p)
    rhs = (1.0 + c[..., KT]) * w + eps
    G = gyro_matrix(c)
    if exact:
        shape = np.broadcast_shapes(G.shape[:-2], rhs.shape[:-1])
        G = np.broadcast_to(G, shape + (3, 3))
        return np.linalg.solve(G, np.broadcast_to(rhs, shape + (3,))[..., None])[..., 0]
    return rhs - ((G - np.eye(3)) @ w[..., None])[..., 0]


def attitude_rate(coeffs, C_pn, w_cmd_p, lat, h=0.0, exact=True):
    """``dC_pn/dt = C_pn [w_np^p x]`` (1/s), with ``w_np^p = w_ip^p - C_pn^T w_ie^n``.

    Parameters
    ----------
    coeffs : array_like, shape (..., 42)
    C_pn : array_like, shape (..., 3, 3)
        Attitude, p to ENU.
    w_cmd_p : array_like, shape (..., 3)
        Torque command, rad/s.
    lat, h : float
        Latitude (rad) and height (m) of the static base.
    exact : bool, optional
        Exact or first-order platform rate (see :func:`platform_rate`).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    w_np = _relative_rate(coeffs, C_pn, w_cmd_p, lat, h, exact)
    z = np.zeros(w_np.shape[:-1])
    x, y, w = w_np[..., 0], w_np[..., 1], w_np[..., 2]
    K = np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)
    return np.asarray(C_pn, dtype=float) @ K


def _relative_rate(coeffs, C_pn, w_cmd_p, lat, h, exact):
    C = _check_dcm(C_pn)
    f_p = specific_force_p(C, lat, h)
    w_ip = platform_rate(coeffs, w_cmd_p, f_p, exact=exact)
    w_ie = earth.earth_rate_n(lat)
    return w_ip - np.einsum("...ji,j->...i", C, w_ie)


def accel_output(coeffs, f_p):
    """Accelerometer outputs ``y`` (m/s^2, X, Y, Z) at specific force ``f_p`` (m/s^2, p), no noise.

    ``y_j = K0_j + (1 + K1_j) f_j + K2_j f_j^2`` with ``f = A @ f_p``.
    """
    c = np.moveaxis(_check_coeffs(coeffs), -1, 0)
    f = _check_vec(f_p, "f_p")
    out = _accel_terms(c, f[..., 0], f[..., 1], f[..., 2])
    return np.stack(np.broadcast_arrays(*out), axis=-1)


def measurement(state, lat, h=0.0):
    """The EKF's ``h(x)``: accelerometer outputs (m/s^2) predicted from the 45-vector.

    Parameters
    ----------
    state : array_like, shape (..., 45)
        ``[42 coefficients (SI), phi, theta, psi (rad)]``.
    lat, h : float
        Latitude (rad) and height (m).

    Returns
    -------
    ndarray, shape (..., 3)
        ``y`` of the X, Y, Z accelerometers, m/s^2.
    """
    x = _check_coeffs(state, "state", N_STATES)
    lat, h = _check_site(lat, h)
    return measurement_unchecked(x, float(earth.gravity(lat, h)))


def measurement_unchecked(x, g):
    """:func:`measurement` for a checked state and gravity ``g`` (m/s^2): no input checks (inner loops)."""
    f = g * _angles_dcm(x[..., ANGLES])[..., 2, :]
    c = np.moveaxis(x, -1, 0)
    return np.stack(np.broadcast_arrays(*_accel_terms(c, f[..., 0], f[..., 1], f[..., 2])), axis=-1)


def state_derivative(state, w_cmd_p, lat, h=0.0):
    """The EKF's ``f(x)``: time derivative of the 45-vector under the torque command ``w_cmd_p``.

    The coefficients are constant; the angle rates follow from the kinematics with the first-order
    platform rate (eq. 19) through the Euler-angle rate relation (see the module notes).

    Parameters
    ----------
    state : array_like, shape (..., 45)
        ``[42 coefficients (SI), phi, theta, psi (rad)]``.
    w_cmd_p : array_like, shape (..., 3)
        Torque command held over the step, rad/s.
    lat, h : float
        Latitude (rad) and height (m).

    Returns
    -------
    ndarray, shape (..., 45)
        Zeros for the coefficients, then ``[phi', theta', psi']`` in rad/s.
    """
    x = _check_coeffs(state, "state", N_STATES)
    w = _check_vec(w_cmd_p, "w_cmd_p")
    lat, h = _check_site(lat, h)
    return state_derivative_unchecked(x, w, float(earth.gravity(lat, h)), earth.earth_rate_n(lat))


def state_derivative_unchecked(x, w, g, w_ie_n):
    """:func:`state_derivative` for checked inputs, gravity ``g`` and earth rate ``w_ie_n`` (ENU): no
    input checks (the filter's Runge-Kutta steps)."""
    ang = x[..., ANGLES]
    C = _angles_dcm(ang)
    f = g * C[..., 2, :]
    c = np.moveaxis(x, -1, 0)
    eps = np.stack(np.broadcast_arrays(*_drift_terms(c, f[..., 0], f[..., 1], f[..., 2])), axis=-1)
    Mg_w = np.stack([c[21] * w[..., 1] + c[22] * w[..., 2], c[23] * w[..., 0] + c[24] * w[..., 2],
                     c[25] * w[..., 0] + c[26] * w[..., 1]], axis=-1)
    w_np = (1.0 + x[..., KT]) * w - Mg_w + eps - np.einsum("...ji,j->...i", C, w_ie_n)
    rates = _angle_rates(ang, w_np)
    out = np.zeros(np.broadcast_shapes(x.shape[:-1], rates.shape[:-1]) + (N_STATES,))
    out[..., ANGLES] = rates
    return out


# --------------------------------------------------------------------------------------------------
# torquing schemes


class Segment(NamedTuple):
    """One rotation of the platform relative to n: ENU unit ``axis``, ``rate`` (rad/s), ``duration`` (s)."""

    axis: tuple
    rate: float
    duration: float


def _multiple(a, b, tol=1e-9):
    """Whole number a / b (int) if a is a whole multiple of b, else None."""
    k = round(a / b)
    return int(k) if k >= 1 and abs(a - k * b) <= tol * max(abs(a), 1.0) else None


@dataclass(frozen=True)
class Scheme:
    """A rolling torquing scheme as data.

    Parameters
    ----------
    segments : tuple of Segment or (axis, rate, duration) tuples
        Rotations relative to n, one after the other: ``axis`` an ENU unit vector, ``rate`` in rad/s
        (0 holds the platform still), ``duration`` in s, a whole number of command periods.
    command_period_s : float
        Torque command period, s (each command is held over one period).
    sample_s : float
        Integration and gyro-noise sample interval, s; divides ``filter_s``.
    filter_s : float
        Output (filter) interval, s; divides ``command_period_s``.
    """

    segments: tuple
    command_period_s: float = 1.0
    sample_s: float = 0.002
    filter_s: float = 0.2
    _starts: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        for name in ("command_period_s", "sample_s", "filter_s"):
            v = getattr(self, name)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"{name}: expected a positive number of seconds, found {v!r}") from None
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"{name}: expected a positive number of seconds, found {v!r}")
            object.__setattr__(self, name, v)
        if _multiple(self.filter_s, self.sample_s) is None:
            raise ValueError(f"sample_s: expected a whole fraction of filter_s = {self.filter_s} s, "
                             f"found {self.sample_s} s")
        if _multiple(self.command_period_s, self.sample_s) is None:
            raise ValueError(f"sample_s: expected a whole fraction of command_period_s = {self.command_period_s} s, "
                             f"found {self.sample_s} s")
        if _multiple(self.command_period_s, self.filter_s) is None:
            raise ValueError(f"filter_s: expected a whole fraction of command_period_s = {self.command_period_s} s "
                             f"(each filter step under one command), found {self.filter_s} s")
        segs = self.segments
        if isinstance(segs, Segment) or not isinstance(segs, (tuple, list)) or len(segs) == 0:
            raise ValueError(f"segments: expected a non-empty tuple of (axis, rate, duration), found {segs!r}")
        out = []
        for i, s in enumerate(segs):
            try:
                axis, rate, duration = s
            except (TypeError, ValueError):
                raise ValueError(f"segments[{i}]: expected (axis, rate, duration), found {s!r}") from None
            u = np.asarray(axis, dtype=float)
            if u.shape != (3,) or not np.all(np.isfinite(u)) or abs(np.linalg.norm(u) - 1.0) > 1e-6:
                raise ValueError(f"segments[{i}].axis: expected an ENU unit vector (3 values, norm 1), found {axis!r}")
            rate = float(rate)
            if not np.isfinite(rate):
                raise ValueError(f"segments[{i}].rate: expected a finite rate in rad/s, found {rate}")
            duration = float(duration)
            if not np.isfinite(duration) or duration <= 0 or _multiple(duration, self.command_period_s) is None:
                raise ValueError(f"segments[{i}].duration: expected a positive whole number of command periods "
                                 f"({self.command_period_s} s), found {duration} s")
            u = u / np.linalg.norm(u)
            out.append(Segment(tuple(float(x) for x in u), rate, duration))
        object.__setattr__(self, "segments", tuple(out))
        object.__setattr__(self, "_starts", np.concatenate([[0.0], np.cumsum([s.duration for s in out])]))

    @property
    def duration(self) -> float:
        """Total duration, s."""
        return float(self._starts[-1])

    @property
    def samples_per_command(self) -> int:
        return _multiple(self.command_period_s, self.sample_s)

    @property
    def samples_per_filter(self) -> int:
        return _multiple(self.filter_s, self.sample_s)

    @property
    def n_commands(self) -> int:
        """Number of command periods."""
        return int(round(self.duration / self.command_period_s))

    @property
    def n_samples(self) -> int:
        """Number of integration samples."""
        return self.n_commands * self.samples_per_command

    @property
    def n_outputs(self) -> int:
        """Number of filter outputs (at ``k filter_s``, k = 1 .. n_outputs)."""
        return self.n_samples // self.samples_per_filter

    def segment_index(self, t):
        """Index of the segment in force at time(s) ``t`` (s); the last one from its start onwards."""
        t = np.asarray(t, dtype=float)
        return np.clip(np.searchsorted(self._starts, t, side="right") - 1, 0, len(self.segments) - 1)


_SOUTH = (0.0, -1.0, 0.0)
_EAST = (1.0, 0.0, 0.0)
_R = 0.1 * units.DEG
#: Seed 002's scheme: 0.1 deg/s about south 1800 s, east 900 s, south 1800 s, east 900 s.
PAPER_SCHEME = Scheme(((_SOUTH, _R, 1800.0), (_EAST, _R, 900.0), (_SOUTH, _R, 1800.0), (_EAST, _R, 900.0)))


def _check_scheme(scheme):
    if not isinstance(scheme, Scheme):
        raise ValueError(f"scheme: expected a Scheme, found {type(scheme).__name__}")
    return scheme


def _segment_starts(scheme, C0):
    """Commanded attitude at the start of each segment and at the end, ``(..., nseg + 1, 3, 3)``."""
    mats = [C0]
    for s in scheme.segments:
        R = Rotation.from_rotvec(np.asarray(s.axis) * s.rate * s.duration).as_matrix()
        mats.append(R @ mats[-1])
    return np.stack(mats, axis=-3)


def commanded_path(scheme, C0, t):
    """The commanded attitude ``C_path(t)`` (p to ENU) of a scheme from the initial attitude ``C0``.

    Parameters
    ----------
    scheme : Scheme
    C0 : array_like, shape (..., 3, 3)
        Initial attitude ``C_pn`` at t = 0.
    t : array_like, shape (m,)
        Times, s (>= 0; after the scheme's end the attitude holds its final value relative to n).

    Returns
    -------
    ndarray, shape (..., m, 3, 3)
        ``Rot_n(u, r (t - t_seg)) @ C_path(t_seg)``.
    """
    scheme = _check_scheme(scheme)
    C0 = _check_dcm(C0, "C0")
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)) or np.any(t < 0):
        raise ValueError(f"t: expected a 1-D array of times >= 0 s, found shape {t.shape}")
    starts = _segment_starts(scheme, C0)
    idx = scheme.segment_index(t)
    axes = np.array([s.axis for s in scheme.segments])[idx]
    rates = np.array([s.rate for s in scheme.segments])[idx]
    durs = np.array([s.duration for s in scheme.segments])[idx]
    tau = np.minimum(t - scheme._starts[idx], durs)
    R = Rotation.from_rotvec(axes * (rates * tau)[:, None]).as_matrix()
    return R @ starts[..., idx, :, :]


def commands(scheme, C0, lat):
    """Torque commands ``w_cmd^p`` (rad/s), one per command period, to follow the scheme.

    ``w_cmd^p = C_path(t_mid)^T (w_ie^n + r u)`` at the period's middle ``t_mid``.

    Parameters
    ----------
    scheme : Scheme
    C0 : array_like, shape (..., 3, 3)
        Initial attitude.
    lat : float
        Latitude, rad.

    Returns
    -------
    ndarray, shape (..., n_commands, 3)
    """
    scheme = _check_scheme(scheme)
    earth.check_latitude(lat, "lat")
    t_mid = (np.arange(scheme.n_commands) + 0.5) * scheme.command_period_s
    C = commanded_path(scheme, C0, t_mid)
    idx = scheme.segment_index(t_mid)
    ru = np.array([np.asarray(s.axis) * s.rate for s in scheme.segments])[idx]
    w_n = earth.earth_rate_n(float(lat)) + ru
    return np.einsum("...kji,kj->...ki", C, w_n)


# --------------------------------------------------------------------------------------------------
# simulator

_drift_nb = numba.njit(cache=True)(_drift_terms)
_accel_nb = numba.njit(cache=True)(_accel_terms)


@numba.njit(cache=True)
def _qdot(q0, q1, q2, q3, c, Gi, b0, b1, b2, g, wN, wU):
    """dq/dt for quaternion q (p to n): 1/2 q (x) w_ip - 1/2 w_ie (x) q, drift at the attitude q."""
    f0 = g * 2.0 * (q1 * q3 - q0 * q2)  # f^p = g * (third row of C_pn)
    f1 = g * 2.0 * (q2 * q3 + q0 * q1)
    f2 = g * (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)
    e0, e1, e2 = _drift_nb(c, f0, f1, f2)
    u0, u1, u2 = b0 + e0, b1 + e1, b2 + e2
    w0 = Gi[0, 0] * u0 + Gi[0, 1] * u1 + Gi[0, 2] * u2
    w1 = Gi[1, 0] * u0 + Gi[1, 1] * u1 + Gi[1, 2] * u2
    w2 = Gi[2, 0] * u0 + Gi[2, 1] * u1 + Gi[2, 2] * u2
    # q (x) [0, w]: scalar -qv.w, vector q0 w + qv x w;  [0, W] (x) q: -W.qv, q0 W + W x qv (W = [0, wN, wU])
    d0 = -(q1 * w0 + q2 * w1 + q3 * w2) + (wN * q2 + wU * q3)
    d1 = q0 * w0 + (q2 * w2 - q3 * w1) - (wN * q3 - wU * q2)
    d2 = q0 * w1 + (q3 * w0 - q1 * w2) - (q0 * wN + wU * q1)
    d3 = q0 * w2 + (q1 * w1 - q2 * w0) - (q0 * wU - wN * q1)
    return 0.5 * d0, 0.5 * d1, 0.5 * d2, 0.5 * d3


def _simulate_kernel(q, coeffs, Ginv, cmd, wN, wU, g, dt, spc, spf, k_start, noise, out_C, out_y):
    """RK4 over the samples k_start .. k_start + len - 1 of each run (q updated in place).

    ``noise`` (runs, len, 3) is the gyro white drift of each sample (rad/s), or empty (runs, 0, 3) for
    none; ``len`` is its length or, when empty, ``cmd``'s remaining samples. Records C_pn and the
    noise-free accelerometer output after every spf-th sample (global sample count).
    """
    runs = q.shape[0]
    n = noise.shape[1]
    noisy = n > 0
    if not noisy:
        n = cmd.shape[1] * spc - k_start
    for r in numba.prange(runs):
        c = coeffs[r]
        Gi = Ginv[r]
        k0, k1, k2 = 1.0 + c[39], 1.0 + c[40], 1.0 + c[41]
        q0, q1, q2, q3 = q[r, 0], q[r, 1], q[r, 2], q[r, 3]
        h = 0.5 * dt
        for i in range(n):
            k = k_start + i
            j = k // spc
            b0, b1, b2 = k0 * cmd[r, j, 0], k1 * cmd[r, j, 1], k2 * cmd[r, j, 2]
            if noisy:
                b0 += noise[r, i, 0]
                b1 += noise[r, i, 1]
                b2 += noise[r, i, 2]
            a0, a1, a2, a3 = _qdot(q0, q1, q2, q3, c, Gi, b0, b1, b2, g, wN, wU)
            e0, e1, e2, e3 = _qdot(q0 + h * a0, q1 + h * a1, q2 + h * a2, q3 + h * a3, c, Gi, b0, b1, b2, g, wN, wU)
            f0, f1, f2, f3 = _qdot(q0 + h * e0, q1 + h * e1, q2 + h * e2, q3 + h * e3, c, Gi, b0, b1, b2, g, wN, wU)
            g0, g1, g2, g3 = _qdot(q0 + dt * f0, q1 + dt * f1, q2 + dt * f2, q3 + dt * f3, c, Gi, b0, b1, b2, g, wN, wU)
            q0 += dt / 6.0 * (a0 + 2.0 * (e0 + f0) + g0)
            q1 += dt / 6.0 * (a1 + 2.0 * (e1 + f1) + g1)
            q2 += dt / 6.0 * (a2 + 2.0 * (e2 + f2) + g2)
            q3 += dt / 6.0 * (a3 + 2.0 * (e3 + f3) + g3)
            nq = 1.0 / np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
            q0, q1, q2, q3 = q0 * nq, q1 * nq, q2 * nq, q3 * nq
            if (k + 1) % spf == 0:
                m = (k + 1) // spf - 1
                C = out_C[r, m]
                C[0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
                C[0, 1] = 2.0 * (q1 * q2 - q0 * q3)
                C[0, 2] = 2.0 * (q1 * q3 + q0 * q2)
                C[1, 0] = 2.0 * (q1 * q2 + q0 * q3)
                C[1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
                C[1, 2] = 2.0 * (q2 * q3 - q0 * q1)
                C[2, 0] = 2.0 * (q1 * q3 - q0 * q2)
                C[2, 1] = 2.0 * (q2 * q3 + q0 * q1)
                C[2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
                y0, y1, y2 = _accel_nb(c, g * C[2, 0], g * C[2, 1], g * C[2, 2])
                out_y[r, m, 0], out_y[r, m, 1], out_y[r, m, 2] = y0, y1, y2
        q[r, 0], q[r, 1], q[r, 2], q[r, 3] = q0, q1, q2, q3


_simulate_serial = numba.njit(cache=True)(_simulate_kernel)
#: Gyro noise is drawn (NumPy) and integrated in chunks of about this many samples per run.
_CHUNK_SAMPLES = 50000
_simulate_parallel = numba.njit(cache=True, parallel=True)(_simulate_kernel)


@dataclass
class PlatformRun:
    """Result of :func:`simulate` (SI units; leading axis: Monte Carlo runs).

    Attributes
    ----------
    t : ndarray, shape (m,)
        Output times ``k filter_s``, k = 1 .. m, s.
    y : ndarray, shape (runs, m, 3)
        Accelerometer outputs at t (X, Y, Z), m/s^2, noise included.
    y_clean : ndarray, shape (runs, m, 3)
        The same without accelerometer noise (``measurement`` of the true state).
    C_pn : ndarray, shape (runs, m, 3, 3)
        True attitude at t, p to ENU.
    w_cmd : ndarray, shape (runs, m, 3)
        Torque command held over ``(t_k - filter_s, t_k]``, rad/s.
    commands : ndarray, shape (runs, n_commands, 3)
        The command of every command period, rad/s.
    C0 : ndarray, shape (runs, 3, 3)
        Initial attitude (t = 0).
    coeffs : ndarray, shape (runs, 42)
        True coefficients, SI.
    scheme, lat, h, g :
        Scheme, latitude (rad), height (m) and gravity (m/s^2) of the run.
    wall_s : float
        Wall time of the compiled loop, s.
    """

    t: np.ndarray
    y: np.ndarray
    y_clean: np.ndarray
    C_pn: np.ndarray
    w_cmd: np.ndarray
    commands: np.ndarray
    C0: np.ndarray
    coeffs: np.ndarray
    scheme: Scheme
    lat: float
    h: float
    g: float
    wall_s: float

    @property
    def angles(self):
        """True attitude angles ``[phi, theta, psi]`` at t, rad, unwrapped along time, (runs, m, 3)."""
        a0 = dcm_to_angles(self.C0)[:, None]
        a = np.unwrap(np.concatenate([a0, dcm_to_angles(self.C_pn)], axis=1), axis=1)
        return a[:, 1:]

    @property
    def states(self):
        """True 45-vectors ``[coeffs, phi, theta, psi]`` at t, (runs, m, 45)."""
        runs, m = self.y.shape[:2]
        return np.concatenate([np.broadcast_to(self.coeffs[:, None], (runs, m, N_COEFFS)), self.angles], axis=-1)


def _per_run(x, tail, runs, name):
    x = np.asarray(x, dtype=float)
    if x.shape == tail:
        return np.ascontiguousarray(np.broadcast_to(x, (runs,) + tail))
    if x.shape == (runs,) + tail:
        return np.ascontiguousarray(x)
    raise ValueError(f"{name}: expected shape {tail} or ({runs},) + {tail}, found {x.shape}")


def _noise(x, runs, name):
    x = np.asarray(x, dtype=float)
    try:
        x = np.broadcast_to(x, (runs, 3))
    except ValueError:
        raise ValueError(f"{name}: expected a standard deviation, one per axis (3) or per run (runs, 3), "
                         f"found shape {x.shape}") from None
    if not np.all(np.isfinite(x)) or np.any(x < 0):
        raise ValueError(f"{name}: expected finite standard deviations >= 0, found {x.ravel()[:3].tolist()}")
    return np.ascontiguousarray(x)


def simulate(scheme, coeffs, C0, lat, h=0.0, gyro_noise=PAPER_GYRO_NOISE, accel_noise=PAPER_ACCEL_NOISE,
             seed=0, runs=None):
    """Simulate the floated platform rolling through a scheme; batched over Monte Carlo runs.

    Parameters
    ----------
    scheme : Scheme
        Torquing scheme (segments, command period, sample and filter intervals).
    coeffs : array_like, shape (42,) or (runs, 42)
        True error coefficients, SI (see :data:`COEFF_NAMES`).
    C0 : array_like, shape (3, 3) or (runs, 3, 3)
        Initial attitude ``C_pn`` (p to ENU); the commands follow the scheme from it.
    lat : float
        Latitude, rad.
    h : float, optional
        Height, m.
    gyro_noise : float or array_like (3,) or (runs, 3), optional
        White gyro drift, standard deviation per sample (held over ``sample_s``), rad/s.
    accel_noise : float or array_like (3,) or (runs, 3), optional
        Accelerometer noise, standard deviation of each output, m/s^2.
    seed : int, optional
        Seed of all noise (runs draw independent streams; same seed, same numbers).
    runs : int, optional
        Number of runs; default from the leading axis of ``coeffs`` or ``C0``, else 1.

    Returns
    -------
    PlatformRun
    """
    scheme = _check_scheme(scheme)
    lat, h = _check_site(lat, h)
    c = _check_coeffs(coeffs)
    C0a = _check_dcm(C0, "C0")
    if c.ndim > 2:
        raise ValueError(f"coeffs: expected shape (42,) or (runs, 42), found {c.shape}")
    if C0a.ndim > 3:
        raise ValueError(f"C0: expected shape (3, 3) or (runs, 3, 3), found {C0a.shape}")
    if runs is None:
        runs = c.shape[0] if c.ndim == 2 else (C0a.shape[0] if C0a.ndim == 3 else 1)
    if not isinstance(runs, (int, np.integer)) or runs < 1:
        raise ValueError(f"runs: expected a positive integer, found {runs!r}")
    runs = int(runs)
    c = _per_run(c, (N_COEFFS,), runs, "coeffs")
    C0a = _per_run(C0a, (3, 3), runs, "C0")
    sg = _noise(gyro_noise, runs, "gyro_noise")
    sa = _noise(accel_noise, runs, "accel_noise")
    G = gyro_matrix(c)
    if np.any(np.abs(np.linalg.det(G)) < 0.5):
        raise ValueError("coeffs: expected small gyro mounting angles (G_XY ... G_ZY), found a near-singular G")
    Ginv = np.ascontiguousarray(np.linalg.inv(G))
    try:
        seq = np.random.SeedSequence(seed)
    except (TypeError, ValueError):
        raise ValueError(f"seed: expected a non-negative integer, found {seed!r}") from None
    # one independent stream per run (gyro noise, then accelerometer noise): run r's numbers do not
    # depend on how many runs are batched with it
    rngs = [np.random.default_rng(s) for s in seq.spawn(runs)]

    cmd = np.ascontiguousarray(commands(scheme, C0a, lat))
    q = np.ascontiguousarray(Rotation.from_matrix(C0a).as_quat(scalar_first=True))
    g = float(earth.gravity(lat, h))
    w_ie = earth.earth_rate_n(lat)
    spc, spf, n, m = scheme.samples_per_command, scheme.samples_per_filter, scheme.n_samples, scheme.n_outputs
    out_C = np.empty((runs, m, 3, 3))
    out_y = np.empty((runs, m, 3))
    kernel = _simulate_parallel if runs > 1 else _simulate_serial
    args = (c, Ginv, cmd, float(w_ie[1]), float(w_ie[2]), g, scheme.sample_s, spc, spf)
    t0 = time.perf_counter()
    if np.any(sg > 0):
        chunk = spc * max(1, _CHUNK_SAMPLES // spc)
        buf = np.empty((runs, chunk, 3))
        for k in range(0, n, chunk):
            noise = buf if n - k >= chunk else np.empty((runs, n - k, 3))
            for r in range(runs):
                rngs[r].standard_normal(out=noise[r])
            noise *= sg[:, None, :]
            kernel(q, *args, k, noise, out_C, out_y)
    else:
        kernel(q, *args, 0, np.zeros((runs, 0, 3)), out_C, out_y)
    wall = time.perf_counter() - t0
    y = out_y + sa[:, None, :] * np.stack([rng.standard_normal((m, 3)) for rng in rngs])
    t = (np.arange(m) + 1) * scheme.filter_s
    w_cmd = cmd[:, (np.arange(m) * spf) // spc]
    return PlatformRun(t=t, y=y, y_clean=out_y, C_pn=out_C, w_cmd=w_cmd, commands=cmd, C0=C0a, coeffs=c,
                       scheme=scheme, lat=lat, h=h, g=g, wall_s=wall)
