"""The IMU: its error model and presets (:mod:`fusionbench.simulation.imu_model`), the IMU spec files and ``[imu]``
tables that give one (:func:`load_spec`), and the simulator that turns truth into IMUData
(:mod:`fusionbench.simulation.imusim`), under one name: ``fusionbench.simulation.imu``. Specs are SI; customary units
go through :mod:`fusionbench.simulation.units`, e.g. ``SensorErrors(bias=(0.01 * units.DEG_PER_H,) * 3)``.
"""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np

from fusionbench.simulation import fields, units
from fusionbench.simulation.imu_model import (BIAS_PRIOR_FLOOR, PRESETS,  # noqa: F401 (this module's public names)
                                              IMUSpec, NoiseSchedule, SensorErrors, VelocityReferenceSpec)
from fusionbench.simulation.imusim import (chunk_grid, run_seed_sequence, simulate, simulate_chunks,  # noqa: F401
                                           simulate_vref, vref_stream)

__all__ = ["SensorErrors", "IMUSpec", "NoiseSchedule", "VelocityReferenceSpec", "PRESETS", "BIAS_PRIOR_FLOOR",
           "SPEC_OVERRIDES", "SPEC_SCALARS", "simulate", "simulate_chunks", "simulate_vref", "vref_stream",
           "chunk_grid", "run_seed_sequence", "spec_from_table", "schedules_from_list", "load_spec", "spec_field",
           "near"]


#: Keys of an ``[imu]`` table (scenario files, IMU spec files) that override a preset, in customary units:
#: key -> (sensor, SensorErrors field, unit factor to SI, lowest value allowed)
SPEC_OVERRIDES = {
    "gyro_bias_dph": ("gyro", "bias", units.DEG_PER_H, -3600.0),
    "gyro_bias_sigma_dph": ("gyro", "bias_sigma", units.DEG_PER_H, 0.0),
    "arw_dpsh": ("gyro", "white", units.DEG_PER_SQRT_H, 0.0),
    "gyro_scale_ppm": ("gyro", "scale", units.PPM, -1e5),
    "accel_bias_ug": ("accel", "bias", units.UG, -1e5),
    "accel_bias_sigma_ug": ("accel", "bias_sigma", units.UG, 0.0),
    "vrw_ug_rthz": ("accel", "white", units.UG_PER_SQRT_HZ, 0.0),
    "accel_scale_ppm": ("accel", "scale", units.PPM, -1e5),
    "gyro_instability_dph": ("gyro", "instability", units.DEG_PER_H, 0.0),
    "rrw_dph_rth": ("gyro", "random_walk", units.DEG_PER_H_SQRT_H, 0.0),
    "accel_instability_ug": ("accel", "instability", units.UG, 0.0),
    "accel_rw_ug_rts": ("accel", "random_walk", units.UG_PER_SQRT_S, 0.0),
}
#: Largest magnitude accepted for each override (same units as its key): a gyro bias of 3600 deg/h is
#: one degree per second, an accelerometer bias of 1e5 ug a tenth of g.
_OVERRIDE_MAX = {"gyro_bias_dph": 3600.0, "gyro_bias_sigma_dph": 3600.0, "arw_dpsh": 100.0, "gyro_scale_ppm": 1e5,
                 "accel_bias_ug": 1e5, "accel_bias_sigma_ug": 1e5, "vrw_ug_rthz": 1e5, "accel_scale_ppm": 1e5,
                 "gyro_instability_dph": 3600.0, "rrw_dph_rth": 3600.0, "accel_instability_ug": 1e5,
                 "accel_rw_ug_rts": 1e5}
