"""Consistency without truth (fusionbench.recording.consistency): the carry is exact and a one-sample timing error
shows, a constant bias does not show, white noise shows as the attainable bound says, and bad input is one clear error.

Every expected number comes from the trajectory's truth composed with the earth's turn, from the error model of
a stationary alignment, or from the bound; tolerances are the strapdown's own accuracy (0.01 arcsec, as
tests/test_strapdown.py) or chi-square limits on an RMS estimated from a known number of window pairs."""

import json
import sys
import types

import numpy as np
import pytest
from scipy.stats import chi2

from fusionbench.methods.aligner import AlignmentResult, Site
from fusionbench.recording.consistency import carry, consistency
from fusionbench.recording.consistency_report import summary_lines, to_json, write_consistency_report
from fusionbench.scoring import metrics
from fusionbench.simulation import attitude, earth, imu as imu_mod, trajectory as tj, units
from fusionbench.simulation.imudata import IMUData
from fusionbench.simulation.translation import Translation, VelocityDisturbance

D = units.DEG
SITE = Site(34 * D, 108 * D, 450.0)
EXACT = 0.01 * units.ARCSEC  # the strapdown's accuracy on exact increments (tests/test_strapdown.py)
#: Sway of a few degrees at 0.11-0.17 Hz (peak rates 5-6 deg/s per axis), frequencies that do not divide the
#: windows: a periodic sway with whole cycles per window would hide a timing error (same rate at both ends).
SWAY = tj.EulerSway(mean=(1 * D, -2 * D, 30 * D), amplitude=(5 * D, 7 * D, 9 * D), frequency=(0.17, 0.13, 0.11))


def swaying(duration):
    return tj.Trajectory(SITE.lat, SITE.lon, SITE.h, SWAY,
                         Translation(disturbance=VelocityDisturbance((0.05,) * 3)), duration)


def static(duration, mean=(1 * D, -2 * D, 123 * D)):
    return tj.Trajectory(SITE.lat, SITE.lon, SITE.h, tj.EulerSway(mean=mean), duration=duration)


def rate_nb(t):
    """|omega_nb^b| of the sway at time t, rad/s: how fast the attitude changes."""
    return float(np.linalg.norm(tj.euler_rates_to_body(*SWAY.euler(np.array([t])))))


def earth_turn(T):
    """N = exp([omega_ie^n T x]): the ENU frame's turn with the earth over T s (C(t+T) = N^T C(t) B)."""
    return attitude.rotvec_to_dcm(earth.earth_rate_n(SITE.lat) * T)


def carried_truth(tr, a, start, end):
    """Exact result of carrying the truth at ``a`` as if it were the attitude at ``start`` over (start, end]: the
    body's true rotation and the earth's turn over that span, composed from the trajectory's truth (no strapdown)."""
    C = tr.truth([a, start, end]).C_bn
    N = earth_turn(end - start)
    return N.T @ C[0] @ C[1].T @ N @ C[2]  # C(end) = N^T C(start) B, so B = C(start)^T N C(end)


# ---------------------------------------------------------------------------------------------- exact cases
@pytest.mark.parametrize("kind", ["increment", "rate"])
def test_perfect_static_record_windows_agree_exactly(kind):
    """coarse on a perfect stationary record is exact: every window is right and the windows agree to numerics;
    270 s in windows of 60 s: four windows, the partial fifth dropped."""
    tr = static(270.0)
    data = imu_mod.simulate(tr, imu_mod.IMUSpec(), 0.1, output=kind)
    res = consistency(data, SITE, ["coarse"], window_s=60.0)
    assert res.windows == 4 and res.samples_per_window == 600
    np.testing.assert_allclose(res.t_end, [60.0, 120.0, 180.0, 240.0], atol=1e-9)
    assert np.abs(attitude.misalignment(res.C_bn[0], tr.truth(res.t_end).C_bn)).max() < EXACT
    assert np.abs(res.disagreement).max() < EXACT
    assert np.abs(res.disagreement_euler).max() < EXACT


