"""``align``'s answer with its uncertainty and its claim (issue 24): the method's predicted sigma, the limit of the
IMU's fixed biases and, when the record or the IMU lies outside what the method claims, the reason and a warning
(fusionbench.bench.claim_check). The figures asserted are computed here from the spec, the earth's constants and the
method's own result."""

import json

import numpy as np
import pytest
from scipy.stats import chi2

from fusionbench.bench.claim_check import SWAY_RATIO, base_kind, outside_claim, rate_scatter
from fusionbench.cli import main
from fusionbench.files.imufiles import read_imu, write_csv, write_psins
from fusionbench.methods.aligner import Site, load_method
from fusionbench.methods.claims import Supports
from fusionbench.simulation import earth, trajectory as tj, units
from fusionbench.simulation.aiding import Aiding
from fusionbench.simulation.drive import car_drive
from fusionbench.simulation.imu import PRESETS, simulate
from fusionbench.simulation.imudata import IMUData

D = np.pi / 180
LAT, LON, H = 47.0 * D, 8.0 * D, 400.0
MEAN = (1.5 * D, -3.0 * D, -250.0 * D)
OMEGA = 7.292115e-5  # the earth's rate, rad/s (WGS-84)
SITE = ("--lat", 47, "--lon", 8, "--height", 400)


def fb(capsys, *args):
    """``fusionbench ARGS`` in this process: (exit status, stdout, stderr)."""
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def static_csv(tmp_path_factory):
    """150 s of a static base at 47 N, 50 Hz, navigation grade with its noise (seed 1), as the contract CSV."""
    tr = tj.Trajectory(LAT, LON, H, tj.EulerSway(mean=MEAN), duration=150.0)
    return write_csv(tmp_path_factory.mktemp("static") / "static.csv", simulate(tr, PRESETS["navigation"], 0.02, seed=1))


@pytest.fixture(scope="module")
def sway_imu(tmp_path_factory):
    """120 s of a mild sway (0.5, 0.8, 0.3 deg at 0.2, 0.12, 0.05 Hz) at 47 N, navigation grade, as a PSINS .imu."""
    tr = tj.Trajectory(LAT, LON, H, tj.EulerSway(mean=MEAN, amplitude=(0.5 * D, 0.8 * D, 0.3 * D),
                                                 frequency=(0.2, 0.12, 0.05)), duration=120.0)
    return write_psins(tmp_path_factory.mktemp("sway") / "sway.imu", simulate(tr, PRESETS["navigation"], 0.02, seed=2),
                       (0.0, 0.0, 0.0), lat=LAT, lon=LON, h=H)


def test_eso_td_told_a_gyro_beyond_its_claim_answers_with_the_reason_and_one_warning_line(capsys, static_csv, tmp_path):
    # the tactical preset with 2 deg/h of fixed gyro bias: beyond the 0.15 of the horizontal earth rate eso-td claims
    # on a fixed base, short of the 0.5 at which every method refuses
    spec = tmp_path / "fog-2dph.toml"
    spec.write_text('[imu]\npreset = "tactical"\ngyro_bias_dph = [2.0, 2.0, 2.0]\n')
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--method", "eso-td", "--imu", str(spec), "--json")
    assert status == 0, err
    res = json.loads(out)
    # 2 deg/h fixed, 0.5 deg/h drifting, against the horizontal earth rate at 47 deg
    bias = np.hypot(2.0, 0.5) * D / 3600.0
    ratio = bias / (OMEGA * np.cos(LAT))
    assert ratio == pytest.approx(0.201, abs=0.001)
    reason = res["outside_claim"]
    assert "gyro bias of IMU 'fog-2dph'" in reason and f"{ratio:.3g} of the horizontal earth rate" in reason
    assert "beyond the 0.15 it claims" in reason and "latitude" not in reason and "base" not in reason
    assert err == f"fusionbench: warning: eso-td: outside its claim: {reason}\n"
    assert res["base"] == "static" and res["limit_note"] is None
    # the existing keys are kept as they were
    assert {"method", "t_end", "C_bn", "pitch_deg", "roll_deg", "yaw_deg", "heading_deg"} <= set(res)
    # the plain output says it too
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--method", "eso-td", "--imu", str(spec))
    assert status == 0 and err == f"fusionbench: warning: eso-td: outside its claim: {reason}\n"
    assert f"outside the method's claim: {reason}" in out
    # the tactical preset itself (0.109 of the earth rate here) is claimed on a fixed base: no warning
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--method", "eso-td", "--imu", "tactical")
    assert status == 0 and err == "" and "outside" not in out
    # kf claims it on a fixed base (up to 0.15 of the earth rate): no warning, its predicted sigma; pid too (its
    # compass loop's level pair keeps a tactical gyro's noise out of the levels: docs/methods/pid.md)
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--method", "kf", "--imu", "tactical")
    assert status == 0 and err == "" and "outside" not in out and "predicted sigma E " in out
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--method", "pid", "--imu", "tactical")
    assert status == 0 and err == "" and "outside" not in out


