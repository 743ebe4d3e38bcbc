"""A conformance matrix file: its conditions (base, latitude, heading, IMU, reference or receiver), its sizes and
thresholds (:func:`parse`), and each condition as an ordinary alignment scenario (:func:`condition_scenario`) with
its attainable bound (:func:`condition_bound`). The format is docs/scenarios.md's; the experiment that runs a
matrix is :mod:`fusionbench.experiments.conformance`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import ClassVar, Mapping

import numpy as np

from fusionbench.bench.experiment import ScenarioBase
from fusionbench.methods import claims
from fusionbench.methods.claims import azimuth_bias_ratio
from fusionbench.scoring import bound
from fusionbench.simulation import fields, imu, units
from fusionbench.simulation.drive import car_legs

#: Bases of a condition: kind claimed (:data:`fusionbench.methods.claims.BASE_KINDS`), sway amplitude (deg) and
#: frequency (Hz) of [pitch, roll, yaw].
BASE_MOTIONS = {
    "static": ("static", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "sway-mild": ("sway", (1.0, 1.5, 2.0), (0.2, 0.1, 0.05)),
    "sway-table1": ("sway", (5.0, 7.0, 9.0), (0.5, 0.3, 0.2)),
    "moving": ("moving", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "drive": ("moving", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
}
#: What the receiver of a moving condition measures (``aiding``).
AIDING = ("velocity", "position", "velocity+position")
#: Acceleration of the moving base along its heading, m/s^2 (0.1 g).
MOVING_ACCEL = 0.1 * units.G0
#: Mean tilt of every base, deg (pitch, roll): a level IMU would hide sign errors between the level axes.
TILT_DEG = (1.0, -2.0)
_TOP = {"name", "description", "kind", "experiment", "duration_s", "rate_hz", "runs", "methods", "quick", "metrics",
        "conformance", "condition", "paper", "imu", "site", "template", "run_unclaimed"}
#: Longitude (deg) and height (m) of a condition when the matrix gives no ``[site]``.
DEFAULT_LON_DEG, DEFAULT_HEIGHT_M = 108.0, 100.0
_CONDITION_KEYS = {"name", "base", "lat_deg", "heading_deg", "imu", "vref_sigma_mps", "expect", "aiding",
                   "aiding_rate_hz", "position_sigma_m", "lever_arm_m", "delay_s", "outage_s", "init_error_deg"}


@dataclass(frozen=True)
class Condition:
    """One condition of the matrix (deg, m/s, m); ``expect`` is "align" or "refuse"; ``imu`` a preset name or the
    absolute path of an IMU spec file. On a moving base: what the receiver measures (``aiding``, :data:`AIDING`), at
    ``aiding_rate_hz`` (None: at every increment, the per-increment reference), with ``vref_sigma_mps`` and
    ``position_sigma_m`` of noise, from an antenna at ``lever_arm_m`` (body RFU), ``delay_s`` late, and an outage of
    ``outage_s`` from half the record on (both given to the method). ``init_error_deg``: every method is handed an
    initial attitude, the truth turned by this much in azimuth (None: each starts on its own); a method that
    declares a smaller capture range (``init_capture_deg``) must refuse it, naming ``init``."""

    name: str
    base: str
    lat_deg: float
    heading_deg: float
    imu: str
    vref_sigma_mps: float = 0.0
    expect: str = "align"
    lon_deg: float = DEFAULT_LON_DEG
    height_m: float = DEFAULT_HEIGHT_M
    aiding: str = "velocity"
    aiding_rate_hz: float | None = None
    position_sigma_m: float = 0.5
    lever_arm_m: tuple = (0.0, 0.0, 0.0)
    delay_s: float = 0.0
    outage_s: float = 0.0
    init_error_deg: float | None = None

    def refuses_init(self, method) -> bool:
        """Whether ``method`` must refuse this condition's initial attitude: one beyond the capture range it
        declares (:attr:`fusionbench.methods.aligner_base.AlignerBase.init_capture_deg`)."""
        capture = getattr(method, "init_capture_deg", None)
        return self.init_error_deg is not None and capture is not None and abs(self.init_error_deg) > capture

    @property
    def kind(self):
        return BASE_MOTIONS[self.base][0]

    @property
    def receiver(self):
        """Whether the condition's aiding is a receiver's (``[aiding]``: its own rate, position, lever arm, latency or
        an outage) rather than the per-increment velocity reference (``[vref]``)."""
        return self.kind == "moving" and (self.aiding != "velocity" or self.aiding_rate_hz is not None
                                          or any(self.lever_arm_m) or self.delay_s != 0.0 or self.outage_s > 0.0)

    def aiding_claim(self, rate_hz):
        """What a method must claim to run here (:meth:`fusionbench.methods.claims.Supports.covers`): the aiding
        kinds, the rows' rate (Hz; ``rate_hz`` the IMU's when the reference is per increment) and the outage (s)."""
        if self.kind != "moving":
            return {}
        return {"aiding": tuple(self.aiding.split("+")), "aiding_hz": self.aiding_rate_hz or rate_hz,
                "outage_s": self.outage_s}


@dataclass(frozen=True)
class Matrix(ScenarioBase):
    """A validated conformance matrix file."""

    #: Its conditions carry their own features and starts (:class:`fusionbench.bench.experiment.ScenarioBase`).
    features: ClassVar[tuple] = ()
    variants: ClassVar[Mapping] = MappingProxyType({})
    init_misalignment: ClassVar[None] = None

    name: str
    description: str
    conditions: tuple
    duration_s: float
    rate_hz: float
    runs: int
    quick_duration_s: float
    quick_runs: int
    methods: tuple | None
    settling_band_arcmin: float
    level_tolerance_arcmin: float
    efficiency_max: dict
    source: str = ""
    paper: dict = field(default_factory=dict)
    experiment: str = "conformance"
    kind: str = "conformance"
    template: bool = False
    run_unclaimed: bool = False

    def sized(self, quick):
        """(duration_s, runs) for a full or a quick run."""
        return (self.quick_duration_s, self.quick_runs) if quick else (self.duration_s, self.runs)

    def threshold(self, method):
        """The efficiency a method must reach: its entry of ``[conformance.efficiency]``, else ``default``."""
        return float(self.efficiency_max.get(method, self.efficiency_max["default"]))


def parse(data, src="<conformance>"):
    """Validate a conformance matrix mapping (as read from TOML); errors name the file and the field."""
    bad = sorted(set(data) - _TOP)
    if bad:
        raise fields.FieldError(f"{fields.where(src, bad[0])}: unknown (expected one of {sorted(_TOP)})")
    name = fields.string(data, "name", src)
    if data.get("kind", "conformance") != "conformance":
        raise fields.FieldError(f"{fields.where(src, 'kind')}: expected 'conformance' for a conformance matrix, "
                                f"found {data['kind']!r}")
    duration = fields.number(data, "duration_s", src, lo=10.0, hi=86400.0)
    rate = fields.number(data, "rate_hz", src, lo=1.0, hi=10000.0)
    runs = int(fields.number(data, "runs", src, 20.0, lo=1, hi=100000))
    quick = fields.table(data, "quick", src, {"duration_s", "runs"})
    methods = data.get("methods")
    if methods is not None and (not isinstance(methods, list) or not methods
                                or not all(isinstance(m, str) and m for m in methods)):
        raise fields.FieldError(f"{fields.where(src, 'methods')}: expected a non-empty list of method names (absent: "
                                f"every registered aligner), found {methods!r}")
    met = fields.table(data, "metrics", src, {"settling_band_arcmin"})
    conf = fields.table(data, "conformance", src, {"level_tolerance_arcmin", "efficiency"})
    eff = conf.get("efficiency", {})
    if not isinstance(eff, dict) or "default" not in eff:
        raise fields.FieldError(f"{fields.where(src, 'conformance.efficiency')}: expected a table with 'default' and "
                                f"per-method thresholds, found {eff!r}")
    eff = {k: fields.number(eff, k, src, lo=1.0, hi=1e6, label=f"conformance.efficiency.{k}") for k in eff}
    sensor = data.get("imu")
    if sensor is not None:
        spec = imu.spec_field(sensor, src)  # checked here, once
        sensor = sensor if sensor in imu.PRESETS else str(imu.near(sensor, src).resolve())
    site = fields.table(data, "site", src, {"lat_deg", "lon_deg", "height_m"})
    site_lat = fields.number(site, "lat_deg", src, lo=-89.0, hi=89.0, label="site.lat_deg") if "lat_deg" in site else None
    template, unclaimed = data.get("template", False), data.get("run_unclaimed", False)
    for key, value in (("template", template), ("run_unclaimed", unclaimed)):
        if not isinstance(value, bool):
            raise fields.FieldError(f"{fields.where(src, key)}: expected true or false, found {value!r}")
    items = data.get("condition")
    if not isinstance(items, list) or not items:
        raise fields.FieldError(f"{fields.where(src, 'condition')}: expected [[condition]] tables, found {items!r}")
    conds, seen = [], set()
    for i, c in enumerate(items):
        label = f"condition[{i}]"
        if not isinstance(c, dict):
            raise fields.FieldError(f"{fields.where(src, label)}: expected a table, found {c!r}")
        extra = sorted(set(c) - _CONDITION_KEYS)
        if extra:
            raise fields.FieldError(f"{fields.where(src, label + '.' + extra[0])}: unknown (expected one of "
                                    f"{sorted(_CONDITION_KEYS)})")
        cname = fields.string(c, "name", src, label=f"{label}.name")
        if cname in seen:
            raise fields.FieldError(f"{fields.where(src, label + '.name')}: expected a unique name, found {cname!r} again")
        seen.add(cname)
        lat = fields.number(c, "lat_deg", src, site_lat, lo=-89.0, hi=89.0, label=f"{label}.lat_deg")
        cimu = fields.string(c, "imu", src, sensor, choices=None if sensor else imu.PRESETS, label=f"{label}.imu")
        if cimu != sensor and cimu not in imu.PRESETS:
            raise fields.FieldError(f"{fields.where(src, label + '.imu')}: expected one of {sorted(imu.PRESETS)} (or "
                                    f"the matrix's own imu), found {cimu!r}")
        expect = fields.string(c, "expect", src, "align", choices=("align", "refuse", "auto"), label=f"{label}.expect")
        if expect == "auto":  # refuse where the gyro bias hides the earth rate (every aligner given the model does)
            ratio = azimuth_bias_ratio(spec if cimu == sensor else imu.PRESETS[cimu], np.radians(lat))
            expect = "refuse" if ratio > claims.MAX_BIAS_TO_EARTH_RATE else "align"
        base = fields.string(c, "base", src, choices=BASE_MOTIONS, label=f"{label}.base")
        conds.append(Condition(
            cname, base, lat,
            fields.number(c, "heading_deg", src, lo=-360.0, hi=360.0, label=f"{label}.heading_deg"), cimu,
            fields.number(c, "vref_sigma_mps", src, 0.0, lo=0.0, hi=10.0, label=f"{label}.vref_sigma_mps"), expect,
            fields.number(site, "lon_deg", src, DEFAULT_LON_DEG, lo=-360.0, hi=360.0, label="site.lon_deg"),
            fields.number(site, "height_m", src, DEFAULT_HEIGHT_M, lo=-1e4, hi=1e5, label="site.height_m"),
            **_receiver(c, src, label, BASE_MOTIONS[base][0], duration, rate),
            init_error_deg=(fields.number(c, "init_error_deg", src, lo=-180.0, hi=180.0,
                                          label=f"{label}.init_error_deg") if "init_error_deg" in c else None)))
    return Matrix(name, str(data.get("description", "")), tuple(conds), duration, rate, runs,
                  fields.number(quick, "duration_s", src, duration, lo=10.0, hi=duration, label="quick.duration_s"),
                  int(fields.number(quick, "runs", src, float(min(runs, 3)), lo=1, hi=runs, label="quick.runs")),
                  None if methods is None else tuple(methods),
                  fields.number(met, "settling_band_arcmin", src, 30.0, lo=1e-3, hi=1e4, label="metrics.settling_band_arcmin"),
                  fields.number(conf, "level_tolerance_arcmin", src, 0.5, lo=0.0, hi=1e4,
                                label="conformance.level_tolerance_arcmin"),
                  eff, src, dict(data.get("paper", {})), template=template,
                  run_unclaimed=unclaimed)


def _receiver(c, src, label, kind, duration, rate):
    """The aiding keys of condition ``c`` (a moving base's only: refused elsewhere) as Condition fields."""
    keys = sorted(k for k in ("aiding", "aiding_rate_hz", "position_sigma_m", "lever_arm_m", "delay_s", "outage_s")
                  if k in c)
    if keys and kind != "moving":
        raise fields.FieldError(f"{fields.where(src, label + '.' + keys[0])}: expected only on a moving base (moving, "
                                f"drive), found it on a {kind} one")
    out = {"aiding": fields.string(c, "aiding", src, "velocity", choices=AIDING, label=f"{label}.aiding"),
           "position_sigma_m": fields.number(c, "position_sigma_m", src, 0.5, lo=0.0, hi=100.0,
                                             label=f"{label}.position_sigma_m"),
           "lever_arm_m": fields.vector(c, "lever_arm_m", src, lo=-10.0, hi=10.0, label=f"{label}.lever_arm_m"),
           "delay_s": fields.number(c, "delay_s", src, 0.0, lo=0.0, hi=1.0, label=f"{label}.delay_s"),
           "outage_s": fields.number(c, "outage_s", src, 0.0, lo=0.0, hi=duration / 3, label=f"{label}.outage_s")}
    if "aiding_rate_hz" in c:
        out["aiding_rate_hz"] = fields.number(c, "aiding_rate_hz", src, lo=0.1, hi=rate, label=f"{label}.aiding_rate_hz")
    return out


def condition_scenario(matrix, cond, quick=False, band_arcmin=None):
    """The alignment scenario (:class:`fusionbench.bench.scenarios.Scenario`) of one condition."""
    from fusionbench.bench import scenarios

    duration, runs = matrix.sized(quick)
    _, amp, freq = BASE_MOTIONS[cond.base]
    d = {"name": f"{matrix.name}.{cond.name}",
         "description": f"conformance condition {cond.name}: {cond.base} base, {cond.lat_deg:g} deg latitude, heading "
                        f"{cond.heading_deg:g} deg, {Path(cond.imu).stem} IMU, reference noise {cond.vref_sigma_mps:g} m/s",
         "duration_s": duration, "rate_hz": matrix.rate_hz, "runs": runs, "quick": {"duration_s": duration, "runs": runs},
         "site": {"lat_deg": cond.lat_deg, "lon_deg": cond.lon_deg, "height_m": cond.height_m},
         "attitude": {"pitch_deg": TILT_DEG[0], "roll_deg": TILT_DEG[1], "heading_deg": cond.heading_deg,
                      "sway_amplitude_deg": list(amp), "sway_frequency_hz": list(freq)},
         "imu": cond.imu,
         "vref": {"sigma_mps": [cond.vref_sigma_mps] * 3},
         "metrics": {"settling_band_arcmin": matrix.settling_band_arcmin if band_arcmin is None else band_arcmin}}
    if cond.init_error_deg is not None:  # the truth turned in azimuth (platform angles: the third is about up)
        d["init"] = {"misalignment_deg": [0.0, 0.0, cond.init_error_deg]}
    if cond.base == "moving":
        h = np.radians(cond.heading_deg)
        d["motion"] = {"segments": [{"accel_mps2": [MOVING_ACCEL * np.sin(h), MOVING_ACCEL * np.cos(h), 0.0],
                                     "duration_s": duration}]}
    elif cond.base == "drive":
        d["motion"] = {"legs": [{"duration_s": leg.duration, "accel_mps2": leg.accel,
                                 "turn_rate_dps": float(np.degrees(leg.turn_rate))} for leg in car_legs(duration)]}
    if cond.receiver:
        kinds = cond.aiding.split("+")
        d.pop("vref")
        d["aiding"] = {"rate_hz": cond.aiding_rate_hz or matrix.rate_hz, "lever_arm_m": list(cond.lever_arm_m),
                       "delay_s": cond.delay_s}
        if "velocity" in kinds:
            d["aiding"]["velocity_sigma_mps"] = cond.vref_sigma_mps
        if "position" in kinds:
            d["aiding"]["position_sigma_m"] = cond.position_sigma_m
        if cond.outage_s:
            d["aiding"]["outages"] = [{"start_s": duration / 2, "end_s": duration / 2 + cond.outage_s}]
    return scenarios.parse(d, f"{matrix.source} condition '{cond.name}'")


def condition_bound(scn, cond, duration):
    """The bound (3,) rad of a condition at the end of its record, ENU: on a fixed base the attainable bound about the
    theoretical limit (:func:`fusionbench.scoring.bound.attainable_bound`); on a moving one the spread of the optimal
    estimator about the limit it scores against (:func:`fusionbench.scoring.bound.bias_limit`, the fixed biases
    unknown to it), with the condition's aiding as the methods get it."""
    traj = scn.trajectory(duration)
    if cond.kind == "moving":
        return scn.moving_limit(traj).sigma[-1]
    _, sigma = bound.attainable_bound(scn.imu_spec, duration, trajectory=traj, **scn.reference_model())
    return sigma[-1]


