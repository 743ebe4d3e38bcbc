"""The factor graphs with aiding at a receiver's epochs (velocity and/or position rows, a lever arm, a latency, an
outage) on a car's drive with turns (:func:`fusionbench.simulation.drive.car_drive`,
:func:`fusionbench.simulation.aidingsim.simulate_aiding`): exact with a perfect IMU and exact rows and wrong when the
lever arm, the latency or the epochs are misread; within their own marginal sigma on noisy data; the robust and adaptive
graphs on rows; the rows' arithmetic against brute force."""

from dataclasses import replace

import numpy as np
import pytest

from baselines.factor_graph import FactorGraphAligner, RobustFactorGraphAligner
from baselines.graph_adaptive import AdaptiveFactorGraphAligner
from baselines.graph_aiding import build_problem, path_offsets, recording_rows, tile_data
from baselines.graph_rows import at_rows, integral_at_rows, mean_at_rows, tile_sums, tiles
from baselines.graph_support import keyframe_counts
from fusionbench.methods.aligner import Site
from fusionbench.simulation import attitude, earth, units
from fusionbench.simulation.aiding import Aiding
from fusionbench.simulation.aiding_geometry import bracket, enu_offset
from fusionbench.simulation.aidingsim import AidingSpec, simulate_aiding
from fusionbench.simulation.drive import car_drive
from fusionbench.simulation.imu import PRESETS, IMUSpec, NoiseSchedule, simulate

D = np.pi / 180
LAT = 34 * D
SITE = Site(LAT, 0.3, 50.0)
DUR = 150.0  # four 40-deg turns
DT = 0.02
EXACT = (0.0, 0.0, 0.0)
# The model is exact (rows at their times, lever arm, positions as the graph's coordinates): with a perfect IMU and
# exact rows what is left is the solver's tolerance, 2e-5 to 1e-3 arcmin measured (the most with 1-Hz positions
# across an outage, where the heading is weakest); each misreading below costs 0.9 to 30 arcmin.
TOL_ARCMIN = 0.005
CASES = {
    "velocity 10 Hz": AidingSpec(10.0, EXACT),
    "velocity 1 Hz": AidingSpec(1.0, EXACT),
    "position 1 Hz": AidingSpec(1.0, None, EXACT),
    "velocity, 1.5-m lever arm": AidingSpec(10.0, EXACT, lever_arm=(0.0, 1.5, 0.0)),
    "position, 1.5-m lever arm": AidingSpec(1.0, None, EXACT, lever_arm=(0.0, 1.5, 0.0)),
    "velocity, 50-ms latency": AidingSpec(10.0, EXACT, delay=0.05),
    "velocity, 60-s outage": AidingSpec(10.0, EXACT, outages=((60.0, 120.0),)),
    "position, 60-s outage": AidingSpec(1.0, None, EXACT, outages=((60.0, 120.0),)),
}


@pytest.fixture(scope="module")
def drive():
    # wait 0.05 s: the legs (whole 0.1 s) start between the receiver's epochs; a row exactly where the turn rate
    # jumps would read the truth's rate after the jump (the lever arm's velocity), the IMU half-way
    tr = car_drive(LAT, SITE.lon, SITE.h, heading=30 * D, duration=DUR, wait=0.05)
    guess = attitude.euler_platform_to_dcm(np.radians([0.3333, 0.3333, 0.6667])) @ tr.truth([0.0]).C_bn[0]
    return tr, simulate(tr, IMUSpec(), DT), guess, tr.truth([DUR]).C_bn[0]


def _error(drive, aiding, method=None, site=SITE):
    tr, data, guess, C_end = drive
    res = (method or FactorGraphAligner(marginals=False)).align(data, site, aiding=aiding, init=guess)
    return attitude.misalignment(res.C_bn_final[0], C_end) / units.ARCMIN


def _rows(drive, spec):
    tr, data, _, _ = drive
    return simulate_aiding(tr, spec, DUR, grid=data.increments()[0])


@pytest.mark.parametrize("case", list(CASES))
def test_a_perfect_imu_with_exact_rows_is_aligned_exactly(drive, case):
    assert np.abs(_error(drive, _rows(drive, CASES[case]))).max() < TOL_ARCMIN


@pytest.mark.parametrize("case,misread", [
    ("velocity, 1.5-m lever arm", "lever arm ignored"), ("position, 1.5-m lever arm", "lever arm ignored"),
    ("velocity, 50-ms latency", "latency ignored"), ("velocity 10 Hz", "one epoch late"),
    ("position 1 Hz", "one epoch late")])