def test_kf_told_a_navigation_imu_gives_its_sigma_and_the_fixed_bias_limit_without_a_warning(capsys, static_csv):
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--method", "kf", "--imu", "navigation", "--json")
    assert status == 0 and err == "", err
    res = json.loads(out)
    assert res["outside_claim"] is None and res["base"] == "static" and res["limit_note"] is None
    # the sigma: the method's own, at the last sample, from the same record aligned here
    imu, _ = read_imu(static_csv)
    own = load_method("kf", imu="navigation").align(imu, Site(LAT, LON, H))
    want = own.sigma_phi[0, -1] / units.ARCMIN
    assert [res["sigma_arcmin"][k] for k in "ENU"] == pytest.approx(want, rel=1e-9)
    assert 0.01 < want[0] < 1.0 and want[2] > 1.0  # level to a fraction of an arcmin, azimuth to arcmin
    # the limit: the closed form with the preset's fixed biases resolved at the answer's attitude
    C = np.array(res["C_bn"])
    eps = C @ np.full(3, 0.005 * D / 3600.0)
    nab = C @ np.full(3, 25e-6 * units.G0)
    g = earth.gravity(LAT, H)
    limit = np.array([-nab[1] / g, nab[0] / g, -eps[0] / (OMEGA * np.cos(LAT)) + np.tan(LAT) * nab[0] / g])
    assert [res["limit_arcmin"][k] for k in "ENU"] == pytest.approx(limit / units.ARCMIN, rel=1e-6)
    # the plain output prints the same figures
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--method", "kf", "--imu", "navigation")
    assert status == 0 and err == "" and "inside the method's claim" in out
    assert f"E {res['limit_arcmin']['E']:.3g}, N {res['limit_arcmin']['N']:.3g}" in out


def test_without_imu_there_is_no_limit_and_coarse_has_no_sigma(capsys, static_csv):
    status, out, err = fb(capsys, "align", static_csv, *SITE, "--json")
    assert status == 0 and err == ""
    res = json.loads(out)
    assert res["sigma_arcmin"] is None and res["limit_arcmin"] is None and "--imu" in res["limit_note"]
    assert res["outside_claim"] is None and res["base"] == "static"


def test_coarse_on_a_swaying_record_is_outside_its_claim_and_coarse_i0_is_not(capsys, sway_imu):
    status, out, err = fb(capsys, "align", sway_imu, "--json")
    assert status == 0, err
    res = json.loads(out)
    assert res["base"] == "sway"
    assert res["outside_claim"] == "a swaying base, which it does not claim (it claims static)"
    assert err == "fusionbench: warning: coarse: outside its claim: a swaying base, which it does not claim (it " \
                  "claims static)\n"
    status, out, err = fb(capsys, "align", sway_imu, "--method", "coarse-i0", "--json")
    assert status == 0 and err == "" and json.loads(out)["outside_claim"] is None


def test_a_latitude_beyond_the_claim(capsys, tmp_path):
    """coarse claims 80 deg and aligns up to 89: at 85 it answers, with the reason."""
    tr = tj.Trajectory(85 * D, 0.0, 0.0, tj.EulerSway(mean=MEAN), duration=60.0)
    path = write_csv(tmp_path / "north.csv", simulate(tr, PRESETS["navigation"], 0.02, seed=3))
    status, out, err = fb(capsys, "align", path, "--lat", 85, "--json")
    assert status == 0, err
    res = json.loads(out)
    assert res["outside_claim"] == "latitude 85 deg, beyond the 80 deg it claims"
    assert err.count("\n") == 1 and "coarse: outside its claim: latitude 85 deg" in err
    # and a refusal stays a refusal: adrc-paper aligns only up to 80 deg
    status, out, err = fb(capsys, "align", path, "--lat", 85, "--method", "adrc-paper", "--json")
    assert status == 2 and out == "" and "warning" not in err


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """A car's drive with turns at 47 N, 150 s at 50 Hz, navigation grade, and its receiver's velocity rows at 1 and
    0.5 Hz (0.02 m/s), as aiding CSVs (fusionbench.files.aidingfiles.write_csv)."""
    from fusionbench.files.aidingfiles import write_csv as write_aiding
    from fusionbench.simulation.aidingsim import AidingSpec, simulate_aiding

    folder = tmp_path_factory.mktemp("drive")
    tr = car_drive(LAT, LON, H, heading=1.0, duration=150.0)
    imu = simulate(tr, PRESETS["navigation"], 0.02, seed=1, output="rate")
    files = {hz: write_aiding(folder / f"rows_{hz:g}hz.csv",
                              simulate_aiding(tr, AidingSpec(rate_hz=hz, velocity_sigma=(0.02,) * 3), seed=1))
             for hz in (1.0, 0.5)}
    return write_csv(folder / "drive.csv", imu), files


