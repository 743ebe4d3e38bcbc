"""eso-td's default configuration against what the data allow: static, swaying and moving bases, from its own start.

Criteria (issue "Right answers on anyone's data", item 5): final level errors within 0.5' of the limits and
the final azimuth error less its limit, rms over the runs, at most 3 x the attainable bound

    sigma_U = sqrt(ARW^2 / (W^2 cos^2 L T) + (instability / (W cos L))^2)

on a static or swaying base (T the record's length), and at most 3 x the project's Kalman filter's rms on
a moving base with a noisy velocity reference. The default reads the azimuth as the least-squares slope of
eq. 12 over the fit, which starts when the ESO's expanding memory reaches its floor (on a fixed base 12.1 s
after the 60-s coarse stage): for an angle random walk that slope has 6/5 the variance of the whole record's
end-point difference, over T_fit = T - 60 - 12.1 s, so the expected ratio to the bound is sqrt(1.2 T / T_fit)
(1.26 over 300 s) when the ARW dominates.

A tactical gyro's tilt walk needs the fixed base's wider ESO floor (w0 = 0.2 rad/s): the conformance matrix's own
level tolerance (the bias-only limit plus what the instability and rate random walk move it by) is met with it and
missed with the moving base's 0.05 rad/s.
"""

import numpy as np
import pytest

from adrc.moving_base import MOVING_BASE_GAINS, ESOTDAligner
from fusionbench.bench import scenarios
from fusionbench.bench.experiment import run_scenario
from fusionbench.methods.coarse import InertialCoarseAligner
from baselines.kalman import KalmanAligner
from fusionbench.methods.aligner import Site
from fusionbench.scoring import metrics
from fusionbench.simulation import attitude, earth, trajectory as tj, units
from fusionbench.simulation.imu import PRESETS, VelocityReferenceSpec, simulate, simulate_vref
from fusionbench.simulation.imudata import IMUData
from tests.conftest import load_fixture
from tests.moving_base_helpers import moving_base_limits

D = np.pi / 180
ARCMIN = units.ARCMIN


def _constant_biases(spec, runs, seed):
    """Each run's constant gyro and accelerometer biases (body, SI): the fixed part plus its per-run draw,
    as the simulator draws them."""
    from fusionbench.simulation.imusim import _RunState

    states = [_RunState(spec, seed, r) for r in range(runs)]
    return (np.array([st.sensors["gyro"]["bias"] for st in states]),
            np.array([st.sensors["accel"]["bias"] for st in states]))


def bound(spec, lat, T):
    """The attainable azimuth bound (rad) of a static or swaying base over T s (module docstring)."""
    wN = earth.OMEGA_IE * np.cos(lat)
    return np.hypot(spec.gyro.white[0] / (wN * np.sqrt(T)), spec.gyro.instability[0] / wN)


@pytest.mark.parametrize("kind,lat_deg,heading_deg,preset,vref_sigma", [
    ("static", 34.0, 0.0, "seed000", 0.0),
    ("static", 60.0, 179.0, "navigation", 0.05),   # a zero reference with 0.05 m/s white noise per sample
    ("sway", -45.0, -179.0, "seed000", 0.0),       # seed 000's 5/7/9-deg sway and 0.05 m/s velocity disturbance
])
def test_static_and_swaying_bases_reach_the_attainable_bound(kind, lat_deg, heading_deg, preset, vref_sigma):
    runs, seed, dt, T = 8, 11, 0.01, 300.0
    lat = lat_deg * D
    mean = (0.5 * D, -1.0 * D, -heading_deg * D)
    if kind == "sway":
        tr = tj.moored(lat, mean=mean, disturbance_rms=0.05, duration=T)
    else:
        tr = tj.Trajectory(lat, 0.0, 0.0, tj.EulerSway(mean=mean), duration=T)
    spec = PRESETS[preset]
    data = simulate(tr, spec, dt, runs=runs, seed=seed)
    vref = None
    if vref_sigma:
        vref = simulate_vref(tr, VelocityReferenceSpec((vref_sigma,) * 3), data.increments()[0], runs=runs, seed=seed)
    res = ESOTDAligner().align(data, Site(lat), vref=vref)
    phi = attitude.misalignment(res.C_bn_final, tr.truth([res.t_end]).C_bn[0])
    eps, nab = _constant_biases(spec, runs, seed)
    C_mean = tr.truth(np.linspace(T / 2, T, 201)).C_bn.mean(axis=0)  # the limits are linear in C: the sway's mean
    lim = np.stack([metrics.theoretical_limits(eps[r], nab[r], C_mean, lat) for r in range(runs)])
    dev = (phi - lim) / ARCMIN
    assert np.abs(dev[:, :2]).max() < 0.5  # measured 0.044', 0.038', 0.072'
    rms, b = np.sqrt(np.mean(dev[:, 2] ** 2)), bound(spec, lat, T) / ARCMIN
    assert rms < 3 * b
    expected = np.sqrt(1.2 * T / (T - 60.0 - ESOTDAligner().for_base(fixed=True).td_start_s))
    # 8 runs: the rms is known to about 25 %; the instability and the reference add for navigation grade
    # (measured 1.32, 1.58, 1.42 times the bound)
    assert 0.6 * expected < rms / b < 1.5 * expected