def test_misread_rows_are_not_aligned(drive, case, misread):
    # the same rows read wrongly: the antenna's motion taken for the IMU's (0.13 m/s in a 5-deg/s turn), the rows
    # taken at their stamps, or each row's time shifted by one epoch
    aid = _rows(drive, CASES[case])
    if misread == "lever arm ignored":
        wrong = replace(aid, lever_arm=np.zeros(3))
    elif misread == "latency ignored":
        wrong = replace(aid, delay=0.0).rows(aid.t <= DUR)
    else:
        late = aid.t + np.median(np.diff(aid.t))
        wrong = replace(aid, t=late).rows(late <= DUR)
    assert np.abs(_error(drive, aid)).max() < TOL_ARCMIN
    assert np.abs(_error(drive, wrong)).max() > 100 * TOL_ARCMIN  # 0.9 to 31 arcmin measured


@pytest.mark.parametrize("kind", ["velocity", "position"])
@pytest.mark.parametrize("at_rest", [True, False])
def test_rows_at_rest_without_a_value_and_rows_that_miss_an_axis(kind, at_rest):
    # zero-velocity rows (a car at a light: no value, the IMU at rest, no lever arm) for 2 s, or none, then rows
    # from an antenna on a lever arm: velocities without a vertical (NMEA's VTG), or positions without a height:
    # every axis a row measures, and only those (the vertical channel, measured nowhere, held by a loose prior)
    tr = car_drive(LAT, SITE.lon, SITE.h, heading=30 * D, duration=DUR, wait=2.05)
    data = simulate(tr, IMUSpec(), DT)
    spec = AidingSpec(10.0, EXACT, lever_arm=(0.3, 1.5, 0.8)) if kind == "velocity" else \
        AidingSpec(1.0, None, EXACT, lever_arm=(0.3, 1.5, 0.8))
    aid = simulate_aiding(tr, spec, DUR, grid=data.increments()[0])
    rest = aid.t_valid < 2.0
    x = getattr(aid, kind).copy()
    x[..., 2] = np.nan
    x[:, rest] = np.nan
    aid = replace(aid, **{kind: x}, at_rest=rest) if at_rest else replace(aid, **{kind: x}).rows(~rest)
    guess = attitude.euler_platform_to_dcm(np.radians([0.3333, 0.3333, 0.6667])) @ tr.truth([0.0]).C_bn[0]
    assert np.abs(_error((tr, data, guess, tr.truth([DUR]).C_bn[0]), aid)).max() < TOL_ARCMIN


def test_with_positions_the_site_is_only_their_origin(drive):
    # the site given 300 m south-west of where the drive starts: the positions say where the car is (no prior at
    # the site to fight them); a prior of 1 m there would put 300 m into the first keyframe
    aid = _rows(drive, CASES["position 1 Hz"])
    off = Site(SITE.lat - 200.0 / 6.36e6, SITE.lon - 200.0 / (6.38e6 * np.cos(LAT)), SITE.h)
    assert np.linalg.norm(enu_offset(np.array([SITE.lat, SITE.lon, SITE.h]), np.array([off.lat, off.lon, off.h]))) > 250
    assert np.abs(_error(drive, aid, site=off)).max() < TOL_ARCMIN


@pytest.fixture(scope="module")
def noisy():
    tr = car_drive(LAT, SITE.lon, SITE.h, heading=30 * D, duration=DUR, wait=0.05)
    data = simulate(tr, PRESETS["navigation"], DT, runs=3, seed=2)
    guess = attitude.euler_platform_to_dcm(np.radians([0.3333, 0.3333, 0.6667])) @ tr.truth([0.0]).C_bn[0]
    return tr, data, guess, tr.truth([DUR]).C_bn[0]


def _noisy_run(noisy, spec):
    tr, data, guess, C_end = noisy
    aid = simulate_aiding(tr, spec, DUR, runs=3, seed=2, grid=data.increments()[0])
    res = FactorGraphAligner().align(data, SITE, aiding=aid, init=guess)  # the navigation model, rows' sigmas
    phi = np.stack([attitude.misalignment(C, C_end) for C in res.C_bn_final])
    return phi, res.sigma_phi[:, -1]


@pytest.mark.parametrize("case", ["velocity 10 Hz", "velocity 1 Hz", "position 1 Hz", "velocity, 1.5-m lever arm",
                                  "velocity, 50-ms latency", "velocity, 60-s outage"])
