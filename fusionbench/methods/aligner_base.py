"""The base class of the project's aligners: one input policy for every method, then the method's own work.

:class:`AlignerBase` implements ``align`` of the :class:`fusionbench.methods.aligner.Aligner` protocol as the policy
below followed by the subclass's :meth:`AlignerBase._align`. A subclass declares its limits once, as
attributes, and implements ``_align`` only; it never checks its arguments itself. The protocol stays
structural: a user's own aligner needs no base class (``fusionbench run`` takes any object with ``name``,
``description``, ``min_duration_s`` and ``align``).

The policy, in this order (each refusal a ``ValueError`` of one line naming the method, the field, what was
expected and what was found: ``"kf: site latitude: expected a latitude between -89 and 89 deg, found 89.5 deg"``):

1. **data** (:func:`fusionbench.methods.inputs.check_inputs`): ``imu`` an
   :class:`~fusionbench.simulation.imudata.IMUData` with finite samples; ``init`` of shape (3, 3) or (R, 3, 3), finite
   rotation matrices, broadcast over the R recordings.
2. **aiding** (:class:`fusionbench.simulation.aiding.Aiding`; the per-increment ``vref`` array of earlier versions is
   converted to one, and both at once are refused): rows for R recordings, every row valid inside the record. A method
   that does not consume the aiding of a moving base (:attr:`AlignerBase.uses_aiding` False: the compass loops,
   the analytic coarse alignment) takes only rows at rest (a fixed base's zero-velocity reference).
3. **init** when the method needs one (``supports.needs_init``: a navigator starts from an alignment).
4. **site latitude** within +-:attr:`~AlignerBase.max_latitude_deg`
   (:func:`fusionbench.simulation.earth.check_latitude`).
5. **the IMU model** the method was given (its ``spec``; None: not checked) must leave the azimuth observable at
   the site (:func:`fusionbench.methods.claims.check_azimuth_observable`: a MEMS gyro's bias hides the earth rate).
6. **duration**: at least :attr:`~AlignerBase.min_duration_s` of data (``imu.duration``).
7. **a base that moves**: without aiding of its motion (none, or only rows at rest), an aligner checks that the
   record is of a stationary or swaying base (:func:`fusionbench.methods.motion.check_stationary`) and refuses one that
   moves anywhere in it, naming ``--aiding``.
8. **a given init the method cannot recover from**: a method that declares :attr:`~AlignerBase.init_capture_deg`
   (a linearised fine aligner) checks ``init`` against a coarse solution of the record's first seconds
   (:func:`fusionbench.methods.init_check.check_capture`) and refuses one beyond its capture range, naming ``init``.

What only a method can judge (a step the data's sample interval cannot carry) it checks in ``_align``, with
messages of the same form.

Options are checked when the method is built, from the constructor's own defaults (:func:`check_option`): an
option whose default is a number must be a finite number of that kind (a whole number where the default is
one; None where its annotation allows it), not negative where the default is positive, and positive where
the class lists it in
:attr:`AlignerBase.positive_options` (step sizes, gains, windows: 0 makes no method); a flag must be true or
false. A refusal is one ``ValueError`` naming the method and the option (``"adrc: option h1: expected a
positive number, found -4"``); a scenario's variant adds its ``variants.NAME``.
"""

from __future__ import annotations

import functools
import inspect
import numbers

import numpy as np

from fusionbench.methods import motion
from fusionbench.methods.aligner import AlignmentResult, Site
from fusionbench.methods.claims import check_azimuth_observable, supports
from fusionbench.methods.inputs import check_init, check_inputs
from fusionbench.simulation import earth
from fusionbench.simulation.aiding import Aiding
from fusionbench.simulation.imudata import IMUData


