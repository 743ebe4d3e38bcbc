"""Platform error model: coefficients and their units, drift, platform rate, accelerometer outputs, and the filter's
f(x) and h(x) (equations in the :mod:`baselines.rolling` module notes; the attitude angles are
:mod:`baselines.rolling.angles`)."""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import earth, units

from .angles import _angle_rates, _angles_dcm, _check_vec
from .terms import accel_terms, drift_terms

# --------------------------------------------------------------------------------------------------
# constants, names and units


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
# the error model (element formulas in baselines.rolling.terms)


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
    out = drift_terms(c, f[..., 0], f[..., 1], f[..., 2])
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
        ``w_cmd + KT w_cmd - (G - I) w_cmd + eps`` (the paper's eq. 19; its dropped products bias the
        gyro terms, see the module notes).

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
    C = _check_dcm(C_pn)
    w_np = platform_rate(coeffs, w_cmd_p, specific_force_p(C, lat, h), exact=exact)
    w_np = w_np - np.einsum("...ji,j->...i", C, earth.earth_rate_n(lat))
    z = np.zeros(w_np.shape[:-1])
    x, y, w = w_np[..., 0], w_np[..., 1], w_np[..., 2]
    K = np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)
    return C @ K


def accel_output(coeffs, f_p):
    """Accelerometer outputs ``y`` (m/s^2, X, Y, Z) at specific force ``f_p`` (m/s^2, p), no noise.

    ``y_j = K0_j + (1 + K1_j) f_j + K2_j f_j^2`` with ``f = A @ f_p``.
    """
    c = np.moveaxis(_check_coeffs(coeffs), -1, 0)
    f = _check_vec(f_p, "f_p")
    out = accel_terms(c, f[..., 0], f[..., 1], f[..., 2])
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
    return np.stack(np.broadcast_arrays(*accel_terms(c, f[..., 0], f[..., 1], f[..., 2])), axis=-1)


def state_derivative(state, w_cmd_p, lat, h=0.0):
    """The EKF's ``f(x)``: time derivative of the 45-vector under the torque command ``w_cmd_p``.

    The coefficients are constant; the angle rates follow from the kinematics with the exact platform
    rate ``G^-1 ((I + diag KT) w_cmd + eps)`` (the simulator's) through the Euler-angle rate relation
    (see the module notes).

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
    eps = np.stack(np.broadcast_arrays(*drift_terms(c, f[..., 0], f[..., 1], f[..., 2])), axis=-1)
    rhs = (1.0 + x[..., KT]) * w + eps
    G = np.broadcast_to(np.eye(3), x.shape[:-1] + (3, 3)).copy()
    G[..., 0, 1], G[..., 0, 2], G[..., 1, 0] = x[..., 21], x[..., 22], x[..., 23]
    G[..., 1, 2], G[..., 2, 0], G[..., 2, 1] = x[..., 24], x[..., 25], x[..., 26]
    w_ip = np.linalg.solve(G, rhs[..., None])[..., 0]
    w_np = w_ip - np.einsum("...ji,j->...i", C, w_ie_n)
    rates = _angle_rates(ang, w_np)
    out = np.zeros(np.broadcast_shapes(x.shape[:-1], rates.shape[:-1]) + (N_STATES,))
    out[..., ANGLES] = rates
    return out
