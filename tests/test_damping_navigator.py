"""Seed 004's damped free-inertial navigation: the discrete network, the damped loop against linear theory,
the Schuler period, the adaptive scheme, chunked processing and input errors."""

import numpy as np
import pytest
from scipy import signal
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from damping import network as N
from damping import qmap
from damping.navigator import DampedNavigator, q_for_damping
from fusionbench.methods.aligner import Navigator, Site
from fusionbench.scoring import metrics
from fusionbench.simulation import earth, imu, trajectory, units
from fusionbench.simulation.imudata import IMUData
from fusionbench.simulation.translation import Translation


@pytest.mark.parametrize("q", [1.0, 2.5, 6.5])
def test_lag_realisation_is_the_network(q):
    ss = N.state_space(q)
    num, den = signal.ss2tf(ss.A, ss.B, ss.C, ss.D)
    H = N.network(q)
    np.testing.assert_allclose(num[0] / den[0], H.num / H.den[0], rtol=1e-10, atol=1e-16)


def test_discrete_table_is_the_matrix_exponential():
    """cont2discrete of the lag pair against the closed-form exponential of its Jordan block."""
    net = N.DiscreteNetwork(1.0)
    q = np.array([1.0, 1.7321, 4.2, 6.5556, 8.0])
    Ad, Bd = net.matrices(q)
    for j, qq in enumerate(q):
        a = 1.0 / N.time_constant(qq)
        e = np.exp(-a)
        np.testing.assert_allclose(Ad[j], e * np.array([[1.0, 0.0], [a, 1.0]]), atol=1e-9)
        np.testing.assert_allclose(Bd[j], [1 - e, 1 - e - a * e], atol=1e-9)
    with pytest.raises(ValueError, match="q: expected values in"):
        net.matrices([0.5])


def test_q_changing_every_step_follows_the_time_varying_network():
    """Stepping with a new q every second equals integrating the time-varying ODE with q and the input held
    over each step: nothing is lost or injected when q changes."""
    net = N.DiscreteNetwork(1.0)
    rng = np.random.default_rng(3)
    steps = 600
    q = np.clip(4.0 + np.cumsum(rng.normal(0, 0.3, steps)), 1.0, 8.0)
    u = 5.0 * np.sin(np.arange(steps) / 40.0) + rng.normal(0, 0.5, steps)
    x = np.array([1.0, -2.0])
    y_d = []
    for k in range(steps):
        y, x = net.step(q[k], x, u[k])
        y_d.append(y)

    z = np.array([1.0, -2.0])
    for k in range(steps):  # integrate step by step so the held values switch exactly at the boundaries
        ss = N.state_space(q[k])
        z_out = solve_ivp(lambda t, z: ss.A @ z + ss.B[:, 0] * u[k], (k, k + 1), z, rtol=1e-11, atol=1e-12,
                          method="DOP853").y[:, -1]
        assert N.DiscreteNetwork.output(q[k], z, u[k]) == pytest.approx(y_d[k], abs=1e-6)  # grid interpolation
        z = z_out
    np.testing.assert_allclose(x, z, atol=1e-6)


def _static(lat, hours, rate=5.0):
    traj = trajectory.Trajectory(lat, 0.0, 0.0, trajectory.EulerSway((0.0, 0.0, 0.3)), Translation(),
                                 hours * 3600.0)
    data = imu.simulate(traj, imu.IMUSpec(), 1.0 / rate)
    return traj, data


def _tilted(C, phi):
    return Rotation.from_rotvec(-np.asarray(phi)).as_matrix() @ C  # (I - [phi x]) C for small phi


def test_damped_loop_follows_the_linear_north_loop():
    """At the equator (no Foucault coupling) an initial east tilt evolves as the linear loop
    phiE' = -(dvN + k (x1 - x2)) / RM, dvN' = g phiE with the network's lags on dvN."""
    traj, data = _static(0.0, 3.0)
    phi0 = 1.0 * units.ARCMIN
    q = q_for_damping(0.5)
    nav = DampedNavigator("fixed", damp_from_s=0.0)
    res = nav.align(data, Site(0.0), init=_tilted(traj.truth([0.0]).C_bn[0], [phi0, 0, 0]))
    phi = metrics.misalignment_history(res.C_bn, traj.truth(res.t).C_bn)[0]
    g = earth.gravity(0.0)
    rm = earth.radii(0.0)[0]
    T, k = N.time_constant(q, earth.schuler_frequency(0.0)), N.gain(q)
    A = np.array([[0, -1 / rm, -k / rm, k / rm], [g, 0, 0, 0], [0, 1 / T, -1 / T, 0], [0, 0, 1 / T, -1 / T]])
    sys = signal.StateSpace(A, np.zeros((4, 1)), np.eye(4)[:1], np.zeros((1, 1)))
    t = np.concatenate([[0.0], res.t])
    _, y, _ = signal.lsim(sys, np.zeros(t.size), t, X0=[phi0, 0, 0, 0])
    assert np.max(np.abs(phi[:, 0] - y[1:])) < 0.01 * phi0  # 0.4 % measured
    # and the loop is damped: after two Schuler periods the tilt is under a tenth of its start
    assert np.max(np.abs(phi[res.t > 2 * earth.schuler_period(0.0), 0])) < 0.1 * phi0