class AlignerBase:
    """An aligner that applies the one input policy (module docstring) before its own :meth:`_align`.

    Attributes
    ----------
    name, description : str
        The method's name and one-line description (required).
    min_duration_s : float
        Shortest record accepted, s (class attribute, or set in ``__init__`` when it depends on the options).
    max_latitude_deg : float
        Highest abs(latitude) accepted, deg (90: any). What the method *claims* (``supports.max_abs_lat_deg``, the
        conditions the conformance matrix runs) may be less: this is where it refuses.
    spec : IMUSpec or None
        The IMU model the method was given (its ``imu`` option); the azimuth observability is checked with it.
    uses_aiding : bool
        Whether the method consumes the aiding of a moving base (velocity or position rows at their epochs, with
        the lever arm and the latency); False: it takes only rows at rest.
    init_capture_deg : float or None
        The largest error of a given initial attitude the method recovers from, deg (a rotation angle); None: any
        (a compass loop, a graph) or it takes none. With a value, a given ``init`` is checked (policy step 8) over
        the method's ``coarse_s`` seconds (60 without one).
    """

    name: str
    description: str
    min_duration_s: float = 0.0
    max_latitude_deg: float = 90.0
    spec = None
    uses_aiding: bool = False
    init_capture_deg = None
    #: Options that must be positive (besides being of their default's kind): the update interval at least.
    positive_options: tuple = ("step_s",)

    def __init_subclass__(cls, **kwargs):
        """Check the options given to a subclass's constructor (:func:`check_option`) before it runs."""
        super().__init_subclass__(**kwargs)
        init = cls.__dict__.get("__init__")
        if init is None:
            return
        sig = inspect.signature(init)

        @functools.wraps(init)
        def checked(self, *args, **kw):
            given = sig.bind_partial(self, *args, **kw).arguments
            for name, value in list(given.items())[1:]:
                param = sig.parameters[name]
                if param.kind in (param.VAR_KEYWORD, param.VAR_POSITIONAL):
                    continue
                if value is None and "None" in str(param.annotation):  # an option the method may switch off
                    continue
                check_option(getattr(type(self), "name", type(self).__name__), name, value, param.default,
                             name in type(self).positive_options)
            init(self, *args, **kw)

        cls.__init__ = checked

    @property
    def label(self) -> str:
        """Who speaks in a refusal: the method's name (a stage of another method says whose, e.g.
        ``"kf (coarse-i0 start)"``)."""
        return self.name

    def align(self, imu: IMUData, site: Site, vref=None, init=None, aiding=None) -> AlignmentResult:
        """Apply the input policy (module docstring), then align (:meth:`_align`); arguments as
        :meth:`fusionbench.methods.aligner.Aligner.align`."""
        aiding, init = self.check(imu, site, vref, init, aiding)
        if init is not None and self.init_capture_deg is not None:
            from fusionbench.methods.init_check import check_capture

            check_capture(self, imu, site, aiding, init, getattr(self, "coarse_s", 60.0))
        return self._align(imu, site, aiding, init)

    def check(self, imu: IMUData, site: Site, vref=None, init=None, aiding=None):
        """The input policy alone: ``(aiding, init)`` checked and broadcast over the runs (an
        :class:`~fusionbench.simulation.aiding.Aiding` for R recordings or None; (R, 3, 3) or None), or a one-line
        ``ValueError`` naming the method and the field."""
        _, init = check_inputs(imu, None, init, self.name, init_required=supports(self).needs_init)
        aiding = as_aiding(imu, vref, aiding, self.name)
        if aiding is not None and not aiding.is_at_rest() and not self.uses_aiding:
            raise ValueError(f"{self.name}: aiding: expected none or rows at rest ({self.name} aligns a stationary or "
                             f"swaying base and takes no aiding of a moving one), found {aiding.source} with "
                             f"{'velocities' if aiding.has_velocity else 'positions'} of a moving base: use a method "
                             f"that claims a moving base (fusionbench list)")
        earth.check_latitude(site.lat, f"{self.name}: site latitude", self.max_latitude_deg)
        check_azimuth_observable(self.spec, site, self.name)
        if imu.duration < self.min_duration_s:
            raise ValueError(f"{self.name}: duration: expected at least {self.min_duration_s:g} s of data, found "
                             f"{imu.duration:g} s")
        if (aiding is None or aiding.is_at_rest()) and not supports(self).needs_init:
            motion.check_stationary(imu, site, self.label)
        return aiding, init

    def align_chunks(self, chunks, site: Site, record, init=None) -> AlignmentResult:
        """Align R recordings given as consecutive chunks, for a method that defines ``_align_chunks`` (a long
        record streamed: :mod:`fusionbench.bench.streaming`).

        Parameters
        ----------
        chunks : iterable of (IMUData, ndarray or None)
            Consecutive chunks: increments (kind ``"increment"``, body RFU) and the reference velocity (R, n, 3),
            ENU, m/s, at their samples, or None. The samples are not checked (a stream is not held).
        site : Site
        record : object
            The whole record's ``runs``, ``dt`` (s), ``t0`` and ``duration`` (s), e.g.
            :class:`fusionbench.bench.streaming.SimulatedStream`.
        init : ndarray, shape (3, 3) or (R, 3, 3), optional
            Initial attitude C_bn; checked and broadcast as by :meth:`align`.

        The policy of :meth:`align` but for the samples themselves, then ``_align_chunks(chunks, site, init, dt,
        t0, runs)``.
        """
        init = check_init(init, record.runs, self.name, required=supports(self).needs_init)
        earth.check_latitude(site.lat, f"{self.name}: site latitude", self.max_latitude_deg)
        check_azimuth_observable(self.spec, site, self.name)
        if record.duration < self.min_duration_s:
            raise ValueError(f"{self.name}: duration: expected at least {self.min_duration_s:g} s of data, found "
                             f"{record.duration:g} s")
        return self._align_chunks(chunks, site, init, record.dt, record.t0, record.runs)

    def _align(self, imu: IMUData, site: Site, aiding, init) -> AlignmentResult:
        """The method itself, on arguments the policy has checked.

        Parameters
        ----------
        imu : IMUData
            R recordings, body RFU, finite, at least ``min_duration_s`` long.
        site : Site
            Within the method's latitude limit.
        aiding : fusionbench.simulation.aiding.Aiding or None
            Rows for the R recordings, valid inside the record; only rows at rest unless ``uses_aiding``.
        init : ndarray, shape (R, 3, 3), or None
            Initial attitude C_bn, rotation matrices.
        """
        raise NotImplementedError(f"{type(self).__name__}: implement _align(imu, site, aiding, init)")


