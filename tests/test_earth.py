"""Earth model against WGS-84 published values and closed forms."""

import numpy as np
import pytest

from fusionbench.simulation import earth, units


def test_gravity_equator_and_pole_are_somigliana_constants():
    assert earth.gravity(0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert earth.gravity(np.pi / 2) == pytest.approx(9.8321849378, abs=1e-10)


@pytest.mark.parametrize("lat_deg", [15.0, 45.0, 70.0])
def test_gravity_agrees_with_the_1980_series_formula(lat_deg):
    # International Gravity Formula 1980: 9.780327 (1 + 0.0053024 sin^2 L - 0.0000058 sin^2 2L),
    # a truncated series of the same ellipsoid: agreement to about 1e-5 m/s^2
    L = np.radians(lat_deg)
    series = 9.780327 * (1 + 0.0053024 * np.sin(L) ** 2 - 0.0000058 * np.sin(2 * L) ** 2)
    assert earth.gravity(L) == pytest.approx(series, abs=2e-5)


def test_free_air_gradient():
    # d g / d h = -2 g / a (1 + f + m - 2 f sin^2 L): about -3.086e-6 s^-2 at the equator
    dg = earth.gravity(0.0, 1000.0) - earth.gravity(0.0, 0.0)
    assert dg / 1000.0 == pytest.approx(-3.0877e-6, rel=2e-3)


def test_earth_rate_components_and_norm():
    lat = np.radians(34.0)
    w = earth.earth_rate_n(lat)
    assert w[0] == 0.0
    assert w[1] == pytest.approx(7.292115e-5 * np.cos(lat), rel=1e-15)
    assert w[2] == pytest.approx(7.292115e-5 * np.sin(lat), rel=1e-15)
    assert np.linalg.norm(w) == pytest.approx(15.04107 * units.DEG_PER_H, rel=1e-6)


def test_radii_at_equator_and_pole():
    rm, rn = earth.radii(0.0)
    assert rn == pytest.approx(earth.A, rel=1e-15)
    assert rm == pytest.approx(earth.A * (1 - earth.E2), rel=1e-15)
    rm, rn = earth.radii(np.pi / 2)
    assert rm == pytest.approx(rn, rel=1e-12)
    assert rn == pytest.approx(earth.A**2 / earth.B, rel=1e-12)


def test_schuler_period_is_84_4_minutes():
    assert earth.schuler_period(np.radians(34.0)) / 60.0 == pytest.approx(84.4, abs=0.1)


def test_transport_rate_for_east_velocity():
    lat = np.radians(30.0)
    w = earth.transport_rate_n([10.0, 0.0, 0.0], lat, 0.0)
    _, rn = earth.radii(lat)
    assert w == pytest.approx([0.0, 10.0 / rn, 10.0 * np.tan(lat) / rn], rel=1e-14)


def test_latitude_check_names_the_field():
    with pytest.raises(ValueError, match="site latitude"):
        earth.check_latitude(np.radians(95.0), "site latitude")