#: Keys of an ``[imu]`` table that set a figure shared by a triad's three axes (a scalar of SensorErrors), in the
#: unit of the key: key -> (sensor, SensorErrors field, unit factor to SI, lowest, highest value allowed). The
#: correlation time is the Gauss-Markov bias instability's; the quantum is the increment per count (an angle of
#: 3600 arcsec is one degree; a velocity of 1 m/s per count is far beyond any accelerometer).
SPEC_SCALARS = {
    "gyro_tau_s": ("gyro", "tau", 1.0, 0.001, 1e8),
    "accel_tau_s": ("accel", "tau", 1.0, 0.001, 1e8),
    "gyro_quantum_arcsec": ("gyro", "quantum", units.ARCSEC, 0.0, 3600.0),
    "accel_quantum_mps": ("accel", "quantum", 1.0, 0.0, 1.0),
}
#: Keys of an ``[imu]`` table.
SPEC_KEYS = ("preset", "random", "schedule", "name", "description", *SPEC_OVERRIDES, *SPEC_SCALARS)
_SENSORS = ("gyro", "accel")


def schedules_from_list(items, src, key):
    """Noise schedules from a TOML list of ``{start_s, end_s, factor [, sensors]}`` tables (``key`` names it)."""
    if not isinstance(items, list):
        raise fields.FieldError(f"{fields.where(src, key)}: expected a list of tables, found {items!r}")
    out = []
    for i, it in enumerate(items):
        label = f"{key}[{i}]"
        if not isinstance(it, dict) or set(it) - {"start_s", "end_s", "factor", "sensors"}:
            raise fields.FieldError(f"{fields.where(src, label)}: expected start_s, end_s, factor [, sensors], found {it!r}")
        start = fields.number(it, "start_s", src, lo=0, label=f"{label}.start_s")
        end = fields.number(it, "end_s", src, lo=start, label=f"{label}.end_s")
        if end <= start:
            raise fields.FieldError(f"{fields.where(src, label + '.end_s')}: expected an end after start_s = {start:g} s, "
                                    f"found {end:g}")
        factor = fields.number(it, "factor", src, lo=0, hi=1e8, label=f"{label}.factor")
        sensors = it.get("sensors", list(_SENSORS))
        if not isinstance(sensors, list) or not sensors or not all(x in _SENSORS for x in sensors):
            raise fields.FieldError(f"{fields.where(src, label + '.sensors')}: expected a list of {list(_SENSORS)}, "
                                    f"found {sensors!r}")
        out.append(NoiseSchedule(start, end, factor, tuple(sensors)))
    return tuple(out)


def spec_from_table(d, src="<imu>", label="imu"):
    """An IMUSpec from an ``[imu]`` table of a scenario or IMU spec file.

    Keys: ``preset`` (a key of :data:`PRESETS`, default "navigation"), overrides of the preset in
    customary units (:data:`SPEC_OVERRIDES`: ``gyro_bias_dph``, ``arw_dpsh`` (deg/sqrt(h)), ``accel_bias_ug``,
    ``vrw_ug_rthz`` (ug/sqrt(Hz)), ..., each one number or three for the body axes x, y, z; :data:`SPEC_SCALARS`:
    the instability's correlation times ``gyro_tau_s``, ``accel_tau_s`` and the quanta, one number each), ``random``
    (false keeps only the deterministic errors), ``schedule`` (noise-PSD factors over time windows),
    ``name`` and ``description``. ``src`` names the file in error messages, ``label`` the table.

    Raises
    ------
    fields.FieldError
        One line naming the file and the field.
    """
    if not isinstance(d, dict):
        raise fields.FieldError(f"{fields.where(src, label)}: expected a table, found {d!r}")
    bad = sorted(set(d) - set(SPEC_KEYS))
    if bad:
        raise fields.FieldError(f"{fields.where(src, label + '.' + bad[0])}: unknown (expected one of {sorted(SPEC_KEYS)})")
    preset = fields.string(d, "preset", src, "navigation", PRESETS, label=f"{label}.preset")
    spec = PRESETS[preset]
    sensors = {"gyro": spec.gyro, "accel": spec.accel}
    for key, (sensor, name, factor, lo) in SPEC_OVERRIDES.items():
        if key in d:
            values = np.multiply(fields.vector(d, key, src, lo=lo, hi=_OVERRIDE_MAX[key], label=f"{label}.{key}"), factor)
            sensors[sensor] = replace(sensors[sensor], **{name: values})
    for key, (sensor, name, factor, lo, hi) in SPEC_SCALARS.items():
        if key in d:
            value = fields.number(d, key, src, lo=lo, hi=hi, label=f"{label}.{key}") * factor
            sensors[sensor] = replace(sensors[sensor], **{name: value})
    spec = replace(spec, gyro=sensors["gyro"], accel=sensors["accel"],
                   schedules=schedules_from_list(d.get("schedule", []), src, f"{label}.schedule"),
                   name=fields.string(d, "name", src, spec.name, label=f"{label}.name"),
                   description=fields.string(d, "description", src, spec.description, label=f"{label}.description"))
    random = d.get("random", True)
    if not isinstance(random, bool):
        raise fields.FieldError(f"{fields.where(src, label + '.random')}: expected true or false, found {random!r}")
    return spec if random else spec.noise_free()