def check_option(method, name, value, default, positive=False):
    """One option against its default (module docstring): ValueError ``"<method>: option <name>: expected ...,
    found ..."``; an option whose default is None, a string or a table is left to the method."""
    if isinstance(default, bool):
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{method}: option {name}: expected true or false, found {value!r}")
        return
    if not isinstance(default, numbers.Real) or default is inspect.Parameter.empty:
        return
    whole = isinstance(default, numbers.Integral)
    base = "whole number" if whole else "number"
    kind = f"a positive {base}" if positive else f"a {base} >= 0" if default > 0 else f"a {base}"
    ok = (isinstance(value, numbers.Integral) if whole else isinstance(value, numbers.Real)) \
        and not isinstance(value, (bool, np.bool_)) and bool(np.isfinite(value))
    ok = ok and (value > 0 if positive else value >= 0 if default > 0 else True)
    if not ok:
        raise ValueError(f"{method}: option {name}: expected {kind}, found {value!r}")



def as_aiding(imu, vref=None, aiding=None, name="method"):
    """The aiding of a record, checked: ``aiding`` (an :class:`~fusionbench.simulation.aiding.Aiding`) or the
    per-increment ``vref`` array (R, M, 3) or (M, 3), ENU m/s at ``imu.increments()[0]``, converted
    (:meth:`Aiding.from_vref`); for R = ``imu.runs`` recordings, every row valid inside the record; None when neither
    is given. One-line ``ValueError`` naming ``name`` otherwise."""
    if vref is not None and aiding is not None:
        raise ValueError(f"{name}: vref and aiding: expected one of them (vref is the per-increment form of aiding), "
                         f"found both")
    if vref is not None:
        t_end = imu.increments()[0]
        try:
            v = np.asarray(vref, dtype=float)
            aiding = Aiding.from_vref(t_end, v, source="vref")
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name}: {str(exc).splitlines()[0]}") from None
    if aiding is None:
        return None
    if not isinstance(aiding, Aiding):
        raise ValueError(f"{name}: aiding: expected a fusionbench.simulation.aiding.Aiding, "
                         f"found {type(aiding).__name__}")
    try:
        aiding = aiding.for_runs(imu.runs)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    aiding.check_record(imu.t0, imu.t_last, imu.dt, name)
    return aiding


