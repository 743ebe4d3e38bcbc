"""What a calibration method of the platform-rolling experiment is: the :class:`Calibrator` protocol, the
:class:`CalibrationResult` it returns, and how a method is found by name (entry-point group
``fusionbench.calibrators``, or a ``module:Class`` path).

Why here and not in the core: issue 13 asked for these "in the core", but the core (:mod:`fusionbench`) holds only
what two or more families share, and only this family calibrates. The core runs a calibrator through this family's
experiment (:mod:`baselines.rolling.experiment`), never directly, so it needs neither name. Should a second family
calibrate, this module moves to the core as it stands.

Frames and units throughout: p the platform frame, n East-North-Up; the state vector is the 45-vector
``[42 error coefficients (SI, order of baselines.rolling.model.COEFF_NAMES), phi, theta, psi (rad)]`` of the
:mod:`baselines.rolling` module notes.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Protocol, runtime_checkable

import numpy as np

from fusionbench.methods.aligner import load_entry

from . import model

#: Entry-point group of the calibration methods.
CALIBRATORS_GROUP = "fusionbench.calibrators"


@dataclass
class CalibrationResult:
    """What :meth:`Calibrator.calibrate` returns: the estimate history of one recording.

    Attributes
    ----------
    t : ndarray, shape (M,)
        Filter times, s.
    x : ndarray, shape (M, 45)
        State estimate after each update: 42 coefficients (SI) and the attitude angles phi, theta, psi (rad,
        of ``C_pn``, p to ENU).
    sigma : ndarray, shape (M, 45)
        Its standard deviations, same units.
    figures : dict, optional
        Scalars the method reports about the run, copied into metrics.json beside its figures (the rolling EKF's:
        ``information_rank``, the rank of the information matrix the run gathered, SVD with relative tolerance
        :data:`baselines.rolling.observability.RTOL`; ``informed_directions``
        (:func:`baselines.rolling.observability.informed_directions`); ``passes``).
    information : ndarray, shape (45, 45), optional
        Information matrix of the run in prior-scaled error coordinates (``e = D z``, D = ``scale``):
        ``sum_k Phi(t_k, 0)^T H_k^T R^-1 H_k Phi(t_k, 0)`` with the filter's own F and H along its
        estimate and R the accelerometer noise (the piecewise-constant-system information matrix).
    first_pass : CalibrationResult, optional
        Of a method that reprocesses the data: its first (causal, real-time) pass, whose attitude history is the
        one whose settling time means something (later passes start from an estimate that used all the data).
    scale : ndarray, shape (45,), optional
        The prior standard deviations D that scale ``information`` (SI).
    """

    t: np.ndarray
    x: np.ndarray
    sigma: np.ndarray
    figures: dict = None
    information: np.ndarray = None
    first_pass: "CalibrationResult" = None
    scale: np.ndarray = None

    def bound(self):
        """Information bound of the coefficients and angles (45,), SI: ``D sqrt(diag((I + information)^-1))``,
        the standard deviations an efficient estimator reaches with this run's prior and outputs (the
        Cramer-Rao bound of the linearised model, the gyros' white drift left out). None without
        ``information``."""
        if self.information is None:
            return None
        return self.scale * np.sqrt(np.diag(np.linalg.inv(np.eye(len(self.scale)) + self.information)))

    def final(self, last_s=100.0):
        """The paper's readout, (45,): coefficients averaged over the last ``last_s`` seconds; the angles
        at the last filter time (they move with the platform, an average would mix attitudes)."""
        sel = self.t >= self.t[-1] - last_s
        out = self.x[sel].mean(axis=0)
        out[model.ANGLES] = self.x[-1, model.ANGLES]
        return out


@runtime_checkable
class Calibrator(Protocol):
    """Protocol of a calibration method (structural: no base class needed).

    A method may also have ``report_figures(folder, scheme, lat) -> [(file, caption)]``: figures of its own that
    the report adds (the rolling EKF's output-sensitivity curves of the scheme).

    Attributes
    ----------
    name : str
        Its registered name (the scenario's ``methods``).
    description : str
        One line for ``fusionbench list``.
    """

    name: str
    description: str

    def calibrate(self, t, y, w_cmd, lat, h=0.0) -> CalibrationResult:
        """Estimate the 42 error coefficients and the attitude from one recording.

        Parameters
        ----------
        t : ndarray, shape (M,)
            Filter times, s, uniformly spaced (the first one step after the start).
        y : ndarray, shape (M, 3)
            Accelerometer outputs (X, Y, Z: along the accelerometers' sensitive axes, p frame) at ``t``, m/s^2.
        w_cmd : ndarray, shape (M, 3)
            Torque command (p frame, one per gyro X, Y, Z), rad/s, held over the step ending at each ``t``.
        lat : float
            Latitude, rad.
        h : float
            Height, m.

        Returns
        -------
        CalibrationResult
        """


def available_calibrators():
    """Registered calibration methods: ``{name: entry point}`` of the ``fusionbench.calibrators`` group."""
    return {ep.name: ep for ep in entry_points(group=CALIBRATORS_GROUP)}


def load_calibrator(spec, **options) -> Calibrator:
    """A calibration method by registered name or ``module:Class`` path; ValueError naming it when there is no
    such method or it does not follow :class:`Calibrator`."""
    obj = load_entry(CALIBRATORS_GROUP, spec, "calibration method", **options)
    if not isinstance(obj, Calibrator):
        raise ValueError(f"calibration method {spec!r}: expected an object with name, description and calibrate() "
                         "(baselines.rolling.protocol.Calibrator)")
    return obj
