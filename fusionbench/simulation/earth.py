"""WGS-84 earth model: constants, normal gravity, earth rate, radii of curvature.

Conventions: the navigation frame n is East-North-Up (ENU). Latitude and longitude are
geodetic, in radians; height is above the ellipsoid, in metres. Every function accepts
NumPy arrays and broadcasts over leading axes.

References: NIMA TR8350.2 (WGS-84), Somigliana's closed formula for normal gravity with the
second-order free-air height correction used by the same report.
"""

from __future__ import annotations

import numpy as np

#: Semi-major axis, m.
A = 6378137.0
#: Flattening.
F = 1.0 / 298.257223563
#: Semi-minor axis, m.
B = A * (1.0 - F)
#: First eccentricity squared.
E2 = F * (2.0 - F)
#: Earth rotation rate, rad/s.
OMEGA_IE = 7.292115e-5
#: Geocentric gravitational constant GM, m^3/s^2.
GM = 3.986004418e14
#: Normal gravity at the equator and at the poles (Somigliana), m/s^2.
GAMMA_E = 9.7803253359
GAMMA_P = 9.8321849378
#: Somigliana's constant k = (b gamma_p - a gamma_e) / (a gamma_e).
K_SOMIGLIANA = (B * GAMMA_P - A * GAMMA_E) / (A * GAMMA_E)
#: m = omega^2 a^2 b / GM, used by the height correction.
M_RATIO = OMEGA_IE**2 * A**2 * B / GM


def gravity(lat, h=0.0):
    """Magnitude of normal gravity (gravitation plus centrifugal) on the WGS-84 ellipsoid.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude, rad.
    h : array_like, optional
        Height above the ellipsoid, m.

    Returns
    -------
    ndarray
        Normal gravity, m/s^2 (positive; the vector in ENU is ``[0, 0, -g]``).
    """
    lat = np.asarray(lat, dtype=float)
    h = np.asarray(h, dtype=float)
    return somigliana(np.sin(lat) ** 2, h)


def somigliana(s2, h):
    """Normal gravity (m/s^2) from sin^2(latitude) and height (m); plain arithmetic on floats or arrays.

    Kept free of NumPy calls so that compiled integrators can reuse it unchanged.
    """
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / (1.0 - E2 * s2) ** 0.5
    return g0 * (1.0 - 2.0 / A * (1.0 + F + M_RATIO - 2.0 * F * s2) * h + 3.0 / A**2 * h**2)


def radii_from_sin2(s2):
    """Meridian and transverse radii (m) from sin^2(latitude); plain arithmetic (see somigliana)."""
    w = 1.0 - E2 * s2
    rn = A / w**0.5
    return rn * (1.0 - E2) / w, rn


def gravity_n(lat, h=0.0):
    """Normal gravity vector in the ENU frame, ``[0, 0, -g]``, m/s^2, shape ``(..., 3)``."""
    g = gravity(lat, h)
    out = np.zeros(g.shape + (3,))
    out[..., 2] = -g
    return out


def earth_rate_n(lat):
    """Earth rotation rate resolved in ENU at latitude ``lat`` (rad).

    Returns
    -------
    ndarray, shape (..., 3)
        ``[0, OMEGA_IE cos(lat), OMEGA_IE sin(lat)]`` in rad/s.
    """
    lat = np.asarray(lat, dtype=float)
    out = np.zeros(lat.shape + (3,))
    out[..., 1] = OMEGA_IE * np.cos(lat)
    out[..., 2] = OMEGA_IE * np.sin(lat)
    return out


def radii(lat):
    """Meridian (north-south) and transverse (prime-vertical) radii of curvature.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude, rad.

    Returns
    -------
    rm, rn : ndarray
        Meridian radius R_M and transverse radius R_N, m.
    """
    lat = np.asarray(lat, dtype=float)
    return radii_from_sin2(np.sin(lat) ** 2)


def transport_rate_n(v_n, lat, h=0.0):
    """Transport rate omega_en^n of the ENU frame over the earth, rad/s, shape ``(..., 3)``.

    Parameters
    ----------
    v_n : array_like, shape (..., 3)
        Velocity over the earth in ENU, m/s.
    lat : array_like
        Geodetic latitude, rad.
    h : array_like, optional
        Height, m.
    """
    v_n = np.asarray(v_n, dtype=float)
    rm, rn = radii(lat)
    rmh = rm + h
    rnh = rn + h
    out = np.empty(np.broadcast_shapes(v_n.shape, np.shape(rmh) + (3,)))
    out[..., 0] = -v_n[..., 1] / rmh
    out[..., 1] = v_n[..., 0] / rnh
    out[..., 2] = v_n[..., 0] * np.tan(lat) / rnh
    return out


def schuler_frequency(lat=0.0, h=0.0):
    """Schuler angular frequency sqrt(g / R), rad/s, with R the Gaussian mean radius sqrt(R_M R_N).

    The period ``2 pi / schuler_frequency`` is about 84.4 minutes.
    """
    rm, rn = radii(lat)
    return np.sqrt(gravity(lat, h) / (np.sqrt(rm * rn) + h))


def schuler_period(lat=0.0, h=0.0):
    """Schuler period 2 pi / omega_s, s (about 5064 s = 84.4 min)."""
    return 2.0 * np.pi / schuler_frequency(lat, h)


def check_latitude(lat, name="latitude", limit_deg=90.0):
    """Raise ``ValueError`` naming ``name`` unless every latitude (rad) is finite and within +-``limit_deg`` deg
    (by default the whole range [-90, 90] deg; a method declares a smaller limit where its heading needs the
    horizontal earth rate)."""
    lat = np.asarray(lat, dtype=float)
    limit = min(float(limit_deg), 90.0)
    beyond = np.abs(lat) > np.pi / 2 if limit >= 90.0 else np.abs(np.degrees(lat)) > limit
    if not np.all(np.isfinite(lat)) or np.any(beyond):
        deg = np.degrees(lat).ravel()
        found = f"{deg[0]:g}" if deg.size == 1 else f"{deg[:3].tolist()}"
        raise ValueError(f"{name}: expected a latitude between -{limit:g} and {limit:g} deg, found {found} deg")