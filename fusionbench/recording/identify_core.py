"""Noise identification of an IMU from one static record: the Allan deviation of each axis
(:mod:`fusionbench.recording.allan`), the IEEE-952 terms fitted to it (:mod:`fusionbench.recording.allanfit`), and an
IMU spec made of what was identified.

A static record shows the noise: quantisation Q, angle/velocity random walk N, bias instability B, rate/acceleration
random walk K and rate ramp R, per body axis (x right, y forward, z up). It does not show scale factors or axis
misalignment (nothing moves), nor the turn-on bias: the mean of the record is the earth rate and gravity plus the
bias, with an unknown heading, and one record is one draw of the bias. The spec (:meth:`Identification.to_spec`,
:func:`write_spec_toml`) starts from the error-free preset ``ideal`` and sets the white noise (N), the random walk
(K), a first-order Gauss-Markov bias standing for B (:func:`fusionbench.recording.allanfit.gauss_markov`: its Allan
deviation peaks where the fitted curve has its minimum, as high as the flicker floor 0.664 B) and the quantum
(``sqrt(12) Q``, the increment per count whose rounding error has Allan coefficient Q). The per-run bias sigma is a
placeholder, B (or, where no B is seen, the bias instability the lowest measured deviation allows): replace it
with the datasheet's bias repeatability. The rate ramp has no counterpart in the error model and is reported only.

This module computes (:func:`identify`, :class:`Identification`); what is written and printed of it is
:mod:`fusionbench.recording.identify_report`; the public entry points of both are
:mod:`fusionbench.recording.identify`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusionbench.files import reportdir
from fusionbench.recording import allan as allan_mod, allanfit
from fusionbench.simulation import units
from fusionbench.simulation.imu import SPEC_SCALARS, IMUSpec, spec_from_table
from fusionbench.simulation.imudata import IMUData

__all__ = ["MIN_SAMPLES", "MIN_TAU_S", "UNITS", "ADEV_UNITS", "OUTPUT", "Term", "Identification", "identify"]

#: Fewest samples a record must have.
MIN_SAMPLES = 100
#: The longest averaging time (the last octave of the sample interval within a quarter of the record) must reach
#: this, s: below it no bias term can show.
MIN_TAU_S = 10.0
SENSORS = ("gyro", "accel")
AXES = ("x", "y", "z")
#: Units of each term: sensor -> term -> (SI unit, datasheet unit, SI value of one datasheet unit).
UNITS = {
    "gyro": {"Q": ("rad", "arcsec", units.ARCSEC), "N": ("rad/sqrt(s)", "deg/sqrt(h)", units.DEG_PER_SQRT_H),
             "B": ("rad/s", "deg/h", units.DEG_PER_H), "K": ("rad/s/sqrt(s)", "deg/h/sqrt(h)", units.DEG_PER_H_SQRT_H),
             "R": ("rad/s^2", "deg/h/h", units.DEG_PER_H_PER_H)},
    "accel": {"Q": ("m/s", "m/s", 1.0),  # a velocity quantum is quoted in m/s, SI already
              "N": ("m/s/sqrt(s)", "ug/sqrt(Hz)", units.UG_PER_SQRT_HZ), "B": ("m/s^2", "ug", units.UG),
              "K": ("m/s^2/sqrt(s)", "ug/sqrt(s)", units.UG_PER_SQRT_S), "R": ("m/s^3", "ug/s", units.UG_PER_S)},
}
#: Unit of the Allan deviation in the figure and the summary: sensor -> (name, SI value of one unit).
ADEV_UNITS = {"gyro": ("deg/h", units.DEG_PER_H), "accel": ("ug", units.UG)}
#: SI unit of the Allan deviation.
ADEV_SI = {"gyro": "rad/s", "accel": "m/s^2"}
#: Relative deviation of the mean specific force from g beyond which the summary doubts the record is static.
#: Below this probability an Allan point is not one the fitted terms produce (:meth:`Identification.poor_fits`): about
#: one false alarm in 10 000 records of 6 axes x 17 points.
FIT_P_MIN = 1e-6
#: ... and only a point whose Allan deviation is more than this far (relative) from the model's: at short taus, with
#: hundreds of thousands of degrees of freedom, 2 % of a quantiser's departure from white noise is significant and
#: harmless.
MISFIT_MIN = 0.10
STATIC_TOLERANCE = 0.02
#: Quantum (increment per count) over the Allan quantisation coefficient Q: a rounding error uniform over one count
#: has variance quantum^2 / 12, and white phase noise of variance Q^2 has Allan variance 3 Q^2 / tau^2.
QUANTUM_PER_Q = math.sqrt(12.0)
SPEC_FILE, JSON_FILE, FIGURE_FILE = "imu_spec.toml", "identify.json", "allan.png"
#: A previous output of ``identify``, which a new one replaces whole: identify.json (its ``record``, ``method`` and
#: ``spec``) and nothing but the three files it writes.
OUTPUT = reportdir.Output(JSON_FILE, ("record", "method", "spec"), f"a previous fusionbench identify output "
                          f"({JSON_FILE}, {SPEC_FILE}, {FIGURE_FILE} and nothing else)",
                          files=(JSON_FILE, SPEC_FILE, FIGURE_FILE))
#: [imu] keys written for each sensor: what -> key.
_KEYS = {"gyro": {"N": "arw_dpsh", "K": "rrw_dph_rth", "instability": "gyro_instability_dph", "tau": "gyro_tau_s",
                  "quantum": "gyro_quantum_arcsec", "bias_sigma": "gyro_bias_sigma_dph"},
         "accel": {"N": "vrw_ug_rthz", "K": "accel_rw_ug_rts", "instability": "accel_instability_ug",
                   "tau": "accel_tau_s", "quantum": "accel_quantum_mps", "bias_sigma": "accel_bias_sigma_ug"}}


@dataclass(frozen=True)
class Term:
    """One fitted term of one axis.

    Attributes
    ----------
    sensor : {"gyro", "accel"}
    name : {"Q", "N", "B", "K", "R"}
    present : bool
        Whether the fit found it significant.
    value, sigma : float
        Coefficient and its 1-sigma uncertainty, SI (:data:`UNITS`); 0 when absent.
    """

    sensor: str
    name: str
    present: bool
    value: float
    sigma: float

    @property
    def unit_si(self):
        return UNITS[self.sensor][self.name][0]

    @property
    def unit(self):
        """Datasheet unit."""
        return UNITS[self.sensor][self.name][1]

    @property
    def datasheet(self):
        """Coefficient in the datasheet unit."""
        return self.value / UNITS[self.sensor][self.name][2]

    @property
    def datasheet_sigma(self):
        return self.sigma / UNITS[self.sensor][self.name][2]


@dataclass(frozen=True)
class Identification:
    """The noise of one IMU record, per sensor and body axis.

    Attributes
    ----------
    name : str
        The IMU's name (the spec's).
    source : str
        Where the record comes from (a file name), or "".
    dt : float
        Sample interval, s.
    samples : int
        Number of samples.
    kind : {"increment", "rate"}
    run : int
        Which run of the IMUData.
    gyro, accel : tuple of 3 allanfit.AllanFit
        The Allan deviation and the fitted terms of axes x, y, z (rad/s, m/s^2).
    mean_rate : float
        Magnitude of the mean angular rate, rad/s (earth rate plus biases on a static base).
    mean_specific_force : float
        Magnitude of the mean specific force, m/s^2 (about g on a static base).
    """

    name: str
    source: str
    dt: float
    samples: int
    kind: str
    run: int
    gyro: tuple
    accel: tuple
    mean_rate: float
    mean_specific_force: float

    @property
    def duration(self):
        """Length of the record, s."""
        return self.samples * self.dt

    def fits(self, sensor):
        """The three AllanFit of ``sensor``."""
        return self.gyro if sensor == "gyro" else self.accel

    def term(self, sensor, axis, name):
        """The :class:`Term` ``name`` of ``sensor`` on ``axis`` (0-2 or "x", "y", "z")."""
        f = self.fits(sensor)[AXES.index(axis) if isinstance(axis, str) else axis]
        return Term(sensor, name, f.is_present(name), f.value(name), f.sigma(name))

    def gauss_markov(self, sensor):
        """The Gauss-Markov bias standing for the bias instability of ``sensor``: ``(sigma (3,), T, tau_floor)``,
        sigma in rad/s or m/s^2 (0 on an axis without B), the correlation time T (s) shared by the triad (the
        error model has one per sensor: the geometric mean of the axes' ``tau_floor / x_peak``, within the range the
        ``[imu]`` parser accepts) and that mean floor time (s); ``T`` and ``tau_floor`` are None when no axis shows
        B."""
        fits = self.fits(sensor)
        sig = np.array([allanfit.gauss_markov(f.value("B"), f.tau_floor)[0] for f in fits])
        floors = [f.tau_floor for f in fits if f.is_present("B")]
        if not floors:
            return sig, None, None
        floor = float(np.exp(np.mean(np.log(floors))))
        lo, hi = SPEC_SCALARS[_KEYS[sensor]["tau"]][3:]
        return sig, float(np.clip(allanfit.gauss_markov(1.0, floor)[1], lo, hi)), floor

    def quantum(self, sensor):
        """Increment per count of ``sensor`` (rad or m/s): ``sqrt(12) Q`` averaged over the axes that show Q (the
        error model has one per sensor), or 0."""
        qs = [f.value("Q") for f in self.fits(sensor) if f.is_present("Q")]
        return QUANTUM_PER_Q * float(np.mean(qs)) if qs else 0.0

    def bias_bound(self, sensor):
        """``(values (3,), measured (3,) bool)``: B where the fit shows it, else the largest B the record allows,
        the lowest measured deviation over ``sqrt(2 ln2 / pi)`` (SI)."""
        fits = self.fits(sensor)
        measured = np.array([f.is_present("B") for f in fits])
        bound = np.array([f.curve.adev.min() / math.sqrt(allanfit.FLICKER) for f in fits])
        return np.where(measured, [f.value("B") for f in fits], bound), measured

    def poor_fits(self):
        """The axes the standard terms do not describe: ``[(sensor, axis, tau, ratio, p)]`` for each axis with an
        Allan point the fitted model cannot have produced: the estimate over the model's variance, a chi-square
        over its degrees of freedom, more than :data:`MISFIT_MIN` off the model and so unlikely that its
        two-sided probability is below :data:`FIT_P_MIN` (a
        vibration's hump, a motion, a temperature run). ``tau`` (s) is the worst point's, ``ratio`` its Allan
        deviation over the model's. A point test, not the fit's chi-square: that one also grows when a term just
        below detection is left out, which is no reason to doubt the record. Their terms only approximate the
        sensor's noise."""
        out = []
        for s in SENSORS:
            for j, f in enumerate(self.fits(s)):
                c = f.curve
                model = f.avar(c.tau)
                p = _point_p(c.adev ** 2 / model, c.edf)
                p[np.abs(c.adev / np.sqrt(model) - 1.0) <= MISFIT_MIN] = 1.0  # a few % at short tau: no matter
                k = int(np.argmin(p))
                if p[k] < FIT_P_MIN:
                    out.append((s, AXES[j], float(c.tau[k]), float(c.adev[k] / np.sqrt(model[k])), float(p[k])))
        return out

    def static_note(self):
        """One line doubting that the record is static, or ""."""
        off = abs(self.mean_specific_force / units.G0 - 1.0)
        if off > STATIC_TOLERANCE:
            return (f"note: the mean specific force is {self.mean_specific_force:.4g} m/s^2, {100 * off:.1f} % off g: "
                    f"is the record static? The Allan deviation of a moving record is not the sensor's noise")
        return ""

    def to_spec(self) -> IMUSpec:
        """The identified IMU as an IMUSpec: what :func:`write_spec_toml` writes, at full precision."""
        return spec_from_table({k: v for k, v, _ in spec_table(self)}, f"<identified {self.name}>")


def _vec(values):
    return "[" + ", ".join(_fmt(v) for v in values) + "]"


def spec_table(ident: Identification):
    """The ``[imu]`` table of the identified spec: a list of ``(key, value, comment)``, values in the keys' units
    (full precision), only the keys of what was identified (plus the preset, name, description and the
    placeholder bias sigmas)."""
    x_peak, adev_peak = allanfit.gm_peak()
    where = f" from {ident.source}" if ident.source else ""
    rows = [("preset", "ideal", "no errors but those below: scale factors, misalignment and the fixed bias cannot "
                                "be seen in a static record"),
            ("name", ident.name, ""),
            ("description", f"identified{where} by fusionbench identify: {ident.samples} samples of {ident.dt:.6g} s "
                            f"({ident.duration / 3600:.3g} h), Allan deviation and IEEE-952 fit", "")]
    for s in SENSORS:
        keys, terms = _KEYS[s], {t: [ident.term(s, j, t) for j in range(3)] for t in allanfit.TERMS}
        for t in ("N", "K"):
            if any(x.present for x in terms[t]):
                factor = UNITS[s][t][2]
                rows.append((keys[t], [x.value / factor for x in terms[t]],
                             f"{t}, Allan slope {_slope(t)}: +- {_vec(x.datasheet_sigma for x in terms[t])} "
                             f"{UNITS[s][t][1]} (1 sigma); 0 = not significant"))
        sig, T, floor = ident.gauss_markov(s)
        if T is not None:
            factor = UNITS[s]["B"][2]
            rows.append((keys["instability"], [v / factor for v in sig],
                         f"Gauss-Markov sigma for B = {_vec(x.datasheet for x in terms['B'])} {UNITS[s]['B'][1]}: "
                         f"0.664 B / {adev_peak:.4f}, its Allan peak at the flicker floor"))
            rows.append((keys["tau"], T, f"s: the fitted curve's minimum at {floor:.4g} s (geometric mean over the "
                                         f"axes) / {x_peak:.4f}, where a Gauss-Markov's Allan deviation peaks"))
        q = ident.quantum(s)
        if q > 0:
            factor = UNITS[s]["Q"][2]
            rows.append((keys["quantum"], q / factor,
                         f"{UNITS[s]['Q'][1]} per count = sqrt(12) Q, Q = {_vec(x.datasheet for x in terms['Q'])} "
                         f"{UNITS[s]['Q'][1]} (mean of the axes that show it)"))
        bias, measured = ident.bias_bound(s)
        factor = UNITS[s]["B"][2]
        rows.append((keys["bias_sigma"], [v / factor for v in bias],
                     "PLACEHOLDER, replace with the datasheet's bias repeatability: a static record cannot show the "
                     "turn-on bias; this is B" + ("" if measured.all() else
                                                  " (the largest B the record allows where B is not seen)")))
    return rows


def _slope(t):
    return {"Q": "-1", "N": "-1/2", "B": "0", "K": "+1/2", "R": "+1"}[t]


def _phase_check(imu, run):
    if not isinstance(imu, IMUData):
        raise ValueError(f"identify: expected an IMUData record, found {type(imu).__name__}")
    if not (isinstance(run, (int, np.integer)) and 0 <= run < imu.runs):
        raise ValueError(f"identify run: expected a run index in [0, {imu.runs - 1}], found {run!r}")
    n = imu.samples
    m = allan_mod.octave_factors(n + 1)
    longest = float(m[-1] * imu.dt) if m.size else 0.0
    if n < MIN_SAMPLES or longest < MIN_TAU_S:
        raise ValueError(f"identify: expected a static record of at least {MIN_SAMPLES} samples whose longest Allan "
                         f"averaging time (the last octave within a quarter of the record) reaches {MIN_TAU_S:g} s, "
                         f"found {n} samples of {imu.dt:.6g} s ({n * imu.dt:.6g} s, longest averaging time "
                         f"{longest:.6g} s)")


def identify(imu: IMUData, *, name="identified", source="", run=0) -> Identification:
    """Identify the noise terms of each gyro and accelerometer axis of one static record.

    Parameters
    ----------
    imu : IMUData
        The record, kind "increment" (exact) or "rate" (each sample the mean over its interval), body frame.
    name : str
        The IMU's name, written into the spec.
    source : str
        Where the record comes from (a file name), for the spec's comments and the report.
    run : int
        Which run of ``imu``.

    Returns
    -------
    Identification

    Raises
    ------
    ValueError
        One line: not an IMUData, a bad run, or a record too short (fewer than :data:`MIN_SAMPLES` samples, or a
        longest averaging time below :data:`MIN_TAU_S`).
    """
    _phase_check(imu, run)
    curves = allan_mod.allan(imu, run)
    g, a = imu.rates()
    fits = {s: tuple(allanfit.fit(c, imu.dt) for c in getattr(curves, s)) for s in SENSORS}
    return Identification(str(name), str(source), imu.dt, imu.samples, imu.kind, int(run), fits["gyro"], fits["accel"],
                          float(np.linalg.norm(g[run].mean(axis=0))), float(np.linalg.norm(a[run].mean(axis=0))))


# ------------------------------------------------------------------------------------------------ the spec


def _fmt(v):
    return f"{v:.6g}"


def _point_p(ratio, edf):
    """Two-sided probability of each Allan variance estimate over its model variance ``ratio``, a chi-square with
    ``edf`` degrees of freedom over ``edf``."""
    from scipy.stats import chi2 as chi2_dist

    x = np.asarray(edf) * np.asarray(ratio)
    return np.minimum(1.0, 2.0 * np.minimum(chi2_dist.cdf(x, edf), chi2_dist.sf(x, edf)))
