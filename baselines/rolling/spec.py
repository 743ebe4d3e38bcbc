"""A platform-rolling scenario's ``[platform]`` table (:func:`parse_platform`: the rolling scheme, the distribution
of the true error coefficients and initial attitude, the sensor noise) and the truth of each Monte Carlo run
(:func:`draw_truth`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fusionbench.simulation import units

from . import model
from .scheme import AXES, Scheme, Segment

#: Coefficient groups by the names a ``[platform]`` table gives them (``coeff_mean = {D0 = 1.0, ...}``).
GROUP_KEYS = {"D0": model.D0, "D1": model.D1, "D2": model.D2, "GYRO_MOUNT": model.GYRO_MOUNT, "K0": model.K0,
              "K1": model.K1, "K2": model.K2, "ACCEL_MOUNT": model.ACCEL_MOUNT, "KT": model.KT}
PLATFORM_KEYS = {"scheme", "initial_angles_deg", "initial_angles_sigma_deg", "coeff_mean", "coeff_sigma",
                 "gyro_noise_dph", "accel_noise_ug", "readout_s"}


@dataclass(frozen=True)
class PlatformSpec:
    """A validated ``[platform]`` table (SI inside).

    Attributes
    ----------
    scheme : baselines.rolling.scheme.Scheme
    angles_mean, angles_sigma : ndarray, shape (3,)
        Initial attitude angles [phi, theta, psi] (rad) and their spread.
    coeff_mean, coeff_sigma : ndarray, shape (42,)
        True-coefficient distribution, SI.
    gyro_noise, accel_noise : float
        Gyro white drift per 2-ms sample (rad/s) and accelerometer noise per output (m/s^2).
    readout_s : float
        The estimate is averaged over the last ``readout_s`` seconds (the paper: 100 s).
    """

    scheme: Scheme
    angles_mean: np.ndarray
    angles_sigma: np.ndarray
    coeff_mean: np.ndarray
    coeff_sigma: np.ndarray
    gyro_noise: float
    accel_noise: float
    readout_s: float = 100.0
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    def scaled(self, duration):
        """The same spec with the scheme's segments shortened in proportion to last ``duration`` s
        (whole command periods; for ``--quick``)."""
        full = sum(s.duration for s in self.scheme.segments)
        if duration >= full:
            return self
        per = self.scheme.command_period_s
        segs = tuple(Segment(s.axis, s.rate, max(per, round(s.duration * duration / full / per) * per))
                     for s in self.scheme.segments)
        sch = Scheme(segs, self.scheme.command_period_s, self.scheme.sample_s, self.scheme.filter_s)
        return PlatformSpec(sch, self.angles_mean, self.angles_sigma, self.coeff_mean, self.coeff_sigma,
                            self.gyro_noise, self.accel_noise, min(self.readout_s, duration / 10), self.raw)


def parse_platform(d, where):
    """Validate a ``[platform]`` table; ScenarioError-style ValueError naming ``where`` and the field.

    Format (customary units)::

        [platform]
        scheme = [{axis = "south", rate_dps = 0.1, duration_s = 1800.0}, ...]   # axis: a name or [E, N, U]
        initial_angles_deg = [2.0, 3.0, 5.0]          # [phi, theta, psi] of baselines.rolling
        initial_angles_sigma_deg = [0.1, 0.1, 0.1]
        coeff_mean = {D0 = 1.0, GYRO_MOUNT = 120.0, K0 = 400.0, ...}   # per group (or a list per coefficient)
        coeff_sigma = {D0 = 0.2, ...}
        gyro_noise_dph = 0.05
        accel_noise_ug = 1.0
        readout_s = 100.0
    """
    def err(key, expected, found):
        return ValueError(f"{where}: field 'platform.{key}': expected {expected}, found {found!r}")

    bad = set(d) - PLATFORM_KEYS
    if bad:
        raise err(sorted(bad)[0], f"one of {sorted(PLATFORM_KEYS)}", sorted(bad)[0])
    segs = []
    for i, s in enumerate(d.get("scheme", [])):
        if not isinstance(s, dict) or set(s) != {"axis", "rate_dps", "duration_s"}:
            raise err(f"scheme[{i}]", "a table with axis, rate_dps and duration_s", s)
        axis = AXES.get(s["axis"]) if isinstance(s["axis"], str) else s["axis"]
        if axis is None or not isinstance(axis, (list, tuple)) or len(axis) != 3:
            raise err(f"scheme[{i}].axis", f"one of {sorted(AXES)} or [E, N, U]", s["axis"])
        segs.append(Segment(tuple(float(a) for a in axis), np.radians(float(s["rate_dps"])), float(s["duration_s"])))
    if not segs:
        raise err("scheme", "at least one segment", d.get("scheme"))
    try:
        scheme = Scheme(tuple(segs))
    except ValueError as exc:
        raise ValueError(f"{where}: field 'platform.scheme': {exc}") from None

    def vec3(key, default):
        v = d.get(key, default)
        if not isinstance(v, list) or len(v) != 3 or not all(isinstance(x, (int, float)) for x in v):
            raise err(key, "3 numbers", v)
        return np.radians(np.array(v, dtype=float))

    def coeffs(key):
        out = np.zeros(model.N_COEFFS)
        table = d.get(key, {})
        if not isinstance(table, dict):
            raise err(key, "a table of group = value or [values]", table)
        for name, val in table.items():
            sl = GROUP_KEYS.get(name)
            if sl is None:
                raise err(f"{key}.{name}", f"one of {sorted(GROUP_KEYS)}", name)
            n = sl.stop - sl.start
            vals = np.broadcast_to(np.asarray(val, dtype=float), (n,)) if np.ndim(val) == 0 or len(val) == n else None
            if vals is None or not np.all(np.isfinite(vals)):
                raise err(f"{key}.{name}", f"a number or {n} numbers", val)
            out[sl] = vals
        return out * model.COEFF_SCALE

    def num(key, default, lo=0.0):
        v = d.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < lo:
            raise err(key, f"a number >= {lo}", v)
        return float(v)

    sig = coeffs("coeff_sigma")
    if np.any(sig < 0):
        raise err("coeff_sigma", "non-negative values", d.get("coeff_sigma"))
    return PlatformSpec(scheme, vec3("initial_angles_deg", [0.0, 0.0, 0.0]), vec3("initial_angles_sigma_deg", [0.0] * 3),
                        coeffs("coeff_mean"), sig, num("gyro_noise_dph", 0.05) * units.DEG_PER_H,
                        num("accel_noise_ug", 1.0) * units.UG, num("readout_s", 100.0, lo=0.2), dict(d))


def draw_truth(spec: PlatformSpec, seed, k):
    """True coefficients (42, SI) and initial angles (3, rad) of run ``k``: depend on (seed, k) only."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(k), 2002]))
    c = spec.coeff_mean + spec.coeff_sigma * rng.standard_normal(model.N_COEFFS)
    a = spec.angles_mean + spec.angles_sigma * rng.standard_normal(3)
    return c, a
