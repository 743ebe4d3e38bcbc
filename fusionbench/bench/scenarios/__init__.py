"""Scenarios as data: TOML files describing site, motion, IMU, reference, initial guess and run sizes.

Built-in scenarios ship in this folder (``*.toml``); a user's scenario is any TOML file of the
same form. Every file is validated on load; an error names the file and the field.

The format, every key with its type, unit, default and allowed range (``[quick]``, ``[site]``, ``[attitude]``,
``[motion]`` (segments, a disturbance, or a drive's legs), ``[imu]`` with its presets, datasheet-unit overrides and
noise schedules, ``[vref]`` or ``[aiding]`` (a receiver: :mod:`fusionbench.bench.scenarios.tables`), ``[init]``,
``[metrics]``, ``[variants.NAME]``, ``[paper]``, the tables an experiment adds and the conformance-matrix file), is
docs/scenarios.md; tests/test_docs*.py keep it in step with :func:`parse`. In short: angles in degrees, times in
s, sensor figures in the datasheet units named in the key (``gyro_bias_dph``, ``arw_dpsh``, ``vrw_ug_rthz``)::

    name = "static-34n"
    duration_s = 300.0
    rate_hz = 100.0
    methods = ["coarse", "kf"]
    [site]
    lat_deg = 34.0
    [imu]
    preset = "seed000"
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import ClassVar

import numpy as np

from fusionbench.bench import feature as features
from fusionbench.bench.experiment import ScenarioBase, load_experiment
from fusionbench.bench.scenarios.tables import AIDING_KEYS, MAX_SPEED_MPS, MOTION_KEYS, parse_aiding, parse_motion
from fusionbench.methods.aligner import Site, entry_class
from fusionbench.methods.discovery import unknown_option
from fusionbench.scoring import bound
from fusionbench.simulation import attitude, fields, imu, trajectory
from fusionbench.simulation.aidingsim import AidingSpec
from fusionbench.simulation.drive import Drive
from fusionbench.simulation.translation import Translation

_TOP = {"name", "description", "kind", "duration_s", "rate_hz", "runs", "methods", "quick", "site", "attitude",
        "motion", "imu", "vref", "aiding", "init", "metrics", "variants", "paper", "experiment"}
#: What a scenario is about, which decides what its figures draw and which figure the overview scores:
#: ``alignment`` (a stationary or swaying base: the theoretical limits and the settling band apply);
#: ``moving-alignment`` (a vehicle under way with a velocity reference: the stationary limits do not apply,
#: the error is scored against the truth); ``navigation`` (free-inertial navigation from a given attitude over
#: hours, e.g. Schuler damping: no limit, no settling band); ``calibration`` (self-calibration of error
#: coefficients) and ``conformance`` (the method x condition matrix). Inferred when a file gives none: from
#: ``experiment``, then ``navigation`` when [metrics] has rmse_window_s, ``moving-alignment`` when [motion] has
#: segments.
SCENARIO_KINDS = ("alignment", "moving-alignment", "navigation", "calibration", "conformance")
_SECTIONS = {
    "quick": {"duration_s", "runs"},
    "site": {"lat_deg", "lon_deg", "height_m"},
    "attitude": {"pitch_deg", "roll_deg", "heading_deg", "sway_amplitude_deg", "sway_frequency_hz",
                 "sway_phase_deg"},
    "motion": MOTION_KEYS,
    "imu": set(imu.SPEC_KEYS),
    "vref": {"sigma_mps", "schedule"},
    "aiding": AIDING_KEYS,
    "init": {"misalignment_deg"},
    "metrics": {"settling_band_arcmin", "zoom_from_s"},  # and the keys of the metric features
}


def sections():
    """Every table of a scenario file with its keys: the core's and the metric features' (``[metrics]``,
    ``[paper]``: :mod:`fusionbench.features`)."""
    out = {k: set(v) for k, v in _SECTIONS.items()}
    for table in ("metrics", "paper"):
        out.setdefault(table, set()).update(features.table_keys(table))
    return out


#: An invalid scenario file or field: one line naming the file and the field (the FieldError of
#: :mod:`fusionbench.simulation.fields`, which the IMU table's parser raises too).
ScenarioError = fields.FieldError


@dataclass(frozen=True)
class Scenario(ScenarioBase):
    """A validated scenario. Build its parts with the methods below (all SI)."""

    #: One condition, and never a template (:class:`fusionbench.bench.experiment.ScenarioBase`).
    template: ClassVar[bool] = False
    conditions: ClassVar[tuple] = ()

    name: str
    description: str
    duration_s: float
    rate_hz: float
    runs: int
    methods: tuple
    quick_duration_s: float
    quick_runs: int
    site: Site
    euler_mean: tuple
    sway_amplitude: tuple
    sway_frequency: tuple
    sway_phase: tuple
    translation: Translation | Drive
    imu_spec: imu.IMUSpec
    vref_spec: imu.VelocityReferenceSpec
    init_misalignment: tuple | None
    settling_band_arcmin: float
    variants: dict = field(default_factory=dict)
    zoom_from_s: float = 100.0
    features: tuple = ()
    experiment: str = "alignment"
    setup: dict = field(default_factory=dict)
    source: str = ""
    kind: str = "alignment"
    raw: dict = field(default_factory=dict, compare=False, repr=False)
    aiding_spec: AidingSpec | None = None

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    def sized(self, quick: bool):
        """(duration_s, runs) for a full or a quick run."""
        return (self.quick_duration_s, self.quick_runs) if quick else (self.duration_s, self.runs)

    def trajectory(self, duration=None) -> trajectory.Trajectory:
        """The true motion (:class:`fusionbench.simulation.trajectory.Trajectory`; a drive's legs turn the attitude
        with the velocity, :class:`fusionbench.simulation.drive.Drive`)."""
        duration = self.duration_s if duration is None else duration
        if isinstance(self.translation, Drive):
            return trajectory.Trajectory(self.site.lat, self.site.lon, self.site.h, self.translation,
                                         self.translation, duration)
        sway = trajectory.EulerSway(self.euler_mean, self.sway_amplitude, self.sway_frequency, self.sway_phase)
        return trajectory.Trajectory(self.site.lat, self.site.lon, self.site.h, sway, self.translation, duration)

    def reference_model(self):
        """The aiding the methods get, as the bound and the limit model it (:mod:`fusionbench.scoring.bound`):
        ``{"aiding": AidingSpec}`` for a receiver, else the per-increment reference ``{"vref_sigma": m/s, "vref_dt":
        s}`` (on a fixed base without one, the zero-velocity assumption: an exact zero)."""
        if self.aiding_spec is not None:
            return {"aiding": self.aiding_spec}
        return {"vref_sigma": float(max(self.vref_spec.sigma)), "vref_dt": self.dt}

    def moving_limit(self, traj):
        """Where the fixed biases put the optimal estimator on this moving scenario's record ``traj``, and its spread
        about that: :func:`fusionbench.scoring.bound.bias_limit` with :meth:`reference_model`, ``(t, limit, sigma)``
        (s, rad, rad; ENU), computed once per process for the same scenario and record."""
        model = self.reference_model()
        key = (self.name, self.imu_spec, self.site, self.dt, traj.duration, repr(sorted(model.items())))
        if key not in _MOVING_LIMITS:
            _MOVING_LIMITS.clear()  # one scenario at a time: the cache holds the last one's only
            _MOVING_LIMITS[key] = bound.bias_limit(self.imu_spec, traj.duration, trajectory=traj, **model)
        return _MOVING_LIMITS[key]

    def initial_guess(self, C_bn_true):
        """Initial attitude guess (3, 3) from the prescribed misalignment, or None."""
        if self.init_misalignment is None:
            return None
        C_n_nprime = attitude.euler_platform_to_dcm(np.radians(self.init_misalignment))
        return C_n_nprime @ C_bn_true

    def feature(self, name):
        """The scenario's metric feature ``name`` (:mod:`fusionbench.features`), or None."""
        return next((f for f in self.features if f.name == name), None)

    def method(self, name):
        """Instantiate a method by scenario variant name, registered name or ``module:Class`` path, through the
        scenario's experiment (:meth:`fusionbench.bench.experiment.Experiment.load_method`: an aligner gets the
        scenario's IMU spec and velocity-reference noise when it takes them, unless the variant sets them)."""
        exp = self.experiment_type
        if name not in self.variants:
            return exp.load_method(self, name)
        options = dict(self.variants[name])
        try:
            return exp.load_method(self, options.pop("method"), **options)
        except (TypeError, ValueError) as exc:  # an option its class refuses: reported against the scenario's table
            raise ScenarioError(f"{_where(self.source, 'variants.' + name)}: {exc}") from None