def test_aiding_slower_than_the_claim(capsys, drive):
    imu_csv, rows = drive
    args = ("align", imu_csv, *SITE, "--method", "coarse-i0", "--json", "--aiding")
    status, out, err = fb(capsys, *args, rows[1.0])
    assert status == 0 and err == "", err
    res = json.loads(out)
    assert res["outside_claim"] is None and res["base"] == "moving"
    status, out, err = fb(capsys, *args, rows[0.5], "--imu", "navigation")
    assert status == 0, err
    res = json.loads(out)
    assert res["outside_claim"] == "aiding rows at 0.5 Hz, below the 1 Hz it claims"
    assert err == "fusionbench: warning: coarse-i0: outside its claim: aiding rows at 0.5 Hz, below the 1 Hz it claims\n"
    # in motion the static limit does not hold: null, and why
    assert res["limit_arcmin"] is None and "moving base" in res["limit_note"]


# ------------------------------------------------------------------------------------- the check from Python
class Claimed:
    """A method with the given claims."""

    def __init__(self, **claims):
        self.supports = Supports(**claims)


def _static(spec="navigation", duration=60.0, dt=0.02, seed=0, lat=LAT):
    tr = tj.Trajectory(lat, 0.0, 0.0, tj.EulerSway(mean=MEAN), duration=duration)
    return simulate(tr, PRESETS[spec], dt, seed=seed)


def _moving_rows(rate_hz, duration=60.0, gap=None):
    """Velocity rows of a base moving east at 5 m/s, at ``rate_hz``, with the rows valid in ``gap`` (s) left out."""
    t = np.arange(1, int(duration * rate_hz) + 1) / rate_hz
    if gap is not None:
        t = t[(t < gap[0]) | (t >= gap[1])]
    return Aiding(t, velocity=np.tile([5.0, 0.0, 0.0], (t.size, 1)))


def test_outside_claim_names_each_rule():
    imu = _static()
    site = Site(LAT)
    nav, tac = PRESETS["navigation"], PRESETS["tactical"]
    assert outside_claim(Claimed(), imu, site) is None
    assert outside_claim(Claimed(), imu, site, spec=tac) is None  # the default claim: up to 0.5 of the earth rate
    kf = load_method("kf")
    assert outside_claim(kf, imu, site, spec=nav) is None
    assert outside_claim(kf, imu, site, spec=tac) is None  # claims 0.15 of the earth rate at rest ...
    assert outside_claim(kf, imu, site, aiding=_moving_rows(2.0), spec=tac) == (
        "the gyro bias of IMU 'tactical' (1.12 deg/h) is 0.109 of the horizontal earth rate at the site, beyond the "
        "0.05 it claims on a moving base")  # ... and 0.05 in motion
    # navigation grade against a claim of 0.001: its 0.0054 deg/h is 0.00053 of 10.26 deg/h
    ratio = np.sqrt(0.005**2 + 0.002**2) / (OMEGA * np.cos(LAT) * 3600 / D)
    why = outside_claim(Claimed(max_bias_ratio=0.0005), imu, site, spec=nav)
    assert why.endswith(f"is {ratio:.3g} of the horizontal earth rate at the site, beyond the 0.0005 it claims")
    # moving: the kinds, the rate, the outage (the gap beyond one interval), the bias claimed in motion
    coarse_i0 = load_method("coarse-i0")
    assert outside_claim(coarse_i0, imu, site, aiding=_moving_rows(2.0), spec=nav) is None
    assert outside_claim(coarse_i0, imu, site, spec=tac) is None  # claims 0.5 of the earth rate at rest ...
    assert outside_claim(coarse_i0, imu, site, aiding=_moving_rows(2.0), spec=tac).endswith(
        "beyond the 0.05 it claims on a moving base")  # ... and 0.05 in motion
    wide = Claimed(bases=("moving",), max_outage_s=20.0, min_aiding_hz=1.0, aiding=("position",))
    why = outside_claim(wide, imu, site, aiding=_moving_rows(0.5, gap=(10.0, 40.0)))
    assert why == ("aiding of velocity rows, which it does not claim (it claims position); aiding rows at 0.5 Hz, "
                   "below the 1 Hz it claims; an aiding outage of 30 s, beyond the 20 s it claims")
    assert outside_claim(Claimed(bases=("moving",), max_outage_s=30.0), imu, site,
                         aiding=_moving_rows(0.5, gap=(10.0, 40.0))) is None
    assert outside_claim(Claimed(bases=("static", "sway")), imu, site, aiding=_moving_rows(1.0)) == \
        "a moving base, which it does not claim (it claims static, sway)"
    # no condition claimed: a paper's printed parameters, a navigator
    assert outside_claim(load_method("adrc-paper"), imu, site) == \
        "it claims no condition: its parameters are kept to reproduce a paper"
    assert outside_claim(Claimed(bases=(), needs_init=True), imu, site).startswith("it claims no condition: a navigator")
    # at 85 deg kf (claims 89) is outside by its gyro alone; pid (claims 80) by latitude and gyro, "; "-separated
    north = _static(lat=85 * D, duration=30.0)
    ratio = np.hypot(1.0, 0.5) / (OMEGA * np.cos(85 * D) * 3600 / D)
    assert outside_claim(kf, north, Site(85 * D), spec=tac) == (
        f"the gyro bias of IMU 'tactical' (1.12 deg/h) is {ratio:.3g} of the horizontal earth rate at the site, beyond "
        f"the 0.15 it claims")
    pid = load_method("pid")
    assert outside_claim(pid, north, Site(85 * D), spec=tac).startswith("latitude 85 deg, beyond the 80 deg it claims; "
                                                                        "the gyro bias of IMU 'tactical'")


