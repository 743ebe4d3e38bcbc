"""IMU error model: each error term against its closed-form statistics; seeding per run."""

import numpy as np
import pytest

from fusionbench.simulation import attitude, earth, trajectory as tj, units
from fusionbench.simulation.imu import (IMUSpec, NoiseSchedule, PRESETS, SensorErrors, VelocityReferenceSpec, simulate,
                             simulate_chunks, simulate_vref)

D = np.pi / 180
LAT = 34 * D
C_TRUE = attitude.euler_to_dcm([1 * D, -2 * D, 123 * D])


def static(duration=100.0):
    return tj.Trajectory(LAT, 108 * D, 450.0, tj.EulerSway(mean=(1 * D, -2 * D, 123 * D)), duration=duration)


def test_perfect_static_imu_measures_earth_rate_and_gravity():
    data = simulate(static(10.0), IMUSpec(), 0.01)
    w, f = data.mean_rates()
    assert w[0] == pytest.approx(C_TRUE.T @ earth.earth_rate_n(LAT), abs=1e-18)
    assert np.linalg.norm(f[0]) == pytest.approx(earth.gravity(LAT, 450.0), rel=1e-13)


def test_bias_scale_and_misalignment_enter_as_modelled():
    M = np.array([[0, 1e-3, 0], [0, 0, 0], [-2e-3, 0, 0]])
    spec = IMUSpec(gyro=SensorErrors(bias=(1e-6, 2e-6, -3e-6)),
                   accel=SensorErrors(bias=(1e-3, 0, 0), scale=(0, 0, 500e-6), misalignment=M))
    data = simulate(static(10.0), spec, 0.01)
    ref = simulate(static(10.0), IMUSpec(), 0.01)
    assert data.gyro[0] - ref.gyro[0] == pytest.approx(np.tile([1e-8, 2e-8, -3e-8], (1000, 1)), abs=1e-20)
    T = np.eye(3) + np.diag([0, 0, 500e-6]) + M
    expect = ref.accel[0] @ T.T + np.array([1e-5, 0, 0])
    assert data.accel[0] == pytest.approx(expect, abs=1e-15)


def test_angle_random_walk_has_its_variance():
    arw = 0.1 * units.DEG_PER_SQRT_H
    data = simulate(static(1000.0), IMUSpec(gyro=SensorErrors(white=(arw,) * 3)), 0.01, seed=5)
    ref = simulate(static(1000.0), IMUSpec(), 0.01)
    noise = data.gyro[0] - ref.gyro[0]
    # 100 000 samples: the sample std is within 1 % (3 sigma = 3 / sqrt(2 N) ~ 0.7 %)
    assert noise.std(axis=0) == pytest.approx(np.full(3, arw * np.sqrt(0.01)), rel=0.01)


def test_noise_schedule_multiplies_the_psd_inside_its_window():
    vrw = 50 * units.UG_PER_SQRT_HZ
    spec = IMUSpec(accel=SensorErrors(white=(vrw,) * 3), schedules=(NoiseSchedule(200.0, 400.0, 100.0),))
    data = simulate(static(600.0), spec, 0.01, seed=1)
    ref = simulate(static(600.0), IMUSpec(), 0.01)
    n = data.accel[0] - ref.accel[0]
    t = data.t
    inside = n[(t > 200.0) & (t <= 400.0)].std()
    outside = n[t <= 200.0].std()
    assert inside / outside == pytest.approx(10.0, rel=0.03)
    assert outside == pytest.approx(vrw * 0.1, rel=0.03)


def test_gauss_markov_instability_has_its_variance_and_correlation():
    sigma, tau, dt = 1e-6, 5.0, 0.1
    spec = IMUSpec(gyro=SensorErrors(instability=(sigma,) * 3, tau=tau))
    data = simulate(static(20000.0), spec, dt, seed=2)
    ref = simulate(static(20000.0), IMUSpec(), dt)
    b = (data.gyro[0, :, 0] - ref.gyro[0, :, 0]) / dt
    assert b.std() == pytest.approx(sigma, rel=0.05)  # 4000 correlation times: ~2 % sampling error
    lag = int(tau / dt)
    rho = np.corrcoef(b[:-lag], b[lag:])[0, 1]
    assert rho == pytest.approx(np.exp(-1.0), abs=0.04)