def test_carry_is_exact_under_sway_and_one_sample_off_is_arcminutes(record_property):
    """The carry of the truth over (a, b] lands on the truth at b; the same carry one sample late (over
    (a + dt, b + dt]) lands where the truth's own composition says, arcminutes away under a 5-6 deg/s sway."""
    tr, dt = swaying(100.0), 0.01
    data = imu_mod.simulate(tr, imu_mod.IMUSpec(), dt)
    a, b = 23.0, 71.0
    Ca, Cb = tr.truth([a, b]).C_bn
    exact = carry(Ca, data, a, b, SITE)
    assert np.abs(attitude.misalignment(exact, Cb)).max() < EXACT
    late = carry(Ca, data, a + dt, b + dt, SITE)
    d = attitude.misalignment(Cb, late)
    predicted = attitude.misalignment(Cb, carried_truth(tr, a, a + dt, b + dt))
    record_property("one_sample_late_carry_arcmin", float(np.linalg.norm(d) / units.ARCMIN))  # measured 6.2 arcmin
    assert np.linalg.norm(predicted) > 1 * units.ARCMIN
    assert np.abs(d - predicted).max() < EXACT
    # one sample short at the start: off by the attitude's change over that sample, |omega_nb| dt
    short = carry(Ca, data, a + dt, b, SITE)
    miss = np.linalg.norm(attitude.misalignment(Cb, short))
    assert miss == pytest.approx(rate_nb(a + dt / 2) * dt, rel=0.01)


class _Oracle:
    """A test's exact method: the truth of ``trajectory`` at the window's last sample, or ``lag`` samples before it
    (a method one sample late)."""

    name = "oracle"
    description = "the simulator's truth at the last sample"
    min_duration_s = 0.0
    trajectory = None
    lag = 0

    def align(self, imu, site, vref=None, init=None):
        t = imu.increments()[0][-1:]
        return AlignmentResult(self.name, t, self.trajectory.truth(t - self.lag * imu.dt).C_bn[None])


@pytest.fixture
def oracles(monkeypatch):
    """``oracle:Exact`` and ``oracle:Late`` (one sample late) on a swaying trajectory, importable by
    :func:`fusionbench.methods.aligner.load_method` as module:Class paths."""
    tr = swaying(160.0)
    mod = types.ModuleType("consistency_oracle")
    mod.Exact = type("Exact", (_Oracle,), {"name": "exact", "trajectory": tr})
    mod.Late = type("Late", (_Oracle,), {"name": "late", "trajectory": tr, "lag": 1})
    monkeypatch.setitem(sys.modules, "consistency_oracle", mod)
    return tr


def test_exact_method_under_sway_agrees_and_one_sample_late_does_not(oracles, record_property):
    """Windows of 40 s on a swaying base: the exact method's windows agree to the strapdown's accuracy, so the
    carry integrates exactly the samples between the windows' last samples; a method one sample late disagrees by
    what the truth's composition predicts (the rotation over one sample at both ends, arcminutes)."""
    tr, dt = oracles, 0.01
    data = imu_mod.simulate(tr, imu_mod.IMUSpec(), dt)
    res = consistency(data, SITE, ["consistency_oracle:Exact", "consistency_oracle:Late"], window_s=40.0)
    np.testing.assert_allclose(res.t_end, [40.0, 80.0, 120.0, 160.0], atol=1e-9)
    assert np.abs(res.disagreement[0]).max() < EXACT
    for k in range(res.windows - 1):
        a, b = res.t_end[k], res.t_end[k + 1]
        C = tr.truth([a - dt, a, b - dt, b]).C_bn
        carried = earth_turn(b - a).T @ C[0] @ C[1].T @ earth_turn(b - a) @ C[3]  # late at a, carried exactly to b
        predicted = attitude.misalignment(C[2], carried)
        assert np.linalg.norm(predicted) > 1 * units.ARCMIN
        assert np.abs(res.disagreement[1, k] - predicted).max() < EXACT
    record_property("one_sample_late_method_arcmin", float(np.abs(res.disagreement[1]).max() / units.ARCMIN))
    # the two agree to within the lag: each window's difference is the rotation over one sample
    w_nb = np.array([rate_nb(t - dt / 2) for t in res.t_end])
    assert np.linalg.norm(res.agreement[1], axis=1) == pytest.approx(w_nb * dt, rel=0.01)