def test_undamped_navigation_oscillates_with_the_schuler_period():
    traj, data = _static(0.0, 4.0)
    res = DampedNavigator("undamped").align(data, Site(0.0), init=_tilted(traj.truth([0.0]).C_bn[0], [units.ARCMIN, 0, 0]))
    phi_e = metrics.misalignment_history(res.C_bn, traj.truth(res.t).C_bn)[0, :, 0]
    up = np.flatnonzero((phi_e[:-1] < 0) & (phi_e[1:] >= 0))
    period = (res.t[up[-1]] - res.t[up[0]]) / (up.size - 1)
    expected = 2 * np.pi / np.sqrt(earth.gravity(0.0) / earth.radii(0.0)[0])  # the north loop's sqrt(g / RM)
    assert period == pytest.approx(expected, rel=2e-3)
    assert expected / 60 == pytest.approx(84.4, abs=0.2)
    assert np.max(np.abs(phi_e[res.t > 3 * 3600])) > 0.95 * units.ARCMIN  # undamped: no decay


def _ship(accel, lat=np.radians(35.0)):
    """Seed 004's ship, shortened: 1 h at rest, damping from 0.5 h, then east acceleration up to 20 m/s."""
    traj = trajectory.ship(lat, np.radians(241.0), 0.0, heading=np.pi / 2, accel=accel, static_s=3600.0,
                           duration=3600.0 + 20.0 / accel + 1800.0)
    data = imu.simulate(traj, imu.PRESETS["seed004"].noise_free(), 0.2)
    vref = imu.simulate_vref(traj, imu.VelocityReferenceSpec(), data.t)
    init = _tilted(traj.truth([0.0]).C_bn[0], np.radians([0.05, 0.05, 5 / 60]))
    return traj, data, vref, init, Site(lat, np.radians(241.0))


def _nav(scheme, data, vref, init, site):
    return DampedNavigator(scheme, damp_from_s=1800.0, accel_source="vref").align(data, site, vref=vref, init=init)


def test_adaptive_equals_fixed_when_the_acceleration_is_small():
    traj, data, vref, init, site = _ship(0.005)
    fixed, adaptive = (_nav(s, data, vref, init, site) for s in ("fixed", "adaptive"))
    on = fixed.t > 1800.0
    assert np.all(adaptive.series["q_E"][:, on] == pytest.approx(q_for_damping(0.5)))
    np.testing.assert_array_equal(adaptive.C_bn, fixed.C_bn)


def test_adaptive_lowers_q_to_the_map_during_a_large_acceleration():
    traj, data, vref, init, site = _ship(0.05)
    res = _nav("adaptive", data, vref, init, site)
    a, q_target = qmap.training_data(np.array([0.05]))  # the simulated largest q for 0.05 m/s^2
    during = (res.t > 3600.0 + 100.0) & (res.t < 3600.0 + 400.0)
    assert res.series["q_E"][0, during] == pytest.approx(q_target[0], abs=0.05)
    assert np.all(res.series["q_N"][0, res.t > 1800.0] == pytest.approx(q_for_damping(0.5)))  # no north motion
    # the network goes back to xi = 0.5 once the lags have forgotten the manoeuvre (5 T after it)
    nav = DampedNavigator("adaptive")
    assert res.series["q_E"][0, -1] == pytest.approx(nav.q_fixed)
    assert nav.release_s == pytest.approx(5 * N.time_constant(nav.q_fixed))


def test_chunked_navigation_equals_one_pass():
    traj, data, vref, init, site = _ship(0.05)
    nav = DampedNavigator("adaptive", damp_from_s=1800.0, accel_source="ins")
    whole = nav.align(data, site, init=init)
    assert isinstance(nav, Navigator)  # navigate is the same navigation, the policy applied
    np.testing.assert_array_equal(nav.navigate(data, site, init).C_bn, whole.C_bn)
    chunks = ((c, None) for c in imu.simulate_chunks(traj, imu.PRESETS["seed004"].noise_free(), 0.2, chunk_s=700.0))
    parts = nav.navigate_chunks(chunks, site, init, dt=0.2)
    np.testing.assert_allclose(parts.C_bn, whole.C_bn, atol=1e-12)
    np.testing.assert_array_equal(parts.t, whole.t)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="scheme: expected one of"):
        DampedNavigator("critical")
    with pytest.raises(ValueError, match="accel_source"):
        DampedNavigator(accel_source="gps")
    data = IMUData(np.arange(1, 101) * 0.3, np.zeros((1, 100, 3)), np.zeros((1, 100, 3)))
    with pytest.raises(ValueError, match="init: expected an initial attitude"):
        DampedNavigator().align(data, Site(0.5))
    with pytest.raises(ValueError, match="step_s: expected a whole number of samples"):
        DampedNavigator().align(data, Site(0.5), init=np.eye(3))
    with pytest.raises(ValueError, match="vref: accel_source 'vref' needs"):
        DampedNavigator(accel_source="vref", step_s=0.3).align(data, Site(0.5), init=np.eye(3))
