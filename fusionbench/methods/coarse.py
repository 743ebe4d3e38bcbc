"""Analytic coarse alignment (double-vector / TRIAD) on a stationary base.

From the mean specific force ``f^b`` (m/s^2) and mean angular rate ``w^b`` (rad/s) over the
recording, body frame RFU, build orthonormal triads in both frames::

    u = f / |f|                   (up: a stationary accelerometer measures -g^n = [0, 0, g])
    e = (w x f) / |w x f|         (east: earth rate [0, W cos L, W sin L] crossed with up)
    n = u x e                     (north)

and ``C_bn = [e_b n_b u_b]^T`` (its rows are the east, north and up axes seen in the body frame).
Up is the primary vector, so the tilt comes from the accelerometers alone and the azimuth from the
gyros' horizontal component. With accelerometer bias nabla and gyro bias eps it lands on the
theoretical limits (:func:`fusionbench.scoring.metrics.theoretical_limits`); it needs no latitude except
for its checks. On a swaying base the mean rate carries the sway's net rotation over the window
(about amplitude / duration), which can swamp the earth rate: use it on a stationary base, or as
the first stage of a fine aligner.

The result carries a history: the estimate from the data up to each of ``history_points`` times.

:class:`InertialCoarseAligner` (``coarse-i0``) fits in the inertial frame instead: robust to sway, and on a
moving base with aiding (velocity or position rows; see its docstring and :mod:`fusionbench.methods.coarse_aided`).
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.aligner import AlignmentResult, Site
from fusionbench.methods.aligner_base import AlignerBase
from fusionbench.methods.claims import Supports
from fusionbench.methods.coarse_i0 import LEVEL_NOISE_MAX, LEVEL_WINDOW_S, inertial_coarse
from fusionbench.simulation.imu import load_spec
from fusionbench.simulation.imudata import IMUData


def triad(f_b, w_b):
    """C_bn (..., 3, 3) from mean specific force (m/s^2) and angular rate (rad/s), body frame (..., 3)."""
    f_b = np.asarray(f_b, dtype=float)
    w_b = np.asarray(w_b, dtype=float)
    u = f_b / np.linalg.norm(f_b, axis=-1, keepdims=True)
    e = np.cross(w_b, u)
    e = e / np.linalg.norm(e, axis=-1, keepdims=True)
    n = np.cross(u, e)
    return np.stack([e, n, u], axis=-2)


class CoarseAligner(AlignerBase):
    """Analytic coarse alignment (method ``coarse``): TRIAD of the mean specific force and angular rate.

    Parameters
    ----------
    history_points : int
        Number of times at which the growing-window estimate is reported.
    """

    positive_options = ("history_points",)

    name = "coarse"
    supports = Supports(bases=("static",), max_abs_lat_deg=80.0)  # the mean rate carries a sway's net rotation
    description = "analytic coarse alignment (double-vector/TRIAD of mean specific force and earth rate)"
    min_duration_s = 1.0
    #: Beyond it the horizontal earth rate (cos L of it) is too small to point north: at 90 deg there is none, and
    #: the heading would be whatever the sensor errors make it.
    max_latitude_deg = 89.0

    def __init__(self, history_points: int = 200, imu=None):
        self.history_points = int(history_points)
        self.spec = None if imu is None else load_spec(imu)

    def _align(self, imu: IMUData, site: Site, aiding, init) -> AlignmentResult:
        """Align every recording of ``imu`` (stationary base); ``aiding`` (rows at rest) and ``init`` are not used.

        Returns an :class:`AlignmentResult` whose last attitude uses the whole recording.
        """
        t, dth, dv = imu.increments()
        m = min(self.history_points, t.size)
        idx = np.unique(np.linspace(0, t.size - 1, m).round().astype(int))
        span = (idx + 1)[None, :, None] * imu.dt
        w = np.cumsum(dth, axis=1)[:, idx] / span
        f = np.cumsum(dv, axis=1)[:, idx] / span
        return AlignmentResult(self.name, t[idx], triad(f, w))



class InertialCoarseAligner(AlignerBase):
    """Inertial-frame coarse alignment (method ``coarse-i0``), robust to sway; on a moving base with aiding.

    The gyros carry the body frame from its inertially frozen start b0: ``C_b^b0(t)`` (with the
    strapdown's coning compensation); the specific force integrated in b0 gives ``V_b0(t)``
    (with rotation and sculling compensation). The same integral in the inertial frame i0 is
    ``V_i0(t) = C_b0^i0 V_b0(t)``; ``C_b0^i0`` is the least-squares rotation between the two (Wahba's
    problem, :meth:`scipy.spatial.transform.Rotation.align_vectors`) over the second half of the
    record. Then ``C_bn(t) = C_i0^n(t) C_b0^i0 C_b^b0(t)``. Sway enters only through bounded velocity
    terms, so the azimuth comes from how gravity turns with the earth (about OMEGA_IE t cos L rad),
    not from the mean gyro rate. Needs the latitude.

    * **Stationary or swaying base** (no aiding): ``V_i0`` is the closed form of
      :func:`gravity_integral_inertial`, fitted at ``fit_points`` times, and ``C_n^i0(t) = exp([u x]
      OMEGA_IE t)``. The input policy has checked the record for a base that moves
      (:func:`fusionbench.methods.motion.check_stationary`, the same check for every aligner).
    * **With aiding** (:class:`fusionbench.simulation.aiding.Aiding`: velocity or position rows at a receiver's
      epochs, a lever arm, a latency, outages; rows at rest; the per-increment reference of earlier versions as rows at
      every increment end): ``V_i0`` at the rows' times of validity from the rows and ``V_b0`` interpolated there,
      fitted over blocks of rows less an anchor, the lever arm taken off with the attitude of a first fit
      (:mod:`fusionbench.methods.coarse_aided`). With a constant acceleration the axis left weakly observable is the
      specific force's direction, not the vertical: a gyro bias's azimuth limit -epsE / (W cos L) comes with a
      level error of about fE / fU times it.

    ``extra`` reports two diagnostics of the fit per recording (no longer checked here: the input policy's motion
    check refuses a moving base without aiding):

    * ``fit_residual_mps``: the rms residual of the fit once a common scale is allowed
      (``|V_i0 - s C_b0^i0 V_b0|``; the scale takes the accelerometers' scale and vertical bias errors).
      On a stationary or moored base it is the base's velocity disturbance (sqrt(3) 0.05 m/s for
      0.05 m/s rms per axis: 0.087) plus the gyro errors' share, which grows with the record (a tactical gyro,
      1 deg/h and 0.5 deg/h instability: 0.49 m/s over 300 s; 0.1 or less for navigation grade). With aiding,
      the rows' noise averaged over the blocks and the IMU's errors.
    * ``gravity_excess``: ``1 / s - 1``, the mean specific force's excess over the model's gravity (in g): the
      accelerometers' scale and vertical bias; without aiding, a horizontal acceleration a that lasts the whole
      record, which the fit reads as a tilt by a / g, adds a^2 / 2 g^2 (4.9e-3 at 0.1 g).

    Parameters
    ----------
    history_points : int
        Number of times at which the estimate is reported.
    fit_points : int
        Number of fit times in the second half of the record (with aiding: blocks tiling the second half of the
        rows).
    caller : str, optional
        Name of the method whose start this is, for the refusal message (``"eso-td"`` gives
        ``eso-td (coarse-i0 start): ...``).
    level_window_s : float or None
        Each attitude's level is taken from the mean specific force of this many seconds before it (20 s;
        None: the fit's level; see :func:`fusionbench.methods.coarse_level.relevel`).
    level_noise_max : float
        The largest level error (rad, 3e-5: 0.1 arcmin) the window's noise may cause for the level to be taken
        that way: with aiding, its rows' slope's noise; without, the scatter of the specific force between
        four sub-windows (a base moving a little, e.g. a moored ship), over 2.
    imu : str, path or IMUSpec, optional
        The IMU, used only to refuse when its gyro bias hides the earth rate; None: not checked.

    The method's own motion checks (``motion_mps``, ``motion_mps_per_s2``, ``max_gravity_excess`` of earlier
    versions) gave way to the input policy's, the same for every aligner
    (:func:`fusionbench.methods.motion.check_stationary`).
    """

    positive_options = ("history_points", "fit_points")

    name = "coarse-i0"
    uses_aiding = True
    # measured (tests/test_coarse_aiding.py; the conformance matrix's drives at 3 runs, efficiency 1.1-2.1): velocity
    # rows at 10 and 1 Hz, position rows alone at 1 Hz, an outage of 60 s; in motion navigation-grade gyros only: it
    # has no gyro-bias model, and a turning drive makes the bias observable (a tactical IMU: efficiency 70)
    supports = Supports(bases=("static", "sway", "moving"), max_abs_lat_deg=80.0, aiding=("velocity", "position"),
                        min_aiding_hz=1.0, max_outage_s=60.0, max_bias_ratio_moving=0.05)
    description = "inertial-frame coarse alignment (gravity turning with the earth), robust to sway; moving with aiding"
    min_duration_s = 10.0
    max_latitude_deg = 89.0  # as the analytic coarse alignment: no north at the pole

    def __init__(self, history_points: int = 100, fit_points: int = 50, caller: str | None = None, imu=None,
                 level_window_s: float | None = LEVEL_WINDOW_S, level_noise_max: float = LEVEL_NOISE_MAX):
        self.spec = None if imu is None else load_spec(imu)
        self.level_window_s = None if not level_window_s else float(level_window_s)
        self.level_noise_max = float(level_noise_max)
        self.history_points = int(history_points)
        self.fit_points = int(fit_points)
        self.caller = caller

    @property
    def label(self) -> str:
        """The method's name in a refusal: ``coarse-i0``, or ``"<caller> (coarse-i0 start)"`` as another method's
        first stage."""
        return self.name if self.caller is None else f"{self.caller} (coarse-i0 start)"

    def _align(self, imu: IMUData, site: Site, aiding, init) -> AlignmentResult:
        """Align every recording of ``imu``; ``init`` is not used.

        Parameters
        ----------
        imu : IMUData
            Body RFU increments or rates.
        site : Site
            Position at the start of the record.
        aiding : fusionbench.simulation.aiding.Aiding or None
            Rows for the R recordings, valid inside the record; None: a stationary or swaying base (checked by the
            input policy).
        init : None
            Not used.
        """
        return inertial_coarse(imu, site, aiding, self.history_points, self.fit_points, self.level_window_s,
                               self.level_noise_max, self.label, self.name)