def test_noisy_rows_land_within_the_graphs_own_sigma(noisy, case):
    # navigation grade, a GNSS receiver's 0.05 m/s and 0.5 m: over three runs, each axis's rms of error over its
    # marginal sigma below 2.5 (a chi-square of 3 degrees of freedom exceeds 3 x 2.5^2 with probability 3e-4;
    # 0.3 to 1.4 measured); and the sigma says what the rows hold
    spec = replace(CASES[case], velocity_sigma=None if CASES[case].velocity_sigma is None else (0.05,) * 3,
                   position_sigma=None if CASES[case].position_sigma is None else (0.5,) * 3)
    phi, sig = _noisy_run(noisy, spec)
    assert np.all(np.sqrt(np.mean((phi / sig) ** 2, axis=0)) < 2.5), phi / sig
    # the level to a tenth of an arcmin (accelerometer bias 25 ug: 0.09), the heading to a few arcmin
    assert np.all(sig[:, :2] < 0.12 * units.ARCMIN) and np.all(sig[:, 2] < 6 * units.ARCMIN)


def test_fewer_rows_leave_a_larger_sigma(noisy):
    # the same drive: a tenth of the velocity rows, or 60 s of them missing, tell less about the heading
    sig = {r: _noisy_run(noisy, AidingSpec(r, (0.05,) * 3))[1][:, 2].mean() for r in (10.0, 1.0)}
    gap = _noisy_run(noisy, AidingSpec(10.0, (0.05,) * 3, outages=((60.0, 120.0),)))[1][:, 2].mean()
    assert sig[10.0] < gap < sig[1.0]