def test_rate_scatter_of_white_noise_and_of_a_sinusoid():
    """White noise of sigma per sample: the noise share of the 1-s block means is sigma^2 / n and their variance
    scatters about it (chi-square); a sinusoidal rate of amplitude A at f adds A^2 / 2 times the block average's
    gain sinc(f T)^2."""
    rng = np.random.default_rng(7)
    dt, n_s, sigma = 0.01, 30000, 1e-3                     # 300 s at 100 Hz, 1 mrad/s per sample
    t = dt * np.arange(1, n_s + 1)
    w = np.array([1e-5, 2e-5, 3e-5]) + sigma * rng.standard_normal((1, n_s, 3))
    f = np.tile([0.0, 0.0, 9.81], (1, n_s, 1))
    scatter, noise = rate_scatter(IMUData(t, w, f, "rate"))
    assert noise[0] == pytest.approx(np.full(3, sigma**2 / 100), rel=0.03)
    B = 300
    lo, hi = (chi2.ppf(q, B - 1) / (B - 1) for q in (1e-4, 1 - 1e-4))
    assert np.all((lo < scatter[0] / noise[0]) & (scatter[0] / noise[0] < hi)), scatter / noise
    amp, fr = 1e-3, 0.1
    w2 = w + amp * np.sin(2 * np.pi * fr * t)[None, :, None]
    scatter2, noise2 = rate_scatter(IMUData(t, w2, f, "rate"))
    want = amp**2 / 2 * np.sinc(fr * 1.0) ** 2 + sigma**2 / 100
    assert scatter2[0] == pytest.approx(np.full(3, want), rel=0.1)
    assert noise2[0] == pytest.approx(np.full(3, sigma**2 / 100), rel=0.05)  # the straight lines keep the sine out
    assert np.all(scatter2[0] / noise2[0] > 10 * SWAY_RATIO)  # 1 + 50 sinc(0.1)^2 = 49.4
    assert base_kind(IMUData(t, w, f, "rate")) == "static" and base_kind(IMUData(t, w2, f, "rate")) == "sway"


@pytest.mark.parametrize("spec", ["navigation", "tactical", "mems"])
def test_a_static_record_of_each_grade_is_static_and_a_tenth_of_a_degree_sway_is_not(spec):
    assert base_kind(_static(spec, duration=300.0, seed=4)) == "static"
    tr = tj.Trajectory(LAT, 0.0, 0.0, tj.EulerSway(mean=MEAN, amplitude=(0.1 * D,) * 3, frequency=(0.2, 0.12, 0.05)),
                       duration=300.0)
    assert base_kind(simulate(tr, PRESETS[spec], 0.02, seed=4)) == "sway"
    # a record without noise: no share to compare with, and no scatter
    assert base_kind(simulate(tj.Trajectory(LAT, 0.0, 0.0, tj.EulerSway(mean=MEAN), duration=60.0),
                              PRESETS[spec].noise_free(), 0.01)) == "static"