def load_spec(source):
    """An IMU noise model from a preset name, an IMU spec TOML file, or an IMUSpec (returned as it is).

    A TOML file holds an ``[imu]`` table in the scenario format (:func:`spec_from_table`); a scenario file
    works too (its ``[imu]`` is taken). Without a ``name`` the spec is named after the file.

    Raises
    ------
    ValueError
        One line naming the preset or file and what is wrong.
    """
    if isinstance(source, IMUSpec):
        return source
    if not isinstance(source, (str, Path)):
        raise ValueError(f"imu: expected a preset name ({', '.join(PRESETS)}), an IMU spec .toml file or an IMUSpec, "
                         f"found {type(source).__name__}")
    if str(source) in PRESETS:
        return PRESETS[str(source)]
    path = Path(source)
    if path.suffix.lower() != ".toml" and not path.exists():
        raise ValueError(f"imu: expected a preset name ({', '.join(PRESETS)}) or an IMU spec .toml file, found {str(source)!r}")
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such IMU spec file") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: is a directory, expected an IMU spec .toml file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid TOML ({' '.join(str(exc).split())})") from None
    if not isinstance(data.get("imu"), dict):
        raise fields.FieldError(f"{fields.where(path, 'imu')}: expected an [imu] table (preset and overrides), "
                                f"found {'none' if 'imu' not in data else repr(data['imu'])}")
    table = dict(data["imu"])
    table.setdefault("name", path.stem)
    return spec_from_table(table, str(path))


def spec_field(value, src, label="imu"):
    """The IMU of a scenario or matrix field ``label``: an ``[imu]`` table (:func:`spec_from_table`), or a string,
    a preset name or an IMU spec .toml file (:func:`load_spec`), relative to the folder of the file ``src`` when
    ``src`` is one (else to the working directory).

    Raises
    ------
    ValueError
        One line naming the file and the field, or the IMU spec file and its field.
    """
    if isinstance(value, dict):
        return spec_from_table(value, src, label)
    if not isinstance(value, str) or not value:
        raise fields.FieldError(f"{fields.where(src, label)}: expected an [{label}] table, a preset name "
                                f"({', '.join(PRESETS)}) or an IMU spec .toml file, found {value!r}")
    try:
        return load_spec(value if value in PRESETS else str(near(value, src)))
    except ValueError as exc:  # the IMU file's own message, after the field that names it
        raise fields.FieldError(f"{fields.where(src, label)}: {str(exc).splitlines()[0]}") from None


def near(path, src):
    """``path`` as written in the file ``src``: relative to that file's folder when ``src`` is an existing file and
    ``path`` is relative, else as it is."""
    p, home = Path(path).expanduser(), Path(str(src))
    return home.parent / p if not p.is_absolute() and home.is_file() else p