def test_a_moving_base_with_a_noisy_reference_is_within_three_times_the_kalman_filter():
    # seed 001's base (0.1 g east, heading 90 deg), its IMU, a 0.1 m/s reference at 10 Hz; both start
    # from coarse-i0 with the reference over the first 60 s (kf's own start takes no reference yet)
    runs, seed, dt, T, sigma = 8, 5, 0.1, 400.0, 0.1
    lat = 34 * D
    tr = tj.accelerating(lat, mean=(0.0, 0.0, -90 * D), duration=T)
    spec = PRESETS["seed001"]
    data = simulate(tr, spec, dt, runs=runs, seed=seed)
    t, dth, dv = data.increments()
    vref = simulate_vref(tr, VelocityReferenceSpec((sigma,) * 3), t, runs=runs, seed=seed)
    site = Site(lat)
    eso = ESOTDAligner().align(data, site, vref=vref)
    k0 = int(round(60.0 / dt))
    first = InertialCoarseAligner(history_points=20).align(IMUData(t[:k0], dth[:, :k0], dv[:, :k0]), site,
                                                             vref=vref[:, :k0])
    kf = KalmanAligner(imu=spec, vref_sigma=sigma).align(IMUData(t[k0:], dth[:, k0:], dv[:, k0:]), site,
                                                          vref=vref[:, k0:], init=first.C_bn_final)
    eps, nab = _constant_biases(spec, runs, seed)
    C_end = tr.truth([t[-1]]).C_bn[0]
    lim = moving_base_limits(tr, [t[-1]], eps @ C_end.T, nab @ C_end.T)[:, 0]
    dev = {name: (attitude.misalignment(res.C_bn_final, C_end) - lim) / ARCMIN for name, res in
           (("eso-td", eso), ("kf", kf))}
    assert np.abs(dev["eso-td"][:, :2]).max() < 0.5  # measured 0.36' (kf 0.34')
    rms = {k: np.sqrt(np.mean(v[:, 2] ** 2)) for k, v in dev.items()}
    assert rms["eso-td"] < 3 * rms["kf"]  # measured 2.1' against 1.75' (400 s)


def test_a_static_recording_from_another_simulator_lands_on_its_limits():
    # pyins, 40 N, 10 Hz rate samples, 300 s, ARW 0.005 deg/sqrt(h), VRW 10 ug/sqrt(Hz), constant biases:
    # through the align command's path (no reference, no initial attitude). The printed configuration
    # was 32' off; the bound is 5.2'
    t, g, a, meta = load_fixture("pyins_static_40n_noisy")
    imu = IMUData(t, g[None], a[None], "rate")
    site = Site.from_degrees(meta["lat_deg"], meta["lon_deg"], meta["height_m"])
    C = np.array(meta["C_bn_last"])
    lim = metrics.theoretical_limits(meta["gyro_bias_body_rad_s"], meta["accel_bias_body_m_s2"], C, site.lat, site.h)
    dev = (attitude.misalignment(ESOTDAligner().align(imu, site).C_bn_final[0], C) - lim) / ARCMIN
    assert np.abs(dev[:2]).max() < 0.5
    b = 0.005 * units.DEG_PER_SQRT_H / (earth.OMEGA_IE * np.cos(site.lat) * np.sqrt(imu.duration)) / ARCMIN
    assert abs(dev[2]) < 3 * b  # measured 5.5' (one draw)


class MovingBaseFloor(ESOTDAligner):
    """eso-td with the moving base's ESO floor on every base (w0 = 0.05 rad/s): what the fixed base had before."""

    name = "eso-td-moving-floor"

    def __init__(self, **kw):
        b1, b2 = MOVING_BASE_GAINS
        super().__init__(beta11=b1, beta12=b2, beta21=b1, beta22=b2, **kw)


TACTICAL = """
name = "eso-td-tactical"
experiment = "conformance"
duration_s = 300.0
rate_hz = 10.0
runs = 6
methods = ["eso-td", "tests.test_eso_td_accuracy:MovingBaseFloor"]
[conformance]
level_tolerance_arcmin = 0.5
efficiency = { default = 3.0 }
[[condition]]
name = "static-tac"
base = "static"
lat_deg = 0.0
heading_deg = 90.0
imu = "tactical"
[[condition]]
name = "sway-tac"
base = "sway-table1"
lat_deg = -45.0
heading_deg = -179.0
imu = "tactical"
"""


def test_a_tactical_imu_on_a_fixed_base_passes_with_the_fixed_bases_floor_and_not_with_the_moving_ones(tmp_path):
    p = tmp_path / "tactical.toml"
    p.write_text(TACTICAL)
    cells = run_scenario(scenarios.load(p), seed=3, progress=False).metrics["cells"]
    fixed, moving = cells["eso-td"], cells["tests.test_eso_td_accuracy:MovingBaseFloor"]
    assert ESOTDAligner().for_base(fixed=True).beta1 == (0.4, 0.4)  # w0 = 0.2 rad/s chosen on a fixed base
    for cond in ("static-tac", "sway-tac"):
        assert fixed[cond]["status"] == "pass"  # measured levels 0.40'/0.17' (tolerance 0.65'), 0.19'/0.38' (0.52')
        worst = {name: max(c[cond]["final_minus_limit_rms_arcmin"][ax] for ax in "EN")
                 for name, c in (("fixed", fixed), ("moving", moving))}
        assert worst["fixed"] < worst["moving"]  # measured 0.40' < 0.70', 0.38' < 0.64'
    assert "fail" in (moving["static-tac"]["status"], moving["sway-tac"]["status"])