def test_the_models_bias_walk_drives_the_simulated_instability():
    # SensorErrors.bias_walk is what a bias state's random walk must be for the simulator's Gauss-Markov bias: its
    # innovations b[k+1] - exp(-dt/tau) b[k] have the variance sigma^2 (1 - exp(-2 dt/tau)) ~ (2 sigma^2 / tau) dt
    sigma, tau, dt = 1e-6, 50.0, 0.1
    errors = SensorErrors(instability=(sigma,) * 3, tau=tau)
    data = simulate(static(5000.0), IMUSpec(gyro=errors), dt, seed=4)
    b = (data.gyro[0, :, 0] - simulate(static(5000.0), IMUSpec(), dt).gyro[0, :, 0]) / dt
    innovations = b[1:] - np.exp(-dt / tau) * b[:-1]
    walk = errors.bias_walk()
    assert walk == pytest.approx(np.full(3, sigma * np.sqrt(2.0 / tau)), rel=1e-12)
    assert innovations.std() == pytest.approx(walk[0] * np.sqrt(dt), rel=0.03)  # 50 000 draws: 0.3 % sampling error
    # a rate random walk adds in quadrature; a constant bias does not walk
    both = SensorErrors(instability=(sigma,) * 3, tau=tau, random_walk=(3e-7, 0.0, 0.0)).bias_walk()
    assert both[0] == pytest.approx(np.hypot(3e-7, sigma * np.sqrt(2.0 / tau)), rel=1e-12)
    assert np.all(SensorErrors(bias=(1e-5,) * 3, bias_sigma=(1e-5,) * 3).bias_walk() == 0.0)


def test_bias_priors_count_every_unknown_part_and_are_floored():
    # fixed 3, per-run 4 (a 3-4-5 triangle), plus an instability of 12 on x: sqrt(9 + 16 + 144) = 13
    g = SensorErrors(bias=(3e-6,) * 3, bias_sigma=(4e-6,) * 3, instability=(12e-6, 0.0, 0.0))
    assert g.unknown_bias() == pytest.approx([13e-6, 5e-6, 5e-6], rel=1e-12)
    gyro, accel = IMUSpec(gyro=g).bias_prior_sigma()
    assert gyro == pytest.approx([13e-6, 5e-6, 5e-6], rel=1e-12)
    # a perfect accelerometer's prior is the floor, 10 ug; a perfect gyro's 0.01 deg/h = 4.848e-8 rad/s
    assert accel == pytest.approx(np.full(3, 10e-6 * 9.80665), rel=1e-12)
    assert IMUSpec().bias_prior_sigma()[0] == pytest.approx(np.full(3, np.radians(0.01) / 3600.0), rel=1e-12)


def test_per_run_bias_draw_has_its_sigma():
    sig = 50 * units.UG
    data = simulate(static(1.0), IMUSpec(accel=SensorErrors(bias_sigma=(sig,) * 3)), 0.1, runs=400, seed=3)
    ref = simulate(static(1.0), IMUSpec(), 0.1)
    b = (data.accel[:, 0] - ref.accel[:, 0]) / 0.1
    assert b.std(axis=0) == pytest.approx(np.full(3, sig), rel=0.15)  # 400 draws: 3 sigma = 10.6 %


def test_run_k_is_the_same_in_any_batch_and_any_chunking():
    spec = PRESETS["tactical"]
    batch = simulate(static(30.0), spec, 0.01, runs=5, seed=11)
    alone = simulate(static(30.0), spec, 0.01, runs=1, seed=11, first_run=3)
    assert np.array_equal(batch.gyro[3], alone.gyro[0])
    assert np.array_equal(batch.accel[3], alone.accel[0])
    chunks = list(simulate_chunks(static(30.0), spec, 0.01, runs=5, seed=11, chunk_s=7.0))
    assert np.array_equal(np.concatenate([c.gyro for c in chunks], axis=1), batch.gyro)
    assert not np.array_equal(batch.gyro[0], batch.gyro[1])


def test_quantisation_keeps_counts_and_carries_the_remainder():
    q = 0.01 * units.ARCSEC
    data = simulate(static(60.0), IMUSpec(gyro=SensorErrors(quantum=q)), 0.01)
    ref = simulate(static(60.0), IMUSpec(), 0.01)
    counts = data.gyro[0] / q
    assert counts == pytest.approx(np.round(counts), abs=1e-6)
    assert np.abs(np.cumsum(data.gyro[0] - ref.gyro[0], axis=0)).max() <= 0.5 * q * (1 + 1e-9)


def test_rate_output_is_increments_over_dt():
    a = simulate(static(5.0), PRESETS["mems"], 0.01, seed=4)
    b = simulate(static(5.0), PRESETS["mems"], 0.01, seed=4, output="rate")
    assert b.gyro == pytest.approx(a.gyro / 0.01, rel=1e-15)


def test_velocity_reference_noise_and_its_jump():
    t = np.arange(1, 60001) * 0.01
    v = simulate_vref(static(600.0), VelocityReferenceSpec((0.1, 0.1, 0.1), (NoiseSchedule(200, 400, 100),)), t, seed=1)
    assert v[0, t <= 200].std() == pytest.approx(0.1, rel=0.03)
    assert v[0, (t >= 200) & (t < 400)].std() == pytest.approx(1.0, rel=0.03)


def test_invalid_spec_names_the_field():
    with pytest.raises(ValueError, match="white"):
        SensorErrors(white=(-1.0, 0, 0))
    with pytest.raises(ValueError, match="tau"):
        SensorErrors(tau=0.0)
