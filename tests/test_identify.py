"""fusionbench identify: the Allan deviation of a static record, the IEEE-952 terms fitted to it, the spec and the report.

Records are simulated with known terms (``tests/identify_helpers.py``): white noise, random walks and quantisation on a
static base, and bias instability as true flicker noise, whose generator the first test checks against the Allan
variance (2 ln2 / pi) B^2 of the definition. What identify does to its output folder: ``tests/test_identify_output.py``.

Tolerances come from the record, not from trial: for each true term, the relative standard deviation of that term
solved exactly from the best choice of as many octave taus as there are true terms, each Allan variance estimate
chi-square with Greenhall's equivalent degrees of freedom (allantools) and taken as independent; times a z that
holds the probability of any of the file's value checks failing by chance below 0.1 %.
"""

import itertools
import json
import math
from pathlib import Path

import allantools
import numpy as np
import pytest
from scipy import integrate, optimize
from scipy.stats import norm

from fusionbench.recording import allanfit, identify
from fusionbench.simulation import imu, imudata, units
from tests.identify_helpers import ACCEL_N, DT, GYRO_N, _flicker_psd, _record

#: Value checks of the file: 3 records x 2 sensors x 3 axes x 2 terms.
CHECKS = 36
#: Two-sided z of a 0.1 % chance that any of the checks fails.
Z = norm.isf(0.001 / (2 * CHECKS))
#: Allan variance of bias instability B, per B^2 (IEEE 952).
FLICKER = 2 * math.log(2) / math.pi
ALPHA = {"Q": 2, "N": 0, "B": -1, "K": -2, "R": -2}


# ------------------------------------------------------------------------------------- records with known terms


