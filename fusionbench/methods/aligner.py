"""The Aligner protocol, the AlignmentResult every method returns, and building a method (discovery itself:
:mod:`fusionbench.methods.discovery`, re-exported here).

A method is a class with a ``name``, a one-line ``description`` and
``align(imu, site, vref=None, init=None, aiding=None) -> AlignmentResult``. Methods are found by name in
the entry-point group ``fusionbench.methods`` (the project's own families are registered there
in pyproject.toml like any plug-in; the core never imports them), or given as a
``module:Class`` path, so a user's own aligner runs in ``fusionbench run`` without packaging.

A method never sees truth: it gets the IMU data, the site, optional aiding
(:class:`fusionbench.simulation.aiding.Aiding`: velocity and/or position rows at a receiver's epochs, with lever arm
and latency; ``vref``, a velocity at every increment end, is its older form) and an optional initial attitude guess.

Time rule (every method, every kind of input)
---------------------------------------------
An :class:`AlignmentResult`'s attitude at ``t[i]`` is the estimate that uses the samples up to and
including ``t[i]`` and no later one, and is the attitude *at* ``t[i]``; its last entry is at the last
sample of the input, ``imu.increments()[0][-1]`` (= ``imu.t[-1]``). Rate samples (CSV, NPZ) are
instantaneous at their ``t``; increments (the simulator, PSINS ``.imu``) cover ``(t - dt, t]``, so an
increment's information belongs to its end time. A method that steps a loop or filter every few
samples integrates the samples after its last step with the strapdown, so the result still ends at the
last sample. :func:`check_time_rule` checks what it can of this (the runner and the command line call
it on every result); ``tests/test_timing.py`` checks the rest against truth, to one sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from fusionbench.methods.discovery import (METHODS_GROUP, available_methods, entry_class, load_entry,  # noqa: F401
                                           takes_option, unknown_option, uses_noise_model, variant)
from fusionbench.simulation import earth
from fusionbench.simulation.imudata import IMUData



@dataclass(frozen=True)
class Site:
    """Where the alignment happens.

    Parameters
    ----------
    lat : float
        Geodetic latitude, rad.
    lon : float
        Longitude, rad.
    h : float
        Height above the ellipsoid, m.
    """

    lat: float
    lon: float = 0.0
    h: float = 0.0

    def __post_init__(self):
        earth.check_latitude(self.lat, "site latitude")
        if not np.isfinite(self.lon) or abs(self.lon) > 2 * np.pi:
            raise ValueError(f"site longitude: expected a longitude between -360 and 360 deg, found "
                             f"{np.degrees(self.lon):g} deg")
        if not np.isfinite(self.h) or abs(self.h) > 1e5:
            raise ValueError(f"site height: expected a height between -100 and 100 km in m, found {self.h}")

    @classmethod
    def from_degrees(cls, lat_deg, lon_deg=0.0, h=0.0):
        """Site from latitude and longitude in degrees and height in m."""
        if not -90.0 <= float(lat_deg) <= 90.0:  # NaN fails this too
            raise ValueError(f"latitude: expected degrees between -90 and 90, found {lat_deg}")
        if not -360.0 <= float(lon_deg) <= 360.0:
            raise ValueError(f"longitude: expected degrees between -360 and 360, found {lon_deg}")
        return cls(np.radians(float(lat_deg)), np.radians(float(lon_deg)), float(h))

    @property
    def g(self) -> float:
        """Normal gravity at the site, m/s^2."""
        return float(earth.gravity(self.lat, self.h))


@dataclass
class AlignmentResult:
    """What an aligner returns.

    Attributes
    ----------
    method : str
        Method name.
    t : ndarray, shape (M,)
        Times of the attitude history, s, strictly increasing; the last one is the last sample of the
        data (the module's time rule).
    C_bn : ndarray, shape (R, M, 3, 3)
        Estimated attitude history (body RFU to ENU) for each of the R recordings: ``C_bn[:, i]`` is the
        attitude at ``t[i]`` estimated from the samples up to and including ``t[i]`` (for a method that
        is not causal, a smoother, from the whole record: ``causal`` False).
    extra : dict
        Method-specific diagnostics nobody else reads (estimated biases, iteration counts, ...).
    sigma_phi : ndarray, shape (R, M, 3), optional
        The method's own predicted misalignment sigma (E, N, U), rad (filters and smoothers); the runner scores
        its consistency (actual over predicted error at the end).
    series : dict of str to ndarray, shape (R, M), optional
        Other histories the method reports about itself at ``t`` (e.g. a damping coefficient); the report draws
        them, labelled by the method's ``series_labels``.
    figures : dict of str to float, optional
        Scalar figures the method reports about itself; they are written into its metrics.json entry.
    imu_model : str, optional
        Name of the IMU noise model the method assumed (its ``--imu``), for the record.
    causal : bool
        Whether ``C_bn[:, i]`` uses only the samples up to ``t[i]`` (a filter, a loop) or the whole record
        (False: a smoother).
    """

    method: str
    t: np.ndarray
    C_bn: np.ndarray
    extra: dict = field(default_factory=dict)
    sigma_phi: np.ndarray | None = None
    series: dict = field(default_factory=dict)
    figures: dict = field(default_factory=dict)
    imu_model: str | None = None
    causal: bool = True

    def __post_init__(self):
        self.t = np.asarray(self.t, dtype=float)
        self.C_bn = np.asarray(self.C_bn, dtype=float)
        if self.C_bn.ndim != 4 or self.C_bn.shape[1:] != (self.t.size, 3, 3):
            raise ValueError(f"AlignmentResult C_bn: expected shape (runs, {self.t.size}, 3, 3), found {self.C_bn.shape}")
        shape = self.C_bn.shape[:2]
        if self.sigma_phi is not None:
            self.sigma_phi = np.asarray(self.sigma_phi, dtype=float)
            if self.sigma_phi.shape != shape + (3,):
                raise ValueError(f"AlignmentResult sigma_phi: expected shape {shape + (3,)}, found {self.sigma_phi.shape}")
        for key, val in self.series.items():
            if np.shape(val) != shape:
                raise ValueError(f"AlignmentResult series {key!r}: expected shape {shape}, found {np.shape(val)}")
        self.figures = {k: float(v) for k, v in self.figures.items()}

    @property
    def C_bn_final(self):
        """Attitude at the last sample, (R, 3, 3)."""
        return self.C_bn[:, -1]

    @property
    def t_end(self) -> float:
        """Time of the last attitude, s: the last sample of the data."""
        return float(self.t[-1])


def check_time_rule(res: AlignmentResult, imu: IMUData, name: str | None = None):
    """Raise ValueError (one line naming the method) unless ``res`` keeps the time rule on ``imu``.

    Checked: one attitude per recording, finite rotation matrices, strictly increasing times inside the
    data's span, and the last time at the last sample (to a millionth of a sample interval). ``imu`` is an
    :class:`~fusionbench.simulation.imudata.IMUData` or any record with its ``runs``, ``dt``, ``t0`` and ``t_last``
    (s), such as the runner's stream of a long record (:class:`fusionbench.bench.streaming.SimulatedStream`).
    """
    if not isinstance(res, AlignmentResult):
        raise ValueError(f"method {name!r}: align() returned {type(res).__name__}, expected an AlignmentResult")
    who = f"method {name or res.method!r}"
    t_last = imu.t_last
    if res.C_bn.shape[0] != imu.runs:
        raise ValueError(f"{who}: expected an attitude history per recording ({imu.runs}), found {res.C_bn.shape[0]}")
    if res.t.size == 0 or not np.all(np.isfinite(res.t)) or np.any(np.diff(res.t) <= 0):
        raise ValueError(f"{who}: expected strictly increasing finite history times, found {res.t[:5]}...")
    if abs(res.t[-1] - t_last) > 1e-6 * imu.dt:
        raise ValueError(f"{who}: broke the time rule: its last attitude is at {res.t[-1]:.6f} s, the last sample "
                         f"at {t_last:.6f} s")
    if res.t[0] < imu.t0 - 1e-6 * imu.dt:
        raise ValueError(f"{who}: history starts at {res.t[0]:.6f} s, before the data ({imu.t0:.6f} s)")
    if not np.all(np.isfinite(res.C_bn)):
        raise ValueError(f"{who}: returned a non-finite attitude")


@runtime_checkable
class Aligner(Protocol):
    """Protocol of an alignment method (structural: no base class needed; the project's methods implement it on
    :class:`fusionbench.methods.aligner_base.AlignerBase`, which applies one input policy to every method).

    ``min_duration_s`` is the shortest recording the method accepts, s. Optional attributes:
    ``supports`` (a :class:`Supports`: the bases and latitudes it claims; default static and sway up to
    80 deg), for methods that use an IMU noise model, an
    ``imu`` constructor option (:func:`uses_noise_model`), and for the report: ``events(init_given)`` (its own
    stages, e.g. a coarse hand-over, as ``[(t_s, label)]`` or ``[(t0_s, t1_s, label)]``:
    :mod:`fusionbench.reports.figures`), ``series_labels`` (axis labels with units of the result's ``series``) and
    ``report_figures(folder)``. For the runner's speed and memory: ``align_chunks(chunks, site, record, init=None)``
    (and ``_align_chunks``; see :meth:`fusionbench.methods.aligner_base.AlignerBase.align_chunks`), a method that
    works through a long record in consecutive chunks, which the runner then streams to it
    (:mod:`fusionbench.bench.streaming`); ``estimate_only()``, a cheaper copy giving the same attitudes without the
    uncertainty figures, which a smoother's settling on record prefixes uses
    (:func:`fusionbench.bench.runner._prefix_settling`).
    """

    name: str
    description: str
    min_duration_s: float

    def align(self, imu: IMUData, site: Site, vref=None, init=None, aiding=None) -> AlignmentResult:
        """Align a batch of recordings.

        Parameters
        ----------
        imu : IMUData
            R recordings on one time grid, body frame RFU.
        site : Site
            Latitude, longitude, height at the initial state.
        vref : ndarray, shape (R, M, 3), optional
            Reference velocity (ENU, m/s) at the end of each increment interval (``imu.increments()[0]``): the
            per-increment form of ``aiding`` (give one or the other).
        init : ndarray, shape (R, 3, 3) or (3, 3), optional
            Initial attitude guess C_bn; None lets the method initialise itself.
        aiding : fusionbench.simulation.aiding.Aiding, optional
            Velocity and/or position rows at a receiver's epochs, with lever arm and latency; None (and no
            ``vref``): a stationary or swaying base, which the method checks.
        """
        ...


@runtime_checkable
class Navigator(Protocol):
    """Protocol of a navigation method: free-inertial navigation from a given attitude (structural).

    A navigator does not align: it carries an attitude it is given (e.g. an alignment's result) through the
    record, as ``damped-nav`` does. Registered in the ``fusionbench.methods`` group beside the aligners, it
    also has ``align(imu, site, vref=None, init=None)`` for the runner, which needs ``init``, and declares
    ``supports.needs_init`` (:class:`Supports`), so that the conformance matrix leaves it out.
    """

    name: str
    description: str

    def navigate(self, imu: IMUData, site: Site, init, vref=None) -> AlignmentResult:
        """Navigate a batch of recordings from the initial attitude ``init``.

        Parameters
        ----------
        imu : IMUData
            R recordings on one time grid, body frame RFU (x right, y forward, z up): angle (rad) and velocity
            (m/s) increments, or angular rates (rad/s) and specific forces (m/s^2).
        site : Site
            Latitude and longitude (rad) and height (m) at the initial state (``damped-nav`` starts at rest there).
        init : ndarray, shape (R, 3, 3) or (3, 3)
            Initial attitude ``C_bn`` (body RFU to navigation ENU) at the initial state ``imu.t0``.
        vref : ndarray, shape (R, M, 3), optional
            Reference velocity (ENU, m/s) at the end of each increment interval (``imu.increments()[0]``), for a
            navigator that reads one (e.g. an acceleration from a log); None: not given.

        Returns
        -------
        AlignmentResult
            The attitude history ``C_bn`` (R, M, 3, 3), body RFU to ENU, at times ``t`` (M,) s, ending at the
            last sample (the module's time rule).
        """
        ...


def load_method(spec: str, imu=None, vref_sigma=None, **options):
    """Instantiate an alignment method by registered name (named variants included) or ``module:Class`` path.

    Parameters
    ----------
    spec : str
        A name of ``fusionbench list`` or a ``module:Class`` path.
    imu : str, path or IMUSpec, optional
        The IMU noise model given to a method that uses one (:func:`uses_noise_model`) unless ``options``
        name one; ignored by the others.
    vref_sigma : float, optional
        Standard deviation of each velocity-reference sample, m/s, given to a method with a ``vref_sigma`` option
        (the filters: their R) unless ``options`` name one; ignored by the others.
    **options
        Constructor options.

    Raises
    ------
    ValueError
        One line naming the method and what is available, or the option it does not take and those it does.
    """
    cls = entry_class(METHODS_GROUP, spec, "method")
    if not isinstance(cls, type):
        raise ValueError(f"method {spec!r}: expected a class, found {type(cls).__name__}")
    for key, value in (("imu", imu), ("vref_sigma", vref_sigma)):
        if value is not None and key not in options and takes_option(cls, key):
            options[key] = value
    bad, names = unknown_option(cls, options)
    if bad is not None:
        raise ValueError(f"method {spec!r}: option {bad!r}: expected one of {names}")
    obj = cls(**options)
    if not isinstance(obj, Aligner):
        raise ValueError(f"method {spec!r}: expected an object with name, description, min_duration_s and align()")
    return obj


def call_align(method, imu: IMUData, site: Site, aiding=None, init=None) -> AlignmentResult:
    """``method.align`` with ``aiding`` (an :class:`fusionbench.simulation.aiding.Aiding` or None) and ``init``, as
    the runner and the command line call every method: a method whose ``align`` takes no ``aiding`` (a user's aligner
    written for earlier versions) gets the rows as ``vref``, a velocity at every increment end, where they are one (or
    rows at rest: then None), and a one-line refusal naming it otherwise."""
    import inspect

    try:
        takes = "aiding" in inspect.signature(method.align).parameters
    except (TypeError, ValueError):
        takes = False
    if takes or aiding is None:
        return method.align(imu, site, init=init, **({"aiding": aiding} if aiding is not None else {}))
    vref = aiding.dense_velocity(imu.increments()[0], imu.runs)
    if vref is None and not aiding.is_at_rest():
        raise ValueError(f"{getattr(method, 'name', 'method')}: aiding: its align() takes no aiding (only vref, a "
                         f"velocity at every increment end), found {aiding.t.size} rows of {aiding.source}")
    return method.align(imu, site, vref=vref, init=init)