_where, _num, _vec = fields.where, fields.number, fields.vector
#: :meth:`Scenario.moving_limit`'s cache (one scenario's).
_MOVING_LIMITS = {}
#: Largest sway amplitude, deg: a ship rolls by tens of degrees at most.
MAX_SWAY_DEG = 45.0


def _schedules(items, src, key):
    return imu.schedules_from_list(items, src, key)


def _imu_spec(d, src):
    return imu.spec_field(d, src)


def parse(data: dict, src: str = "<scenario>", tables=None) -> Scenario:
    """Validate a scenario mapping (as read from TOML) and build a :class:`Scenario`.

    ``tables`` are an experiment's own required top-level tables, ``{name: parser(table, src, duration_s)}``;
    what each parser returns is the scenario's ``setup[name]``."""
    tables = tables or {}
    unknown = set(data) - _TOP - set(tables)
    if unknown:
        raise ScenarioError(f"{_where(src, sorted(unknown)[0])}: unknown (expected one of {sorted(_TOP)})")
    for sec, keys in sections().items():
        if sec in data and not (sec == "imu" and isinstance(data[sec], str)):  # imu: a table, a preset or a file
            if not isinstance(data[sec], dict):
                raise ScenarioError(f"{_where(src, sec)}: expected a table, found {data[sec]!r}")
            bad = set(data[sec]) - keys
            if bad:
                raise ScenarioError(f"{_where(src, sec + '.' + sorted(bad)[0])}: unknown (expected one of {sorted(keys)})")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"{_where(src, 'name')}: expected a non-empty string, found {name!r}")
    duration = _num(data, "duration_s", src, lo=1.0, hi=10 * 86400)
    rate = _num(data, "rate_hz", src, lo=1.0, hi=10000.0)
    runs = int(_num(data, "runs", src, default=10, lo=1, hi=100000))
    methods = data.get("methods", ["coarse"])
    if not isinstance(methods, list) or not methods or not all(isinstance(m, str) and m for m in methods):
        raise ScenarioError(f"{_where(src, 'methods')}: expected a non-empty list of method names, found {methods!r}")
    quick = data.get("quick", {})
    q_dur = _num(quick, "duration_s", f"{src} [quick]", default=min(duration, 120.0), lo=1.0, hi=duration)
    q_runs = int(_num(quick, "runs", f"{src} [quick]", default=min(runs, 3), lo=1, hi=runs))
    site_d = data.get("site", {})
    lat = _num(site_d, "lat_deg", f"{src} [site]", lo=-90, hi=90)
    site = Site.from_degrees(lat, _num(site_d, "lon_deg", f"{src} [site]", 0.0, -360, 360),
                             _num(site_d, "height_m", f"{src} [site]", 0.0, -1e4, 1e5))
    at = data.get("attitude", {})
    s = f"{src} [attitude]"
    mean = (np.radians(_num(at, "pitch_deg", s, 0.0, -90, 90)), np.radians(_num(at, "roll_deg", s, 0.0, -180, 180)),
            -np.radians(_num(at, "heading_deg", s, 0.0, -360, 360)))
    amp = tuple(np.radians(_vec(at, "sway_amplitude_deg", s, lo=0.0, hi=MAX_SWAY_DEG)))
    freq = _vec(at, "sway_frequency_hz", s)
    if min(freq) < 0 or max(freq) > rate / 4:
        raise ScenarioError(f"{_where(src, 'attitude.sway_frequency_hz')}: expected values in [0, rate_hz/4], found {freq}")
    phase = tuple(np.radians(_vec(at, "sway_phase_deg", s, lo=-360.0, hi=360.0)))
    translation = parse_motion(data.get("motion", {}), src, duration, rate, -mean[2], mean[0], mean[1], any(amp))
    spec = _imu_spec(data.get("imu", {}), src)
    vr = data.get("vref", {})
    vspec = imu.VelocityReferenceSpec(_vec(vr, "sigma_mps", f"{src} [vref]", lo=0.0, hi=MAX_SPEED_MPS),
                                      _schedules(vr.get("schedule", []), src, "vref.schedule"))
    aiding = None
    if "aiding" in data:
        if "vref" in data:
            raise ScenarioError(f"{_where(src, 'aiding')}: expected [aiding] or [vref] (the per-increment reference), "
                                f"found both")
        aiding = parse_aiding(data["aiding"], src, duration)
    for key, scheds in (("imu.schedule", spec.schedules), ("vref.schedule", vspec.schedules),
                        ("aiding.schedule", () if aiding is None else aiding.schedules)):
        for i, sc in enumerate(scheds):
            if sc.start >= duration:
                raise ScenarioError(f"{_where(src, f'{key}[{i}].start_s')}: expected a window that starts inside the "
                                    f"record (< duration_s = {duration:g} s), found {sc.start:g}")
    init = data.get("init", {})
    mis = _vec(init, "misalignment_deg", f"{src} [init]", lo=-180.0, hi=180.0) if "misalignment_deg" in init else None
    band = _num(data.get("metrics", {}), "settling_band_arcmin", f"{src} [metrics]", 1.0, 1e-6, 1e4)
    zoom = _num(data.get("metrics", {}), "zoom_from_s", f"{src} [metrics]", 100.0, 0.0, duration)
    try:
        feats = features.parse_features(data, src, duration, methods)
    except ValueError as exc:  # a feature's own message, as every scenario error: one line
        raise ScenarioError(str(exc).splitlines()[0]) from None
    variants = data.get("variants", {})
    if not isinstance(variants, dict):
        raise ScenarioError(f"{_where(src, 'variants')}: expected tables [variants.NAME], found {variants!r}")
    experiment = data.get("experiment", "alignment")
    exp = _experiment(experiment, src)
    for vname, opts in variants.items():
        if not isinstance(opts, dict) or not isinstance(opts.get("method"), str):
            raise ScenarioError(f"{_where(src, 'variants.' + vname)}: expected a table with a 'method' name and its options")
        _check_variant_options(exp, vname, opts, src)
    setup = {}
    for key, parser in tables.items():
        if not isinstance(data.get(key), dict):
            raise ScenarioError(f"{_where(src, key)}: expected a [{key}] table, found {data.get(key)!r}")
        try:
            setup[key] = parser(data[key], src, duration)
        except ValueError as exc:
            raise ScenarioError(str(exc).splitlines()[0]) from None
    has_rmse_window = "rmse_window_s" in data.get("metrics", {})
    kind = _kind(data, src, exp.kind, has_rmse_window, not translation.is_static())
    return Scenario(name, str(data.get("description", "")), duration, rate, runs, tuple(methods), q_dur, q_runs,
                    site, mean, amp, freq, phase, translation, spec, vspec, mis, band, variants, zoom, feats,
                    experiment, setup, src, kind, data, aiding)


