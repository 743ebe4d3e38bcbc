"""Analytic and inertial-frame coarse alignment against pyins fixtures and the theoretical limits."""

import numpy as np
import pytest

from baselines.coarse import CoarseAligner, InertialCoarseAligner, gravity_integral_inertial
from fusionbench import attitude, earth, metrics, trajectory as tj, units
from fusionbench.aligner import Site
from fusionbench.imu import IMUSpec, SensorErrors, simulate
from fusionbench.imudata import IMUData
from tests.conftest import load_fixture

D = np.pi / 180


def fixture_imu(stem):
    t, g, a, meta = load_fixture(stem)
    return IMUData(t, g[None], a[None], "rate"), meta, Site.from_degrees(meta["lat_deg"], meta["lon_deg"], meta["height_m"])


def test_perfect_pyins_static_file_is_recovered_exactly():
    imu, meta, site = fixture_imu("pyins_static_40n_perfect")
    res = CoarseAligner().align(imu, site)
    err = attitude.misalignment(res.C_bn_final[0], np.array(meta["C_bn_last"]))
    assert np.abs(err).max() < 1e-5 * units.ARCMIN


def test_noisy_pyins_static_file_lands_on_its_limits_within_the_noise():
    imu, meta, site = fixture_imu("pyins_static_40n_noisy")
    C = np.array(meta["C_bn_last"])
    err = attitude.misalignment(CoarseAligner().align(imu, site).C_bn_final[0], C)
    lim = metrics.theoretical_limits(meta["gyro_bias_body_rad_s"], meta["accel_bias_body_m_s2"], C, site.lat, site.h)
    # white noise averaged over T: level VRW / (g sqrt T), azimuth ARW / (W cos L sqrt T)
    T = imu.duration
    sig_level = 10 * units.UG_PER_SQRT_HZ / (site.g * np.sqrt(T))
    sig_az = 0.005 * units.DEG_PER_SQRT_H / (earth.OMEGA_IE * np.cos(site.lat) * np.sqrt(T))
    assert np.abs(err[:2] - lim[:2]).max() < 4 * sig_level
    assert abs(err[2] - lim[2]) < 4 * sig_az


@pytest.mark.parametrize("lat_deg,heading_deg", [(34, 123), (34, 180), (-45, -179), (60, 0), (-20, 90)])
def test_noise_free_biased_data_lands_on_the_limits(lat_deg, heading_deg):
    lat = lat_deg * D
    euler = (1.5 * D, -2 * D, -heading_deg * D)
    tr = tj.Trajectory(lat, 0.3, 100.0, tj.EulerSway(mean=euler), duration=120.0)
    eps = np.array([0.01, -0.02, 0.015]) * units.DEG_PER_H
    nab = np.array([100, -60, 40]) * units.UG
    data = simulate(tr, IMUSpec(gyro=SensorErrors(bias=eps), accel=SensorErrors(bias=nab)), 0.02)
    err = attitude.misalignment(CoarseAligner().align(data, Site(lat, 0.3, 100.0)).C_bn_final[0], tr.truth([120.0]).C_bn[0])
    lim = metrics.theoretical_limits(eps, nab, tr.truth([120.0]).C_bn[0], lat, 100.0)
    assert err == pytest.approx(lim, rel=0.01)


def test_gravity_integral_inertial_is_the_integral_of_the_turning_gravity():
    lat, g = 0.6, 9.8
    t = np.linspace(0, 3000, 30001)
    u = np.array([0, np.cos(lat), np.sin(lat)])
    f = attitude.rotvec_to_dcm(np.outer(t, u * earth.OMEGA_IE)) @ [0, 0, g]
    numeric = np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(t)[:, None], axis=0)  # trapezoid, error ~1e-8 m/s
    assert gravity_integral_inertial(t[1:], lat, g) == pytest.approx(numeric, abs=1e-6)


def test_inertial_coarse_alignment_is_exact_on_a_perfect_swaying_base():
    lat = 34 * D
    sway = tj.EulerSway(mean=(0.5 * D, 1 * D, -30 * D), amplitude=(1 * D, 1.5 * D, 2 * D), frequency=(0.2, 0.1, 0.05))
    tr = tj.Trajectory(lat, 0.0, 0.0, sway, duration=200.0)
    data = simulate(tr, IMUSpec(), 0.01)
    res = InertialCoarseAligner().align(data, Site(lat))
    err = attitude.misalignment(res.C_bn_final[0], tr.truth([200.0]).C_bn[0])
    assert np.abs(err).max() < 0.01 * units.ARCMIN
    # the analytic method is defeated by the same sway: the mean gyro rate carries the net sway rotation
    bad = attitude.misalignment(CoarseAligner().align(data, Site(lat)).C_bn_final[0], tr.truth([200.0]).C_bn[0])
    assert abs(bad[2]) > 10 * units.ARCMIN
