"""Rolling torquing schemes as data, the commanded path, the torque commands and the roll phases as figure events
(:mod:`baselines.rolling` module notes)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from fusionbench.simulation import earth, units

from .model import _check_dcm

# --------------------------------------------------------------------------------------------------
# torquing schemes


class Segment(NamedTuple):
    """One rotation of the platform relative to n: ENU unit ``axis``, ``rate`` (rad/s), ``duration`` (s)."""

    axis: tuple
    rate: float
    duration: float


def _multiple(a, b, tol=1e-9):
    """Whole number a / b (int) if a is a whole multiple of b, else None."""
    k = round(a / b)
    return int(k) if k >= 1 and abs(a - k * b) <= tol * max(abs(a), 1.0) else None


@dataclass(frozen=True)
class Scheme:
    """A rolling torquing scheme as data.

    Parameters
    ----------
    segments : tuple of Segment or (axis, rate, duration) tuples
        Rotations relative to n, one after the other: ``axis`` an ENU unit vector, ``rate`` in rad/s
        (0 holds the platform still), ``duration`` in s, a whole number of command periods.
    command_period_s : float
        Torque command period, s (each command is held over one period).
    sample_s : float
        Integration and gyro-noise sample interval, s; divides ``filter_s``.
    filter_s : float
        Output (filter) interval, s; divides ``command_period_s``.
    """

    segments: tuple
    command_period_s: float = 1.0
    sample_s: float = 0.002
    filter_s: float = 0.2
    _starts: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        for name in ("command_period_s", "sample_s", "filter_s"):
            v = getattr(self, name)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"{name}: expected a positive number of seconds, found {v!r}") from None
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"{name}: expected a positive number of seconds, found {v!r}")
            object.__setattr__(self, name, v)
        if _multiple(self.filter_s, self.sample_s) is None:
            raise ValueError(f"sample_s: expected a whole fraction of filter_s = {self.filter_s} s, "
                             f"found {self.sample_s} s")
        if _multiple(self.command_period_s, self.sample_s) is None:
            raise ValueError(f"sample_s: expected a whole fraction of command_period_s = {self.command_period_s} s, "
                             f"found {self.sample_s} s")
        if _multiple(self.command_period_s, self.filter_s) is None:
            raise ValueError(f"filter_s: expected a whole fraction of command_period_s = {self.command_period_s} s "
                             f"(each filter step under one command), found {self.filter_s} s")
        segs = self.segments
        if isinstance(segs, Segment) or not isinstance(segs, (tuple, list)) or len(segs) == 0:
            raise ValueError(f"segments: expected a non-empty tuple of (axis, rate, duration), found {segs!r}")
        out = []
        for i, s in enumerate(segs):
            try:
                axis, rate, duration = s
            except (TypeError, ValueError):
                raise ValueError(f"segments[{i}]: expected (axis, rate, duration), found {s!r}") from None
            u = np.asarray(axis, dtype=float)
            if u.shape != (3,) or not np.all(np.isfinite(u)) or abs(np.linalg.norm(u) - 1.0) > 1e-6:
                raise ValueError(f"segments[{i}].axis: expected an ENU unit vector (3 values, norm 1), found {axis!r}")
            rate = float(rate)
            if not np.isfinite(rate):
                raise ValueError(f"segments[{i}].rate: expected a finite rate in rad/s, found {rate}")
            duration = float(duration)
            if not np.isfinite(duration) or duration <= 0 or _multiple(duration, self.command_period_s) is None:
                raise ValueError(f"segments[{i}].duration: expected a positive whole number of command periods "
                                 f"({self.command_period_s} s), found {duration} s")
            u = u / np.linalg.norm(u)
            out.append(Segment(tuple(float(x) for x in u), rate, duration))
        object.__setattr__(self, "segments", tuple(out))
        object.__setattr__(self, "_starts", np.concatenate([[0.0], np.cumsum([s.duration for s in out])]))

    @property
    def duration(self) -> float:
        """Total duration, s."""
        return float(self._starts[-1])

    @property
    def samples_per_command(self) -> int:
        return _multiple(self.command_period_s, self.sample_s)

    @property
    def samples_per_filter(self) -> int:
        return _multiple(self.filter_s, self.sample_s)

    @property
    def n_commands(self) -> int:
        """Number of command periods."""
        return int(round(self.duration / self.command_period_s))

    @property
    def n_samples(self) -> int:
        """Number of integration samples."""
        return self.n_commands * self.samples_per_command

    @property
    def n_outputs(self) -> int:
        """Number of filter outputs (at ``k filter_s``, k = 1 .. n_outputs)."""
        return self.n_samples // self.samples_per_filter

    def segment_index(self, t):
        """Index of the segment in force at time(s) ``t`` (s); the last one from its start onwards."""
        t = np.asarray(t, dtype=float)
        return np.clip(np.searchsorted(self._starts, t, side="right") - 1, 0, len(self.segments) - 1)


#: Named ENU unit axes, as a scenario's scheme segment may give them (``axis = "south"``).
AXES = {"east": (1.0, 0.0, 0.0), "west": (-1.0, 0.0, 0.0), "north": (0.0, 1.0, 0.0), "south": (0.0, -1.0, 0.0),
        "up": (0.0, 0.0, 1.0), "down": (0.0, 0.0, -1.0)}
_SOUTH = AXES["south"]
_EAST = AXES["east"]
_R = 0.1 * units.DEG
#: Seed 002's (Ding, rolling-platform self-calibration) scheme: 0.1 deg/s about south 1800 s, east 900 s, south 1800 s,
#: east 900 s.
PAPER_SCHEME = Scheme(((_SOUTH, _R, 1800.0), (_EAST, _R, 900.0), (_SOUTH, _R, 1800.0), (_EAST, _R, 900.0)))


def _check_scheme(scheme):
    if not isinstance(scheme, Scheme):
        raise ValueError(f"scheme: expected a Scheme, found {type(scheme).__name__}")
    return scheme


def _segment_starts(scheme, C0):
    """Commanded attitude at the start of each segment and at the end, ``(..., nseg + 1, 3, 3)``."""
    mats = [C0]
    for s in scheme.segments:
        R = Rotation.from_rotvec(np.asarray(s.axis) * s.rate * s.duration).as_matrix()
        mats.append(R @ mats[-1])
    return np.stack(mats, axis=-3)


def commanded_path(scheme, C0, t):
    """The commanded attitude ``C_path(t)`` (p to ENU) of a scheme from the initial attitude ``C0``.

    Parameters
    ----------
    scheme : Scheme
    C0 : array_like, shape (..., 3, 3)
        Initial attitude ``C_pn`` at t = 0.
    t : array_like, shape (m,)
        Times, s (>= 0; after the scheme's end the attitude holds its final value relative to n).

    Returns
    -------
    ndarray, shape (..., m, 3, 3)
        ``Rot_n(u, r (t - t_seg)) @ C_path(t_seg)``.
    """
    scheme = _check_scheme(scheme)
    C0 = _check_dcm(C0, "C0")
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)) or np.any(t < 0):
        raise ValueError(f"t: expected a 1-D array of times >= 0 s, found shape {t.shape}")
    starts = _segment_starts(scheme, C0)
    idx = scheme.segment_index(t)
    axes = np.array([s.axis for s in scheme.segments])[idx]
    rates = np.array([s.rate for s in scheme.segments])[idx]
    durs = np.array([s.duration for s in scheme.segments])[idx]
    tau = np.minimum(t - scheme._starts[idx], durs)
    R = Rotation.from_rotvec(axes * (rates * tau)[:, None]).as_matrix()
    return R @ starts[..., idx, :, :]


def commands(scheme, C0, lat):
    """Torque commands ``w_cmd^p`` (rad/s), one per command period, to follow the scheme.

    ``w_cmd^p = C_path(t_mid)^T (w_ie^n + r u)`` at the period's middle ``t_mid``.

    Parameters
    ----------
    scheme : Scheme
    C0 : array_like, shape (..., 3, 3)
        Initial attitude.
    lat : float
        Latitude, rad.

    Returns
    -------
    ndarray, shape (..., n_commands, 3)
    """
    scheme = _check_scheme(scheme)
    earth.check_latitude(lat, "lat")
    t_mid = (np.arange(scheme.n_commands) + 0.5) * scheme.command_period_s
    C = commanded_path(scheme, C0, t_mid)
    idx = scheme.segment_index(t_mid)
    ru = np.array([np.asarray(s.axis) * s.rate for s in scheme.segments])[idx]
    w_n = earth.earth_rate_n(float(lat)) + ru
    return np.einsum("...kji,kj->...ki", C, w_n)


def scheme_events(scheme):
    """The roll phases of a scheme as unshaded spans (:class:`fusionbench.reports.figure_events.Event`), named by
    their axis."""
    from fusionbench.reports.figure_events import Event  # only when a figure is drawn

    names = {v: k for k, v in AXES.items()}
    ev, t = [], 0.0
    for seg in scheme.segments:
        ev.append(Event(t, t + seg.duration, f"roll about {names.get(tuple(seg.axis), str(tuple(seg.axis)))}",
                        shade=False))
        t += seg.duration
    return ev