def _tolerance(true, n, dt=DT):
    """Relative tolerance of each true term (see the module docstring)."""
    names = [t for t in "QNBKR" if true.get(t, 0) > 0]
    m = 2 ** np.arange(int(np.log2(n // 4)) + 1)
    tau = m * dt
    cols = {"Q": 3 / tau ** 2, "N": 1 / tau, "B": np.full(tau.size, FLICKER), "K": tau / 3, "R": tau ** 2 / 2}
    A = np.column_stack([cols[t] for t in names])
    c = np.array([true[t] ** 2 for t in names])
    dominant = [names[i] for i in np.argmax(A * c, axis=1)]
    edf = np.array([allantools.edf_greenhall(ALPHA[d], 2, int(k), n + 1, overlapping=True) for d, k in zip(dominant, m)])
    var = 2 * (A @ c) ** 2 / edf
    best = dict.fromkeys(names, np.inf)
    for rows in map(list, itertools.combinations(range(tau.size), len(names))):
        S = A[rows]
        if abs(np.linalg.det(S / np.linalg.norm(S, axis=0))) < 1e-9:
            continue
        cov = np.linalg.inv(S) @ np.diag(var[rows]) @ np.linalg.inv(S).T
        for i, t in enumerate(names):
            best[t] = min(best[t], math.sqrt(cov[i, i]) / (2 * c[i]))  # sd(X) / X = sd(X^2) / (2 X^2)
    return {t: Z * v for t, v in best.items()}


#: Three hours of bias instability over white noise.
NB = dict(n=108000, gyro={"N": GYRO_N, "B": 5 * units.DEG_PER_H}, accel={"N": ACCEL_N, "B": 50 * units.UG})
#: Three hours of rate random walk over white noise (crossing near 10 s).
NK = dict(n=108000, gyro={"N": GYRO_N, "K": 150 * units.DEG_PER_H_SQRT_H},
          accel={"N": ACCEL_N, "K": 10 * units.UG_PER_SQRT_S})
#: One hour of quantised white noise: quanta 8 arcsec and 2e-4 m/s, 1.4 and 1.3 times the noise of one sample (the
#: rounding error is then white), so Q = quantum / sqrt(12).
GYRO_QUANTUM, ACCEL_QUANTUM = 8 * units.ARCSEC, 2e-4
NQ = dict(n=36000, gyro={"N": GYRO_N, "Q": GYRO_QUANTUM / math.sqrt(12)},
          accel={"N": ACCEL_N, "Q": ACCEL_QUANTUM / math.sqrt(12)})


@pytest.fixture(scope="module")
def nb():
    rec = _record(NB["n"], {"white": (GYRO_N,) * 3}, {"white": (ACCEL_N,) * 3}, 1, NB["gyro"]["B"], NB["accel"]["B"])
    return identify.identify(rec, name="nb-test", source="nb.npz")


@pytest.fixture(scope="module")
def nk():
    rec = _record(NK["n"], {"white": (GYRO_N,) * 3, "random_walk": (NK["gyro"]["K"],) * 3},
                  {"white": (ACCEL_N,) * 3, "random_walk": (NK["accel"]["K"],) * 3}, 2)
    return identify.identify(rec)


@pytest.fixture(scope="module")
def nq():
    rec = _record(NQ["n"], {"white": (GYRO_N,) * 3, "quantum": GYRO_QUANTUM},
                  {"white": (ACCEL_N,) * 3, "quantum": ACCEL_QUANTUM}, 3)
    return identify.identify(rec)


#: The datasheet unit of each term, as this file spells it (the conversion the report must make).
DATASHEET = {"gyro": {"Q": units.ARCSEC, "N": units.DEG_PER_SQRT_H, "B": units.DEG_PER_H, "K": units.DEG_PER_H_SQRT_H},
             "accel": {"Q": 1.0, "N": units.UG_PER_SQRT_HZ, "B": units.UG, "K": units.UG_PER_SQRT_S}}


def _check_terms(ident, case):
    assert ident.poor_fits() == []  # the terms describe every axis of a record made of them
    for sensor in ("gyro", "accel"):
        truth = case[sensor]
        tol = _tolerance(truth, case["n"])
        for j in range(3):
            for t in allanfit.TERMS:
                term = ident.term(sensor, j, t)
                if t not in truth:
                    assert not term.present, f"{sensor} {'xyz'[j]}: {t} = {term.datasheet:.4g} {term.unit} found"
                    continue
                assert term.present, f"{sensor} {'xyz'[j]}: {t} missed"
                assert term.value / truth[t] - 1 == pytest.approx(0, abs=tol[t]), f"{sensor} {'xyz'[j]} {t} (SI)"
                assert term.datasheet / (truth[t] / DATASHEET[sensor][t]) - 1 == pytest.approx(0, abs=tol[t]), \
                    f"{sensor} {'xyz'[j]} {t} ({term.unit})"


# ------------------------------------------------------------------------------------------- the generator


def test_the_flicker_generator_has_the_ieee_allan_variance():
    # the expected overlapping Allan variance of the generated samples, from their spectrum and the Allan filter
    # |H(f)|^2 = 4 dt^2 sin^4(pi f tau) / sin^2(pi f dt) on the generator's frequencies, is (2 ln2 / pi) B^2
    n, b = NB["n"], 1.0
    f = np.fft.rfftfreq(8 * n, DT)[1:]
    s2 = _flicker_psd(f, DT, b)
    weight = np.where(np.arange(f.size) == f.size - 1, 1.0, 2.0) / (8 * n * DT)  # both signs, Nyquist once
    for m in 2 ** np.arange(int(np.log2(n // 4)) + 1):
        tau = m * DT
        gain = 4 * DT ** 2 * np.sin(np.pi * f * tau) ** 4 / np.sin(np.pi * f * DT) ** 2
        assert np.sum(s2 * gain * weight) / (2 * tau ** 2) == pytest.approx(FLICKER * b ** 2, rel=2e-3), m


# ------------------------------------------------------------------------------------------- identification


def test_white_noise_and_bias_instability(nb):
    _check_terms(nb, NB)


def test_white_noise_and_rate_random_walk(nk):
    _check_terms(nk, NK)


def test_quantisation(nq):
    _check_terms(nq, NQ)
    tol = {s: _tolerance(NQ[s], NQ["n"])["Q"] for s in ("gyro", "accel")}
    spec = nq.to_spec()  # the quantum per count is sqrt(12) Q
    assert spec.gyro.quantum / GYRO_QUANTUM - 1 == pytest.approx(0, abs=tol["gyro"])
    assert spec.accel.quantum / ACCEL_QUANTUM - 1 == pytest.approx(0, abs=tol["accel"])


def test_a_rate_record_gives_what_its_increment_record_gives():
    kw = dict(gyro={"white": (GYRO_N,) * 3, "random_walk": (NK["gyro"]["K"],) * 3},
              accel={"white": (ACCEL_N,) * 3, "quantum": ACCEL_QUANTUM}, seed=4)
    inc = identify.identify(_record(6000, output="increment", **kw))
    rate = identify.identify(_record(6000, output="rate", **kw))
    assert (inc.kind, rate.kind) == ("increment", "rate")
    for s in ("gyro", "accel"):
        for j in range(3):
            np.testing.assert_allclose(rate.fits(s)[j].curve.adev, inc.fits(s)[j].curve.adev, rtol=1e-9)
            for t in allanfit.TERMS:
                a, b = inc.term(s, j, t), rate.term(s, j, t)
                assert a.present == b.present and b.value == pytest.approx(a.value, rel=1e-6), (s, j, t)


@pytest.mark.parametrize("n, dt, found", [(99, 0.1, "found 99 samples of 0.1 s (9.9 s, longest averaging time 1.6 s)"),
                                          (511, 0.1, "found 511 samples of 0.1 s (51.1 s, longest averaging time 6.4 s)"),
                                          (2000, 0.001, "longest averaging time 0.256 s")])
def test_a_record_too_short_is_one_clear_error(n, dt, found):
    # octaves of dt up to a quarter of the record: 10 s at 0.1 s is 128 dt, so 4 x 128 = 512 samples at least
    t = (np.arange(n) + 1) * dt
    rec = imudata.IMUData(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.8], (n, 1)), "rate")
    with pytest.raises(ValueError, match=r"expected a static record of at least 100 samples whose longest Allan "
                                         r"averaging time \(the last octave within a quarter of the record\) reaches "
                                         r"10 s") as err:
        identify.identify(rec)
    assert found in str(err.value) and "\n" not in str(err.value)


def test_the_shortest_record_is_identified():
    rec = _record(512, {"white": (GYRO_N,) * 3}, {"white": (ACCEL_N,) * 3}, 6)
    ident = identify.identify(rec)
    assert ident.fits("gyro")[0].curve.tau[-1] == pytest.approx(12.8)
    assert all(ident.term("gyro", j, "N").present for j in range(3))


def test_not_a_record_is_refused():
    with pytest.raises(ValueError, match="expected an IMUData record, found str"):
        identify.identify("imu.csv")


# ------------------------------------------------------------------------------------------- the spec


def _gm_avar_from_psd(x):
    """Allan variance at tau = x T of a unit first-order Gauss-Markov rate of correlation time T = 1 s, from its
    one-sided PSD 4 T / (1 + (2 pi f T)^2) through the Allan filter 2 sin^4(pi f tau) / (pi f tau)^2."""
    def g(f):
        return 4.0 / (1 + (2 * np.pi * f) ** 2) * 2 * np.sin(np.pi * f * x) ** 4 / (np.pi * f * x) ** 2
    edges = np.concatenate([np.arange(0.0, 200.0, 1.0 / x), [200.0]])
    return sum(integrate.quad(g, a, b, epsabs=1e-13)[0] for a, b in zip(edges[:-1], edges[1:]))


def test_the_gauss_markov_allan_peak_is_its_closed_form():
    res = optimize.minimize_scalar(lambda x: -_gm_avar_from_psd(x), bounds=(1.0, 3.0), method="bounded",
                                   options={"xatol": 1e-6})
    x_peak, adev_peak = allanfit.gm_peak()
    assert x_peak == pytest.approx(res.x, rel=1e-4)
    assert adev_peak == pytest.approx(math.sqrt(-res.fun), rel=1e-5)
    sigma, T = allanfit.gauss_markov(1e-5, 300.0)  # its peak is the flicker floor of B, at the floor's end
    assert sigma * adev_peak == pytest.approx(math.sqrt(FLICKER) * 1e-5, rel=1e-12)
    assert T * x_peak == pytest.approx(300.0, rel=1e-12)


def test_the_written_spec_loads_with_the_identified_values(nb, tmp_path):
    path = identify.write_spec_toml(nb, tmp_path / "mine.toml")
    text = path.read_text()
    assert "[imu]" in text and 'preset = "ideal"' in text and "PLACEHOLDER" in text
    spec = imu.load_spec(path)
    assert spec.name == "nb-test"
    x_peak, adev_peak = allanfit.gm_peak()
    for s in ("gyro", "accel"):
        errors = getattr(spec, s)
        n_si = [nb.term(s, j, "N").value for j in range(3)]
        b_si = [nb.term(s, j, "B").value for j in range(3)]
        np.testing.assert_allclose(errors.white, n_si, rtol=1e-5)
        np.testing.assert_allclose(errors.instability, np.sqrt(FLICKER) * np.array(b_si) / adev_peak, rtol=1e-5)
        floors = [f.tau_floor for f in nb.fits(s)]
        assert errors.tau == pytest.approx(math.exp(np.mean(np.log(floors))) / x_peak, rel=1e-5)
        np.testing.assert_allclose(errors.bias_sigma, b_si, rtol=1e-5)  # the placeholder: B
        assert errors.random_walk == (0.0,) * 3 and errors.quantum == 0.0  # not seen: not written
        assert errors.bias == (0.0,) * 3 and errors.scale == (0.0,) * 3  # not observable: the ideal preset's
        for field in ("white", "instability", "bias_sigma"):
            np.testing.assert_allclose(getattr(errors, field), getattr(getattr(nb.to_spec(), s), field), rtol=1e-5)


def test_the_ideal_preset_has_no_error():
    spec = imu.load_spec("ideal")
    for e in (spec.gyro, spec.accel):
        assert not any(e.bias + e.bias_sigma + e.white + e.instability + e.random_walk + e.scale) and e.quantum == 0


# ------------------------------------------------------------------------------------------- the report


def test_report_json_figure_and_summary(nb, tmp_path):
    lines = identify.run_identify(_record(4000, {"white": (GYRO_N,) * 3}, {"white": (ACCEL_N,) * 3}, 5), tmp_path,
                                  name="small")
    assert lines[-1].startswith("wrote ") and {p.name for p in tmp_path.iterdir()} == {"imu_spec.toml",
                                                                                      "identify.json", "allan.png"}
    json_path, png_path = identify.write_identify_report(nb, tmp_path / "nb")
    data = json.loads(json_path.read_text(), parse_constant=lambda c: pytest.fail(f"{c} in identify.json"))
    assert data["record"]["samples"] == NB["n"] and data["record"]["dt_s"] == pytest.approx(DT)
    assert data["record"]["duration_s"] == pytest.approx(NB["n"] * DT)
    n_x = data["gyro"]["axes"]["x"]["terms"]["N"]
    assert n_x["present"] and n_x["datasheet_unit"] == "deg/sqrt(h)" and n_x["si_unit"] == "rad/sqrt(s)"
    assert n_x["si"] == pytest.approx(nb.term("gyro", 0, "N").value)
    assert n_x["datasheet"] == pytest.approx(nb.term("gyro", 0, "N").value / units.DEG_PER_SQRT_H)
    assert n_x["datasheet_sigma"] > 0 and n_x["adev_slope"] == -0.5
    b_y = data["accel"]["axes"]["y"]["terms"]["B"]
    assert b_y["datasheet_unit"] == "ug" and b_y["datasheet"] == pytest.approx(nb.term("accel", 1, "B").value / units.UG)
    assert data["accel"]["axes"]["z"]["terms"]["R"] == {**data["accel"]["axes"]["z"]["terms"]["R"], "present": False,
                                                         "si": None, "datasheet": None}
    curve = data["gyro"]["axes"]["z"]
    assert len(curve["tau_s"]) == len(curve["adev"]) == len(curve["adev_lo"]) == len(curve["adev_hi"]) == 15
    assert all(lo < a < hi for lo, a, hi in zip(curve["adev_lo"], curve["adev"], curve["adev_hi"]))
    png = png_path.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20000
    summary = identify.summary(nb)
    axis_lines = [s for s in summary if s.startswith(("gyro ", "accel "))]
    assert len(axis_lines) == 6
    assert all("deg/sqrt(h)" in s and "deg/h" in s and "+-" in s for s in axis_lines[:3])
    assert all("ug/sqrt(Hz)" in s and " ug" in s for s in axis_lines[3:])
    assert any("turn-on bias" in s and "datasheet" in s for s in summary)


def test_the_page_quotes_the_gauss_markov_constants():
    text = (Path(__file__).parents[1] / "docs" / "identify.md").read_text()
    x_peak, adev_peak = allanfit.gm_peak()
    assert f"{x_peak:.4f}" in text and f"{adev_peak:.4f}" in text
    assert "identify.md" in (Path(__file__).parents[1] / "docs" / "scenarios.md").read_text()


def test_a_vibration_is_not_taken_for_sensor_noise(nb):
    """A 1-Hz vibration of 0.5 mm/s on the accelerometers of a static record puts a hump into their Allan curves
    that no sum of the IEEE-952 terms follows: the fit says so (an Allan point no fitted model produces) on exactly
    those axes, and the summary and the spec carry the warning."""
    n = 36000
    rec = _record(n, {"white": (GYRO_N,) * 3}, {"white": (ACCEL_N,) * 3}, 5)
    t = rec.t
    dv = 0.5e-3 * (np.sin(2 * np.pi * 1.0 * t) - np.sin(2 * np.pi * 1.0 * (t - DT)))  # velocity increments, m/s
    accel = rec.accel.copy()
    accel[0, :, :2] += dv[:, None]  # x and y shake, z does not
    shaken = identify.identify(imudata.IMUData(rec.t, rec.gyro, accel, "increment"), name="shaken")
    assert [(s, ax) for s, ax, *_ in shaken.poor_fits()] == [("accel", "x"), ("accel", "y")]
    assert any(line.startswith("warning: the IEEE-952 terms do not describe accel x") for line in identify.summary(shaken))
    assert identify.poor_fit_note(nb) == ""