# ---------------------------------------------------------------------------------------------- a constant bias
def test_constant_bias_puts_every_window_on_the_limit_and_does_not_show():
    """Constant gyro and accelerometer biases, no noise: every coarse window lands on the same theoretical limit
    (azimuth off by the east gyro bias over the horizontal earth rate: 13.7 arcmin for 0.05 deg/h at 34 N) and the
    windows agree although each is wrong. Consistency cannot see a constant bias; the limits (and a twin) can.
    What shows is the carry's drift from the north and up gyro biases, d = -phi' T with the error model
    phi' = -omega_ie^n x phi - eps^n at the limit: d = [0, (wU phiE + epsN) T, (epsU - wN phiE) T]."""
    eps = np.array([0.05, 0.02, 0.03]) * units.DEG_PER_H  # body RFU = ENU: level, facing north
    nab = np.array([30.0, -20.0, 50.0]) * units.UG
    spec = imu_mod.IMUSpec(gyro=imu_mod.SensorErrors(bias=tuple(eps)), accel=imu_mod.SensorErrors(bias=tuple(nab)))
    T = 60.0
    tr = static(4 * T, mean=(0.0, 0.0, 0.0))
    data = imu_mod.simulate(tr, spec, 0.1)
    res = consistency(data, SITE, ["coarse"], window_s=T)
    limit = metrics.theoretical_limits(eps, nab, np.eye(3), SITE.lat, SITE.h)
    az = -eps[0] / (earth.OMEGA_IE * np.cos(SITE.lat)) + np.tan(SITE.lat) * nab[0] / SITE.g  # east bias over wN
    assert limit[2] == pytest.approx(az, rel=1e-9) and abs(az) > 13 * units.ARCMIN
    phi = attitude.misalignment(res.C_bn[0], tr.truth(res.t_end).C_bn)
    np.testing.assert_allclose(phi, np.broadcast_to(limit, phi.shape), atol=np.abs(limit).max() ** 2)  # 2nd order
    # exact: window k's own attitude turned by the earth and by the measured (biased) body rate over T
    w_meas = earth.earth_rate_n(SITE.lat) + eps  # body = ENU
    for k in range(res.windows - 1):
        carried = earth_turn(T).T @ res.C_bn[0, k] @ attitude.rotvec_to_dcm(w_meas * T)
        np.testing.assert_allclose(res.disagreement[0, k], attitude.misalignment(res.C_bn[0, k + 1], carried),
                                   atol=EXACT)
    wN, wU = earth.earth_rate_n(SITE.lat)[1:]
    first_order = np.array([0.0, (wU * limit[0] + eps[1]) * T, (eps[2] - wN * limit[0]) * T])
    np.testing.assert_allclose(res.disagreement[0], np.broadcast_to(first_order, (3, 3)), atol=1e-3 * units.ARCMIN)
    assert np.abs(res.disagreement[0, :, 2]).max() < 0.01 * abs(limit[2])  # 13.7 arcmin off, 0.03 arcmin apart


# ---------------------------------------------------------------------------------------------- white noise
def _rms_limits(nu, p=1e-3):
    """Two-sided limits of (RMS estimate / true sigma) with ``nu`` degrees of freedom at level ``p``."""
    return np.sqrt(chi2.ppf(p / 2, nu) / nu), np.sqrt(chi2.ppf(1 - p / 2, nu) / nu)