def test_the_robust_graph_discounts_outlying_rows_and_the_adaptive_one_finds_a_noisier_stretch(drive):
    aid = _rows(drive, CASES["velocity 10 Hz"])
    v = aid.velocity.copy()
    v[:, np.random.default_rng(1).choice(v.shape[1], v.shape[1] // 50, replace=False), :2] += 3.0  # 2 % 3 m/s off
    bad = replace(aid, velocity=v)
    plain = np.abs(_error(drive, bad)).max()
    robust = np.abs(_error(drive, bad, RobustFactorGraphAligner(marginals=False))).max()
    assert plain > 10.0 and robust < 0.05 * plain  # 25 and 0.3 arcmin measured
    # the rows' noise variance x100 from 60 to 90 s (0.05 m/s nominal, the sigma the rows report): each 10-s
    # window's factor from about 300 degrees of freedom, to some 10 %
    tr, data, guess, _ = drive
    noisy = simulate_aiding(tr, AidingSpec(10.0, (0.05,) * 3, schedules=(NoiseSchedule(60.0, 90.0, 100.0),)), DUR,
                            grid=data.increments()[0], seed=3)
    res = AdaptiveFactorGraphAligner(marginals=False).align(data, SITE, aiding=noisy, init=guess)
    t, lam = res.extra["adapt_window_t"], res.extra["reference_variance_scale"][0]
    inside, outside = (t > 60) & (t < 90), (t < 55) | (t > 95)
    assert np.all((lam[inside] > 60) & (lam[inside] < 160)), lam
    assert np.all((lam[outside] > 0.6) & (lam[outside] < 1.6)), lam
    assert np.all(res.extra["position_variance_scale"] == 1.0)  # no position rows


def test_keyframes_without_rows_have_no_factor_and_rows_between_samples_are_read_there():
    t0, dt, M = 0.0, 0.02, 1500
    t_end = t0 + dt * np.arange(1, M + 1)
    counts = keyframe_counts(M, 25)  # 0.5-s keyframes
    t_kf = np.r_[t0, t_end[counts[1:] - 1]]
    rng = np.random.default_rng(0)
    tv = np.arange(0.7, 30.0, 1.0) + 0.003  # 1 Hz, between samples
    tv = tv[(tv < 10.0) | (tv > 20.0)]  # a 10-s outage
    aid = Aiding(tv, velocity=rng.standard_normal((tv.size, 3)), position=np.column_stack(
        [LAT + 1e-6 * rng.standard_normal(tv.size), np.full(tv.size, 0.3), np.full(tv.size, 50.0)]))
    rows = recording_rows(aid.for_runs(1), 0, t_end, SITE, 0.01, 1.0)
    pr = build_problem(rows, SITE, t_end, t_kf, counts, dt, 1e-5 * rng.standard_normal((M, 3)),
                       np.tile([0.0, 0.0, 9.8 * dt], (M, 1)))
    data = tile_data(pr, np.broadcast_to(np.eye(3), (counts.size, 3, 3)))
    has = np.isfinite(data["v"]["var"][:, 0])
    assert has.sum() == tv.size and np.all(np.isfinite(data["p"]["var"][:, 0]) == has)
    assert set(np.flatnonzero(has)) == set(tiles(tv, t_kf))  # each row in its nearest keyframe's tile, no other
    assert not has[(t_kf > 10.5) & (t_kf < 19.5)].any()
    # a quantity summed per sample, read at a row inside sample j, is the straight line between the sample ends,
    # and its integral from the keyframe the area under those lines (trapezoids, exact for a line)
    x = rng.standard_normal((M, 2))
    tol = 8 * np.finfo(float).eps * M * np.abs(x).max()  # rounding of a cumulative sum over the record
    tile = tiles(t_end, t_kf)
    S = tile_sums(x, tile, counts)
    j, w = bracket(t_end, t0, tv)
    for i in range(tv.size):
        k, c = tile[j[i]], counts[tile[j[i]]]  # the row's keyframe at the end of sample c - 1
        ends = np.r_[t_kf[k], t_end[min(c, j[i]):max(c, j[i] + 1)]]  # from the keyframe to the sample's end
        if j[i] >= c:
            vals = np.vstack([np.zeros(2), np.cumsum(x[c:j[i] + 1], axis=0)])
        else:
            vals = np.vstack([np.zeros(2), -np.cumsum(x[j[i] + 1:c][::-1], axis=0)])[::-1]
            ends = np.r_[t_end[j[i]:c], t_kf[k]]
        line = np.stack([np.interp(tv[i], ends, vals[:, a]) for a in range(2)])
        assert at_rows(S, x, j[i:i + 1], w[i:i + 1])[0] == pytest.approx(line, abs=tol)
        lo, hi = sorted((t_kf[k], tv[i]))
        knots = np.unique(np.r_[lo, ends[(ends > lo) & (ends < hi)], hi])  # every kink: the trapezoids are exact
        area = np.trapezoid(np.stack([np.interp(knots, ends, vals[:, a]) for a in range(2)], axis=1), knots, axis=0)
        area = area if tv[i] >= t_kf[k] else -area
        assert integral_at_rows(S, x, j[i:i + 1], w[i:i + 1], dt, tile, counts)[0] == pytest.approx(area, abs=tol)
    # a per-sample mean rate read at a row: between the middles of the samples around it
    r = rng.standard_normal((M, 3))
    mid = t_end - dt / 2
    assert mean_at_rows(r, j, w) == pytest.approx(np.stack([np.interp(tv, mid, r[:, a]) for a in range(3)], 1))


def test_positions_are_put_in_the_graphs_coordinates_the_integral_of_the_velocity():
    # east 1.5 km along the parallel (where the two agree), then north 1.5 km at 10 m/s: the ENU offset of the end
    # differs from the integral of the ENU velocity by the meridians' convergence, E N tan(L) / (2 R_N) in east
    # (12 cm), and in north by the meridian radius's change, R_M' N^2 / (2 R_M^2) (1.7 mm), second order both
    dt, n, E = 0.1, 1500, 1500.0
    v = np.vstack([np.tile([10.0, 0.0, 0.0], (n, 1)), np.tile([0.0, 10.0, 0.0], (n, 1))])
    d = path_offsets(v, np.zeros(3), dt, SITE)
    rm, rn = earth.radii(LAT)
    e2 = 6.69437999014e-3  # WGS-84
    assert np.abs(d[: n + 1]).max() < 1e-6
    assert d[-1, 0] == pytest.approx(E * E * np.tan(LAT) / (2 * rn), rel=0.01)
    s2 = np.sin(LAT) ** 2
    assert d[-1, 1] == pytest.approx(3 * e2 * np.sin(LAT) * np.cos(LAT) / (1 - e2 * s2) * E * E / (2 * rm), rel=0.05)
    assert d[-1, 2] == 0.0


def test_claims_and_a_bad_position_sigma():
    s = FactorGraphAligner.supports
    assert s.covers("moving", 34.0, aiding=("position",), aiding_hz=0.1, outage_s=140.0)
    assert not s.covers("moving", 34.0, aiding=("velocity",), aiding_hz=0.05)
    assert not s.covers("moving", 34.0, aiding=("velocity",), aiding_hz=1.0, outage_s=200.0)
    with pytest.raises(ValueError, match="gtsam.*aiding_position_sigma.*positive.*-1"):
        FactorGraphAligner(aiding_position_sigma=-1.0)