def coarse_then_fine(imu: IMUData, site: Site, aiding, coarse, coarse_s: float, fine):
    """Initialise with a coarse aligner on the first ``coarse_s`` seconds, then run ``fine`` on the rest.

    For fine aligners that need an initial attitude within a few degrees but must accept any heading. ``coarse`` is
    an aligner (e.g. ``fusionbench.methods.coarse.InertialCoarseAligner``), given the rows of ``aiding`` (an
    :class:`~fusionbench.simulation.aiding.Aiding` or None) valid in its part; ``fine(imu_rest, aiding_rest, C0,
    t_handover)`` returns the fine aligner's AlignmentResult on the remaining increments from the coarse attitude
    ``C0`` (R, 3, 3) at ``t_handover`` (s, the coarse part's last sample), with the rows valid after it (or None). The
    histories are joined; arrays of the fine result's ``extra`` shaped (R, M, ...) get NaN over the coarse part.
    """
    t, dth, dv = imu.increments()
    k0 = int(round(coarse_s / imu.dt))
    if not 0 < k0 < t.size - 1:
        raise ValueError(f"duration: the coarse stage of {coarse_s:g} s leaves no data for fine alignment "
                         f"in {imu.duration:g} s")
    t_hand = float(t[k0 - 1])
    first = coarse.align(IMUData(t[:k0], dth[:, :k0], dv[:, :k0], "increment"), site,
                         aiding=None if aiding is None else aiding.window(-np.inf, t_hand))
    rest = IMUData(t[k0:], dth[:, k0:], dv[:, k0:], "increment")
    res = fine(rest, None if aiding is None else aiding.window(t_hand, np.inf), first.C_bn_final, t_hand)
    m = first.t.size

    def padded(val):  # a history of the fine stage, NaN over the coarse one
        if isinstance(val, np.ndarray) and val.ndim >= 2 and val.shape[:2] == res.C_bn.shape[:2]:
            return np.concatenate([np.full((val.shape[0], m) + val.shape[2:], np.nan), val], axis=1)
        return val

    return AlignmentResult(res.method, np.concatenate([first.t, res.t]), np.concatenate([first.C_bn, res.C_bn], axis=1),
                           {k: padded(v) for k, v in res.extra.items()},
                           sigma_phi=None if res.sigma_phi is None else padded(res.sigma_phi),
                           series={k: padded(np.asarray(v)) for k, v in res.series.items()}, figures=res.figures,
                           imu_model=res.imu_model, causal=res.causal)


def per_increment_velocity(aiding, imu, name="method"):
    """The aiding as a velocity at every increment end (R, M, 3), ENU m/s, for a method that reads one there (the
    compass loops' zero-velocity reference): the rows themselves when they lie exactly there (the simulator's
    per-increment reference), None without aiding or for rows at rest elsewhere (the zero velocity the method
    assumes anyway); a one-line ``ValueError`` naming ``name`` for rows of a moving base elsewhere."""
    if aiding is None:
        return None
    t_end = imu.increments()[0]
    v = aiding.dense_velocity(t_end, imu.runs)
    if v is None and not aiding.is_at_rest():
        raise ValueError(f"{name}: aiding: expected a velocity at every increment end, found {aiding.t.size} rows at "
                         f"{aiding.rate_hz():.3g} Hz")
    return v