def test_white_noise_spread_is_sqrt2_times_the_bound(record_property):
    """White noise only (ARW 0.005 deg/sqrt(h), VRW 6 ug/sqrt(Hz): seed 000's), 40 windows of 60 s of a static
    record: coarse's window-to-window RMS matches the expected disagreement at the attainable bound (about sqrt(2)
    x the bound, plus the carry's own gyro noise), and coarse's own theory (mean gyro and accelerometer noise over
    a window), within chi-square limits (0.1 %, two-sided) for the number of pairs.

    Degrees of freedom: consecutive azimuth disagreements share a window (correlation -1/2), so their mean square
    has nu = 4 (K-1)^2 / (4 (K-1) + 2 (K-2)) (Satterthwaite); the level ones are dominated by the carry's
    independent noise, nu = K - 1. Coarse uses the stationarity the bound's filter does not know, so it sits at
    or below the bound (0.93 of it in azimuth at 60 s): inside the limits."""
    q_g, q_a = 0.005 * units.DEG_PER_SQRT_H, 6.0 * units.UG_PER_SQRT_HZ
    spec = imu_mod.IMUSpec(gyro=imu_mod.SensorErrors(white=(q_g,) * 3), accel=imu_mod.SensorErrors(white=(q_a,) * 3),
                           name="white")
    T, K = 60.0, 40
    data = imu_mod.simulate(static(K * T, mean=(0.0, 0.0, 0.0)), spec, 0.1, seed=0)
    res = consistency(data, SITE, ["coarse"], window_s=T, imu_model=spec)
    rms = res.summary("coarse")["disagreement_rms"]
    assert res.expected[2] == pytest.approx(np.sqrt(2) * res.bound[2], rel=1e-3)  # the azimuth: sqrt(2) x bound
    # coarse's own: level q_a / (g sqrt T), azimuth q_g / (wN sqrt T); then the same propagation over the carry
    wN = earth.earth_rate_n(SITE.lat)[1]
    P = np.diag(np.square([q_a / (SITE.g * np.sqrt(T)), q_a / (SITE.g * np.sqrt(T)), q_g / (wN * np.sqrt(T))]))
    Nt = earth_turn(T).T
    own = np.sqrt(np.diag(Nt @ P @ Nt.T + P + q_g ** 2 * T * np.eye(3)))
    nu = np.array([K - 1, K - 1, 4 * (K - 1) ** 2 / (4 * (K - 1) + 2 * (K - 2))])
    lo, hi = _rms_limits(nu)
    for name, ref in (("bound", res.expected), ("coarse_theory", own)):
        ratio = rms / ref
        record_property(f"rms_over_{name}", [round(float(r), 3) for r in ratio])
        assert np.all((lo < ratio) & (ratio < hi)), (name, ratio, lo, hi)
    record_property("expected_arcmin", [round(float(x), 4) for x in res.expected / units.ARCMIN])
    record_property("rms_arcmin", [round(float(x), 4) for x in rms / units.ARCMIN])


# ---------------------------------------------------------------------------------------------- input and report
@pytest.fixture(scope="module")
def record():
    return imu_mod.simulate(static(100.0), imu_mod.IMUSpec(), 0.1)


@pytest.mark.parametrize("window, match", [
    (60.0, r"at least two windows of 60 s in the record, found a record of 100 s \(windows of at most 50 s\)"),
    (0.0, "expected a positive length in s, found 0.0"),
    (-5.0, "expected a positive length in s, found -5.0"),
    (float("nan"), "expected a positive length in s, found nan"),
    ("long", "expected a positive length in s, found 'long'"),
    (0.1, "expected at least two samples of 0.1 s, found 0.1 s"),
])
def test_bad_window_is_one_clear_error(record, window, match):
    with pytest.raises(ValueError, match=match) as err:
        consistency(record, SITE, ["coarse"], window_s=window)
    assert "\n" not in str(err.value)


def test_bad_record_or_methods_are_one_clear_error(record):
    two = IMUData(record.t, np.concatenate([record.gyro] * 2), np.concatenate([record.accel] * 2))
    for args, match in (((two, SITE, ["coarse"]), "expected one recording, found 2"),
                        ((record, SITE, []), "expected at least one method name, found none"),
                        ((record, SITE, ["coarse", "coarse"]), "expected each method once"),
                        ((record, SITE, ["no-such-method"]), "method 'no-such-method': expected one of")):
        with pytest.raises(ValueError, match=match):
            consistency(*args, window_s=50.0)
    with pytest.raises(ValueError, match="every method refused every window: kf: duration: expected at least 70 s"):
        consistency(record, SITE, ["kf"], window_s=50.0)