def _check_variant_options(exp, vname, opts, src):
    """A variant's options must be options of its method's constructor (checked when the file is read, not when the
    variant first runs); their values are the method's to check when it is built."""
    try:
        cls = entry_class(exp.method_group, opts["method"], "method")
    except ValueError as exc:
        raise ScenarioError(f"{_where(src, 'variants.' + vname + '.method')}: {str(exc).splitlines()[0]}") from None
    key, allowed = unknown_option(cls, [k for k in opts if k != "method"])
    if key is not None:
        raise ScenarioError(f"{_where(src, f'variants.{vname}.{key}')}: unknown option of method "
                            f"{opts['method']!r} (expected one of {allowed})")


def _experiment(name, src):
    """The registered experiment ``name`` (:mod:`fusionbench.bench.experiment`); a ScenarioError naming the field."""
    try:
        return load_experiment(name, _where(src, "experiment"))
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None


def _kind(data, src, given, has_rmse_window, moves):
    """The scenario's ``kind`` (:data:`SCENARIO_KINDS`): as the file gives it, else the experiment's (``given``), else
    inferred (see SCENARIO_KINDS)."""
    if "kind" in data:
        if data["kind"] not in SCENARIO_KINDS:
            raise ScenarioError(f"{_where(src, 'kind')}: expected one of {SCENARIO_KINDS}, found {data['kind']!r}")
        return data["kind"]
    if given is not None:
        return given
    return "navigation" if has_rmse_window else "moving-alignment" if moves else "alignment"


