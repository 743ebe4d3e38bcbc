"""Aiding: what a receiver beside the IMU measures, at its own epochs (GNSS velocity and position, an odometer's or
a log's velocity, zero-velocity periods).

An :class:`Aiding` holds rows stamped on the IMU file's clock, not on the IMU's sample grid: velocity over the earth
(ENU, m/s), position (latitude and longitude in rad, height in m), or both, of the **antenna** (the point the
receiver measures), each row with an optional standard deviation; the lever arm from the IMU to the antenna (body
frame RFU, m); and the receiver's latency (s). Conventions:

* **Time of validity.** A row stamped ``t`` measures the antenna at ``t - delay`` (:attr:`Aiding.t_valid`); a method
  uses it there (an estimate labelled ``t`` uses the rows valid up to ``t``).
* **Lever arm.** With ``l`` the lever arm (body RFU, m), the antenna moves with
  ``v_ant = v + C_bn (omega_nb^b x l)`` and sits at ``p_ant = p + C_bn l`` (ENU;
  :func:`fusionbench.simulation.aiding_geometry.lever_velocity`,
  :func:`~fusionbench.simulation.aiding_geometry.lever_offset`).
* **Rows at rest.** ``at_rest`` marks rows where the base is known to be at rest (a car at a light, a ship at its
  mooring, a static bench): the IMU's velocity is zero there, whatever the lever arm; their ``velocity`` is the
  zero (or a noisy zero) it reports.
* **Missing values.** NaN in a row's velocity or position means "not measured in this row" (NMEA VTG gives no
  vertical velocity, a 10-Hz velocity and a 1-Hz position merged give velocity-only rows); gaps (outages) are
  missing rows.
* **Runs.** ``velocity`` and ``position`` are (K, 3) for one recording or (R, K, 3) for R Monte Carlo recordings
  (the simulator's per-run noise) on the same epochs.

The per-increment array of earlier versions (``vref``, (R, M, 3) at the increment ends) is
:meth:`Aiding.from_vref`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from fusionbench.simulation.aiding_geometry import enu_offset

#: Largest speed an aiding row may report, m/s (a unit error beyond it: km/h or knots read as m/s are well below).
MAX_SPEED_MPS = 2000.0
#: Largest lever arm, m (a ship's mast; beyond it a unit error).
MAX_LEVER_ARM_M = 200.0
#: Largest receiver latency, s (a clock offset belongs in the rows' times, not here).
MAX_DELAY_S = 10.0
#: A per-increment reference whose horizontal speeds stay below this, m/s, is a fixed base's (a moored ship's
#: drift, a reference's noise) unless said otherwise (:meth:`Aiding.from_vref`).
AT_REST_MPS = 0.5
#: Rows may lie this far outside the IMU record, as a fraction of the IMU sample interval (rounding of the stamps).
EDGE_TOLERANCE = 1e-6


@dataclass
class Aiding:
    """Aiding measurements at a receiver's epochs (module docstring).

    Parameters
    ----------
    t : ndarray, shape (K,)
        Time stamps of the rows on the IMU file's clock, s, strictly increasing.
    velocity : ndarray, shape (K, 3) or (R, K, 3), optional
        Velocity of the antenna over the earth, ENU, m/s; NaN where a row does not measure it.
    position : ndarray, shape (K, 3) or (R, K, 3), optional
        Position of the antenna: geodetic latitude (rad), longitude (rad), height above the ellipsoid (m); NaN
        where a row does not measure it.
    sigma_v : ndarray, shape (K, 3), optional
        Standard deviation of each velocity row, ENU, m/s; None: the method's own figure (its ``vref_sigma``).
    sigma_p : ndarray, shape (K, 3), optional
        Standard deviation of each position row, ENU, m; None: the method's own figure.
    lever_arm : (3,) array_like
        From the IMU to the antenna, body frame RFU, m.
    delay : float
        The receiver's latency, s: a row stamped t measures the antenna at t - delay.
    at_rest : ndarray of bool, shape (K,), optional
        Rows at which the base is known to be at rest (zero velocity of the IMU).
    source : str
        What the rows came from (a file name), for messages.
    """

    t: np.ndarray
    velocity: np.ndarray | None = None
    position: np.ndarray | None = None
    sigma_v: np.ndarray | None = None
    sigma_p: np.ndarray | None = None
    lever_arm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    delay: float = 0.0
    at_rest: np.ndarray | None = None
    source: str = "aiding"

    def __post_init__(self):
        who = self.source
        self.t = _real(self.t, f"{who} t")
        if self.t.ndim != 1 or self.t.size < 1:
            raise ValueError(f"{who} t: expected a 1-D array of at least one time in s, found shape {self.t.shape}")
        bad = np.flatnonzero(~np.isfinite(self.t))
        if bad.size:
            raise ValueError(f"{who} t: expected finite times, found {self.t[bad[0]]} at row {bad[0]}")
        bad = np.flatnonzero(np.diff(self.t) <= 0)
        if bad.size:
            k = int(bad[0]) + 1
            raise ValueError(f"{who} t: expected strictly increasing times, found {self.t[k]:.10g} s at row {k} after "
                             f"{self.t[k - 1]:.10g} s")
        K = self.t.size
        if self.velocity is None and self.position is None and self.at_rest is None:
            raise ValueError(f"{who}: expected velocity, position or rows at rest, found none")
        self.velocity = _rows(self.velocity, K, f"{who} velocity")
        self.position = _rows(self.position, K, f"{who} position")
        if self.velocity is not None:
            big = np.abs(self.velocity) > MAX_SPEED_MPS
            if big.any():
                k = int(np.argwhere(big)[0][-2])
                raise ValueError(f"{who} velocity: expected m/s below {MAX_SPEED_MPS:g}, found "
                                 f"{np.abs(self.velocity[..., k, :]).max():.6g} at row {k} (km/h or knots?)")
        if self.position is not None:
            lat, lon, h = (self.position[..., i] for i in range(3))
            for name, x, lim, unit in (("latitude", lat, np.pi / 2, "rad"), ("longitude", lon, 2 * np.pi, "rad"),
                                       ("height", h, 1e5, "m")):
                out = np.abs(np.nan_to_num(x)) > lim
                if out.any():
                    k = int(np.argwhere(out)[0][-1])
                    shown = np.degrees(x[..., k]) if unit == "rad" else x[..., k]
                    raise ValueError(f"{who} position: expected a {name} within +-{np.degrees(lim) if unit == 'rad' else lim:g} "
                                     f"{'deg' if unit == 'rad' else unit}, found {np.ravel(shown)[0]:.6g} at row {k}")
        for name in ("sigma_v", "sigma_p"):
            val = getattr(self, name)
            if val is None:
                continue
            val = _real(val, f"{who} {name}")
            if val.ndim == 0 or val.shape == (K,):  # one figure for all rows, or one per row for every axis
                val = np.broadcast_to(val.reshape(-1, 1), (K, 3)).copy()
            if val.shape != (K, 3):
                raise ValueError(f"{who} {name}: expected one standard deviation per row (({K},) or ({K}, 3)), found "
                                 f"shape {val.shape}")
            bad = np.argwhere(~(np.isfinite(val) & (val > 0)))
            if bad.size:
                raise ValueError(f"{who} {name}: expected positive finite standard deviations, found "
                                 f"{val[tuple(bad[0])]} at row {bad[0][0]}")
            setattr(self, name, val)
        self.lever_arm = _real(self.lever_arm, f"{who} lever arm")
        if self.lever_arm.shape != (3,) or not np.all(np.isfinite(self.lever_arm)):
            raise ValueError(f"{who} lever arm: expected three finite numbers X,Y,Z in m (body right, front, up), found "
                             f"{np.ravel(self.lever_arm).tolist()}")
        if np.linalg.norm(self.lever_arm) > MAX_LEVER_ARM_M:
            raise ValueError(f"{who} lever arm: expected at most {MAX_LEVER_ARM_M:g} m, found "
                             f"{np.linalg.norm(self.lever_arm):.6g} m (mm or cm read as m?)")
        if not (isinstance(self.delay, (int, float, np.floating)) and np.isfinite(self.delay)
                and abs(self.delay) <= MAX_DELAY_S):
            raise ValueError(f"{who} delay: expected a latency in s within +-{MAX_DELAY_S:g}, found {self.delay!r}")
        self.delay = float(self.delay)
        if self.at_rest is not None:
            rest = np.asarray(self.at_rest)
            if rest.shape != (K,) or rest.dtype.kind not in "bui":
                raise ValueError(f"{who} at_rest: expected {K} flags, found shape {rest.shape} of {rest.dtype}")
            self.at_rest = rest.astype(bool)
        runs = {a.shape[0] for a in (self.velocity, self.position) if a is not None and a.ndim == 3}
        if len(runs) > 1:
            raise ValueError(f"{who}: expected velocity and position for the same number of runs, found {sorted(runs)}")
        if not self.measures.any():
            raise ValueError(f"{who}: expected at least one row with a measurement, found only NaN")

    # ------------------------------------------------------------------------------------------ what it holds
    @property
    def t_valid(self):
        """Time each row measures (its stamp less the latency), s, (K,)."""
        return self.t - self.delay

    @property
    def runs(self) -> int | None:
        """Number of recordings the rows are drawn for (None: the same rows for every recording)."""
        for a in (self.velocity, self.position):
            if a is not None and a.ndim == 3:
                return a.shape[0]
        return None

    @property
    def has_velocity(self) -> bool:
        """Whether some row measures a horizontal velocity (or says the base is at rest)."""
        return bool(self.velocity_rows().any())

    @property
    def has_position(self) -> bool:
        """Whether some row measures the horizontal position."""
        return bool(self.position_rows().any())

    @property
    def measures(self):
        """Rows (K,) that measure something."""
        return self.velocity_rows() | self.position_rows()

    def velocity_rows(self):
        """Rows (K,) with a horizontal velocity (finite east and north in every run) or at rest."""
        ok = np.zeros(self.t.size, bool)
        if self.velocity is not None:
            ok |= np.all(np.isfinite(self.velocity[..., :2]), axis=(-1,) if self.velocity.ndim == 2 else (0, -1))
        if self.at_rest is not None:
            ok |= self.at_rest
        return ok

    def position_rows(self):
        """Rows (K,) with a horizontal position (finite latitude and longitude in every run)."""
        if self.position is None:
            return np.zeros(self.t.size, bool)
        return np.all(np.isfinite(self.position[..., :2]), axis=(-1,) if self.position.ndim == 2 else (0, -1))

    def is_at_rest(self) -> bool:
        """Whether every row says the base is at rest (and none measures a position): a fixed base's reference."""
        return self.at_rest is not None and bool(self.at_rest.all()) and not self.has_position

    def rate_hz(self) -> float:
        """Median rate of the rows, Hz (rows per second; inf for a single row)."""
        return 1.0 / float(np.median(np.diff(self.t))) if self.t.size > 1 else np.inf

    def longest_gap(self, t0, t1) -> float:
        """Longest time without a measuring row between ``t0`` and ``t1`` (s, valid times), s."""
        tv = self.t_valid[self.measures]
        edges = np.concatenate([[t0], tv[(tv > t0) & (tv < t1)], [t1]])
        return float(np.max(np.diff(edges)))

    # ------------------------------------------------------------------------------------------ conversions
    @classmethod
    def from_vref(cls, t_end, vref, at_rest=None, source="vref"):
        """The per-increment reference of earlier versions as rows: ``vref`` (R, M, 3) or (M, 3), ENU m/s, at the
        increment ends ``t_end`` (M,) s (``imu.increments()[0]``); no lever arm, no delay, no sigma (the method's
        own). ``at_rest``: a fixed base's zero-velocity reference (with its noise); None: when no speed reaches
        :data:`AT_REST_MPS` (the methods check the IMU record for motion whenever the rows say the base is at
        rest)."""
        vref = _real(vref, source)
        t_end = _real(t_end, f"{source} t")
        if vref.ndim not in (2, 3) or vref.shape[-2:] != (t_end.size, 3):
            raise ValueError(f"{source}: expected shape (runs, {t_end.size}, 3) or ({t_end.size}, 3) (runs, increments, "
                             f"ENU), found {vref.shape}")
        if not np.isfinite(vref).all():
            raise ValueError(f"{source}: expected finite velocities, found NaN or inf")
        if at_rest is None:
            at_rest = bool(np.max(np.abs(vref[..., :2]), initial=0.0) < AT_REST_MPS)
        return cls(t_end, velocity=vref, at_rest=np.full(t_end.size, True) if at_rest else None, source=source)

    def for_runs(self, runs: int) -> Aiding:
        """These rows for ``runs`` recordings: arrays (R, K, 3), broadcast when the rows are the same for all."""
        have = self.runs
        if have is not None and have != runs:
            raise ValueError(f"{self.source}: expected rows for {runs} recordings, found {have}")

        def widen(a):
            return None if a is None else np.broadcast_to(a, (runs,) + a.shape[-2:]).copy() if a.ndim == 2 else a
        return replace(self, velocity=widen(self.velocity), position=widen(self.position))

    def select_runs(self, idx) -> Aiding:
        """The rows of recordings ``idx`` (an index array or slice); rows shared by all recordings stay shared."""
        def pick(a):
            return a if a is None or a.ndim == 2 else a[idx]
        return replace(self, velocity=pick(self.velocity), position=pick(self.position))

    def window(self, t_from, t_to) -> Aiding | None:
        """The rows valid in ``(t_from, t_to]`` (s), or None when there are none."""
        tv = self.t_valid
        sel = (tv > t_from) & (tv <= t_to)
        if not sel.any():
            return None
        return self.rows(sel)

    def rows(self, sel) -> Aiding:
        """The rows ``sel`` (a boolean mask or index array over the K rows)."""
        def take(a, axis):
            return None if a is None else np.take(a, np.flatnonzero(sel) if np.asarray(sel).dtype == bool else sel,
                                                  axis=axis)
        return replace(self, t=take(self.t, 0), velocity=take(self.velocity, -2), position=take(self.position, -2),
                       sigma_v=take(self.sigma_v, 0), sigma_p=take(self.sigma_p, 0), at_rest=take(self.at_rest, 0))

    def dense_velocity(self, t_end, runs):
        """The velocity (R, M, 3), ENU m/s, at the increment ends ``t_end`` (M,) s when the rows are exactly there
        (the per-increment reference), else None; rows at rest without a velocity are zero."""
        if self.t.size != np.size(t_end) or self.position is not None:
            return None
        dt = (t_end[-1] - t_end[0]) / max(t_end.size - 1, 1)
        if np.max(np.abs(self.t_valid - t_end)) > EDGE_TOLERANCE * dt:
            return None
        v = np.zeros((runs, self.t.size, 3)) if self.velocity is None else self.for_runs(runs).velocity
        if not np.isfinite(v).all():
            return None
        return v

    def check_record(self, t0, t_last, dt, name="method"):
        """Raise ValueError (one line naming ``name`` and the row) unless every row is valid inside the IMU record,
        from its initial state ``t0`` to its last sample ``t_last`` (s; ``dt`` the sample interval)."""
        tv = self.t_valid
        tol = EDGE_TOLERANCE * dt
        for k, what, bad in ((0, "before", tv < t0 - tol), (-1, "after", tv > t_last + tol)):
            if bad.any():
                i = int(np.flatnonzero(bad)[k])
                lag = f" (stamped {self.t[i]:.6f} s, latency {self.delay:g} s)" if self.delay else ""
                raise ValueError(f"{name}: {self.source}: row {i} is valid at {tv[i]:.6f} s{lag}, {what} the IMU record "
                                 f"({t0:.6f} to {t_last:.6f} s): expected rows inside the record (trim the file, or "
                                 f"put its times on the IMU's clock)")

    def velocities_from_positions(self) -> Aiding | None:
        """Velocity rows from consecutive position rows: the difference of two positions over their interval, at its
        middle (ENU, m/s; sigma from the positions' when they have one), for methods that read a velocity. Pairs
        further apart than 1.5 times the median interval (an outage) are not differenced. None without two
        consecutive positions. Keeps the lever arm and the delay (the antenna's velocity)."""
        rows = np.flatnonzero(self.position_rows())
        if rows.size < 2:
            return None
        tv = self.t_valid[rows]
        dt = np.diff(tv)
        ok = dt <= 1.5 * np.median(dt)
        if not ok.any():
            return None
        p = self.position[..., rows, :]
        a, b = p[..., :-1, :][..., ok, :], p[..., 1:, :][..., ok, :]
        d = enu_offset(b, a) / dt[ok][:, None]
        if not np.all(np.isfinite(d[..., 2])):
            d[..., 2] = np.nan
        sig = None
        if self.sigma_p is not None:
            s = self.sigma_p[rows]
            sig = np.hypot(s[:-1][ok], s[1:][ok]) / dt[ok][:, None]
        mid = 0.5 * (tv[:-1] + tv[1:])[ok] + self.delay
        return Aiding(mid, velocity=d, sigma_v=sig, lever_arm=self.lever_arm, delay=self.delay,
                      source=f"{self.source} (differenced positions)")


def _real(x, what):
    a = np.asarray(x)
    if a.dtype.kind not in "iuf":
        raise ValueError(f"{what}: expected real numbers, found {a.dtype} values")
    return a.astype(float, copy=False)


def _rows(a, K, what):
    """A (K, 3) or (R, K, 3) array of rows, no inf (NaN: not measured)."""
    if a is None:
        return None
    a = _real(a, what)
    if a.ndim not in (2, 3) or a.shape[-2:] != (K, 3):
        raise ValueError(f"{what}: expected shape ({K}, 3) or (runs, {K}, 3), found {a.shape}")
    if np.isinf(a).any():
        k = int(np.argwhere(np.isinf(a))[0][-2])
        raise ValueError(f"{what}: expected finite values (NaN where not measured), found inf at row {k}")
    return a