def test_report_and_summary(record, tmp_path):
    """A method that refuses every window is reported, not fatal; the JSON is strict (no NaN) and the figure is
    written."""
    res = consistency(record, SITE, ["coarse", "coarse-i0", "kf"], window_s=50.0, imu_model="navigation")
    assert res.refused[2] == ["kf: duration: expected at least 70 s of data, found 50 s"] * 2
    lines = summary_lines(res)
    assert len(lines) == 2 + 3 and lines[0].startswith("2 windows of 50 s")
    assert lines[-1].split() == ["kf", "refused", "every", "window:", "kf:", "duration:", "expected", "at", "least",
                                 "70", "s", "of", "data,", "found", "50", "s"]
    assert "x expected" in lines[2] and "against the others" in lines[2]
    paths = write_consistency_report(res, tmp_path / "out")
    assert sorted(p.name for p in paths) == ["consistency.json", "consistency.png"]
    assert (tmp_path / "out" / "consistency.png").stat().st_size > 10000
    text = (tmp_path / "out" / "consistency.json").read_text()
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    assert doc == json.loads(json.dumps(to_json(res)))
    assert doc["window_s"] == 50.0 and doc["t_end_s"] == pytest.approx([50.0, 100.0])
    kf = doc["methods"]["kf"]
    assert kf["windows_aligned"] == 0 and kf["attitude_deg"]["yaw"] == [None, None]
    assert kf["disagreement_arcmin"]["U"] == [None] and kf["summary"]["disagreement_arcmin"]["rms"]["U"] is None
    coarse = doc["methods"]["coarse"]
    assert coarse["attitude_deg"]["yaw"] == pytest.approx([123.0] * 2, abs=1e-6)
    assert abs(coarse["disagreement_arcmin"]["U"][0]) < 1e-4
    assert set(doc["bound"]) == {"bound_arcmin", "expected_disagreement_arcmin"}


def _snapshot(folder):
    from pathlib import Path

    return {p.relative_to(folder).as_posix(): None if p.is_dir() else p.read_bytes()
            for p in sorted(Path(folder).rglob("*"))}


def test_the_report_folder_is_replaced_whole_or_left_as_it_was(record, tmp_path, monkeypatch):
    """A figure that fails half-written leaves the previous output exactly as it was; a new one replaces it."""
    from fusionbench.reports import figures

    res = consistency(record, SITE, ["coarse"], window_s=50.0)
    out = tmp_path / "out"
    write_consistency_report(res, out)
    before = _snapshot(out)
    assert set(before) == {"consistency.json", "consistency.png"}

    def half_then_fail(fig, path):
        with open(path, "wb") as fh:
            fh.write(b"half a figure")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(figures, "save_png", half_then_fail)
    with pytest.raises(OSError, match="No space left"):
        write_consistency_report(res, out, aiding={"file": "new"})
    assert _snapshot(out) == before and [p.name for p in tmp_path.iterdir()] == ["out"]  # nothing hidden left
    monkeypatch.undo()
    two = consistency(record, SITE, ["coarse", "coarse-i0"], window_s=50.0)
    write_consistency_report(two, out)
    assert set(json.loads((out / "consistency.json").read_text())["methods"]) == {"coarse", "coarse-i0"}
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


@pytest.mark.parametrize("files", [
    {"notes.txt": "mine"},
    {"consistency.json": '{"kind": "consistency"}', "notes.txt": "mine"},  # an output, and a file of mine
    {"consistency.json": '{"kind": "identify"}'},
    {"identify.json": '{"record": {}, "method": {}, "spec": {}}'},  # the other command's
    {"metrics.json": '{"scenario": "s", "methods": {}}'},  # a run's report
])
def test_a_folder_of_other_files_is_refused_and_untouched(record, tmp_path, files):
    res = consistency(record, SITE, ["coarse"], window_s=50.0)
    out = tmp_path / "mine"
    out.mkdir()
    for name, text in files.items():
        (out / name).write_text(text)
    before = _snapshot(out)
    with pytest.raises(ValueError) as err:
        write_consistency_report(res, out)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{out}: ") and "previous fusionbench consistency output" in msg
    assert "found other files" in msg
    assert _snapshot(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["mine"]
