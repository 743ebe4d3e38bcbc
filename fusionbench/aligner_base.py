"""The base class of the project's aligners: one input policy for every method, then the method's own work.

:class:`AlignerBase` implements ``align`` of the :class:`fusionbench.aligner.Aligner` protocol as the policy
below followed by the subclass's :meth:`AlignerBase._align`. A subclass declares its limits once, as
attributes, and implements ``_align`` only; it never checks its arguments itself. The protocol stays
structural: a user's own aligner needs no base class (``fusionbench run`` takes any object with ``name``,
``description``, ``min_duration_s`` and ``align``).

The policy, in this order (each refusal a ``ValueError`` of one line naming the method, the field, what was
expected and what was found: ``"kf: site latitude: expected a latitude between -89 and 89 deg, found 89.5 deg"``):

1. **data** (:func:`fusionbench.inputs.check_inputs`): ``imu`` an :class:`~fusionbench.imudata.IMUData` with
   finite samples; ``vref`` of shape (R, M, 3) or (M, 3), finite; ``init`` of shape (3, 3) or (R, 3, 3), finite
   rotation matrices. ``vref`` and ``init`` are broadcast over the R recordings, so ``_align`` gets arrays of
   shape (R, M, 3) and (R, 3, 3) (or None).
2. **init** when the method needs one (``supports.needs_init``: a navigator starts from an alignment).
3. **site latitude** within +-:attr:`~AlignerBase.max_latitude_deg` (:func:`fusionbench.earth.check_latitude`).
4. **the IMU model** the method was given (its ``spec``; None: not checked) must leave the azimuth observable at
   the site (:func:`fusionbench.aligner.check_azimuth_observable`: a MEMS gyro's bias hides the earth rate).
5. **duration**: at least :attr:`~AlignerBase.min_duration_s` of data (``imu.duration``).

What only a method can judge (a step the data's sample interval cannot carry, a base that moves without a
reference) it checks in ``_align``, with messages of the same form.

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

from . import earth
from .aligner import AlignmentResult, Site, check_azimuth_observable, supports
from .imudata import IMUData
from .inputs import check_init, check_inputs


class AlignerBase:
    """An aligner that applies the one input policy (module docstring) before its own :meth:`_align`.

    Attributes
    ----------
    name, description : str
        The method's name and one-line description (required).
    min_duration_s : float
        Shortest record accepted, s (class attribute, or set in ``__init__`` when it depends on the options).
    max_latitude_deg : float
        Highest |latitude| accepted, deg (90: any). What the method *claims* (``supports.max_abs_lat_deg``, the
        conditions the conformance matrix runs) may be less: this is where it refuses.
    spec : IMUSpec or None
        The IMU model the method was given (its ``imu`` option); the azimuth observability is checked with it.
    """

    name: str
    description: str
    min_duration_s: float = 0.0
    max_latitude_deg: float = 90.0
    spec = None
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

    def align(self, imu: IMUData, site: Site, vref=None, init=None) -> AlignmentResult:
        """Apply the input policy (module docstring), then align (:meth:`_align`); arguments as
        :meth:`fusionbench.aligner.Aligner.align`."""
        vref, init = self.check(imu, site, vref, init)
        return self._align(imu, site, vref, init)

    def check(self, imu: IMUData, site: Site, vref=None, init=None):
        """The input policy alone: ``(vref, init)`` checked and broadcast over the runs (or None), or a one-line
        ``ValueError`` naming the method and the field."""
        vref, init = check_inputs(imu, vref, init, self.name, init_required=supports(self).needs_init)
        earth.check_latitude(site.lat, f"{self.name}: site latitude", self.max_latitude_deg)
        check_azimuth_observable(self.spec, site, self.name)
        if imu.duration < self.min_duration_s:
            raise ValueError(f"{self.name}: duration: expected at least {self.min_duration_s:g} s of data, found "
                             f"{imu.duration:g} s")
        return vref, init

    def align_chunks(self, chunks, site: Site, record, init=None) -> AlignmentResult:
        """Align R recordings given as consecutive chunks, for a method that defines ``_align_chunks`` (a long
        record streamed: :mod:`fusionbench.streaming`).

        Parameters
        ----------
        chunks : iterable of (IMUData, ndarray or None)
            Consecutive chunks: increments (kind ``"increment"``, body RFU) and the reference velocity (R, n, 3),
            ENU, m/s, at their samples, or None. The samples are not checked (a stream is not held).
        site : Site
        record : object
            The whole record's ``runs``, ``dt`` (s), ``t0`` and ``duration`` (s), e.g.
            :class:`fusionbench.streaming.SimulatedStream`.
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

    def _align(self, imu: IMUData, site: Site, vref, init) -> AlignmentResult:
        """The method itself, on arguments the policy has checked.

        Parameters
        ----------
        imu : IMUData
            R recordings, body RFU, finite, at least ``min_duration_s`` long.
        site : Site
            Within the method's latitude limit.
        vref : ndarray, shape (R, M, 3), or None
            Reference velocity (ENU, m/s) at the increment ends (``imu.increments()[0]``).
        init : ndarray, shape (R, 3, 3), or None
            Initial attitude C_bn, rotation matrices.
        """
        raise NotImplementedError(f"{type(self).__name__}: implement _align(imu, site, vref, init)")


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