def load(path, overrides=None) -> Scenario:
    """Load and validate a scenario from a TOML file path; ``overrides`` replace top-level entries of the file
    (see :func:`get`)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ScenarioError(f"{path}: no such scenario file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML ({exc})") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path}: expected a UTF-8 TOML text file, found bytes that are not text ({exc.reason} "
                            f"at byte {exc.start})") from None
    except IsADirectoryError:
        raise ScenarioError(f"{path}: expected a scenario file, found a folder") from None
    return _parse_any(data, str(path), overrides)


def _parse_any(data, src, overrides=None):
    """The scenario object of the file's experiment (``experiment``, default ``alignment``): its ``load``; the
    ``overrides`` replace top-level entries first."""
    if overrides:
        data = {**data, **overrides}
    return _experiment(data.get("experiment", "alignment"), src).load(data, src)


def builtin_names(templates=True):
    """Names of the built-in scenarios, sorted; ``templates=False`` leaves out the templates of a user's sensor
    (``twin``: run only with ``--imu`` and ``--site``), which is what ``run all`` runs."""
    names = sorted(p.name[:-5] for p in resources.files(__name__).iterdir() if p.name.endswith(".toml"))
    return names if templates else [n for n in names if not getattr(get(n), "template", False)]


def get(name_or_path, overrides=None) -> Scenario:
    """A built-in scenario by name, or a scenario file by path.

    ``overrides`` replace top-level entries of the file before it is validated, e.g. ``{"imu": "my_imu.toml",
    "site": {"lat_deg": 34.2}}`` (the command line's ``run --imu`` and ``--site``); give an IMU file's path
    absolute (a relative one would be taken relative to the scenario file's folder).
    """
    if name_or_path in builtin_names():
        ref = resources.files(__name__) / f"{name_or_path}.toml"
        return _parse_any(tomllib.loads(ref.read_text()), f"{name_or_path}.toml", overrides)
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        return load(p, overrides)
    raise ScenarioError(f"scenario {name_or_path!r}: expected a built-in name ({', '.join(builtin_names())}) or a .toml file")
