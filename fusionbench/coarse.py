"""Analytic coarse alignment (double-vector / TRIAD) on a stationary base.

From the mean specific force ``f^b`` (m/s^2) and mean angular rate ``w^b`` (rad/s) over the
recording, body frame RFU, build orthonormal triads in both frames::

    u = f / |f|                   (up: a stationary accelerometer measures -g^n = [0, 0, g])
    e = (w x f) / |w x f|         (east: earth rate [0, W cos L, W sin L] crossed with up)
    n = u x e                     (north)

and ``C_bn = [e_b n_b u_b]^T`` (its rows are the east, north and up axes seen in the body frame).
Up is the primary vector, so the tilt comes from the accelerometers alone and the azimuth from the
gyros' horizontal component. With accelerometer bias nabla and gyro bias eps it lands on the
theoretical limits (:func:`fusionbench.metrics.theoretical_limits`); it needs no latitude except
for its checks. On a swaying base the mean rate carries the sway's net rotation over the window
(about amplitude / duration), which can swamp the earth rate: use it on a stationary base, or as
the first stage of a fine aligner.

The result carries a history: the estimate from the data up to each of ``history_points`` times.

:class:`InertialCoarseAligner` (``coarse-i0``) fits in the inertial frame instead: robust to sway, and on a
moving base with aiding (velocity or position rows; see its docstring and :mod:`fusionbench.coarse_aided`).
"""

from __future__ import annotations

import numpy as np

from . import earth
from .aligner import AlignmentResult, Site
from .aligner_base import AlignerBase
from .attitude import rotvec_to_dcm
from .claims import Supports
from .coarse_aided import aided_fit, aiding_rows, fit_rotation, imu_at_rows, place
from .coarse_inertial import c_n_i0, gravity_integral_inertial
from .coarse_kernel import body_pass
from .coarse_level import relevel
from .imu import load_spec
from .imudata import IMUData
from .strapdown import body_increments


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
      (:func:`fusionbench.motion.check_stationary`, the same check for every aligner).
    * **With aiding** (:class:`fusionbench.aiding.Aiding`: velocity or position rows at a receiver's epochs, a
      lever arm, a latency, outages; rows at rest; the per-increment reference of earlier versions as rows at
      every increment end): ``V_i0`` at the rows' times of validity from the rows and ``V_b0`` interpolated there,
      fitted over blocks of rows less an anchor, the lever arm taken off with the attitude of a first fit
      (:mod:`fusionbench.coarse_aided`). With a constant acceleration the axis left weakly observable is the
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
        None: the fit's level; see :func:`fusionbench.coarse_level.relevel`).
    level_noise_max : float
        The largest level error (rad, 3e-5: 0.1 arcmin) the window's noise may cause for the level to be taken
        that way: with aiding, its rows' slope's noise; without, the scatter of the specific force between
        four sub-windows (a base moving a little, e.g. a moored ship), over 2.
    imu : str, path or IMUSpec, optional
        The IMU, used only to refuse when its gyro bias hides the earth rate; None: not checked.

    The method's own motion checks (``motion_mps``, ``motion_mps_per_s2``, ``max_gravity_excess`` of earlier
    versions) gave way to the input policy's, the same for every aligner (:func:`fusionbench.motion.check_stationary`).
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
                 level_window_s: float | None = 20.0, level_noise_max: float = 3e-5):
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
        aiding : fusionbench.aiding.Aiding or None
            Rows for the R recordings, valid inside the record; None: a stationary or swaying base (checked by the
            input policy).
        init : None
            Not used.
        """
        who = self.label
        t, dth, dv = imu.increments()
        R, N, _ = dth.shape
        keep = np.unique(np.linspace(0, N - 1, max(self.history_points, self.fit_points) * 4).round().astype(int))
        rows = None if aiding is None else aiding_rows(aiding, R, who)
        ckeep = vkeep = keep
        integral = lever = False
        if rows is not None:  # V at the increment ends around each row; C_b^b0 at the nearest for the lever arm
            pl = place(t, imu.t0, rows)
            integral = bool(pl.wide.any() or pl.kp.size)
            lever = bool(np.any(rows.lever_arm != 0) and rows.moving.any())
            vkeep = np.unique(np.concatenate([keep, pl.samples()]))
            if lever:
                near = np.concatenate([pl.near, pl.near_p])
                ckeep = np.unique(np.concatenate([keep, near[near >= 0]]))
        C_b, dv_b = body_increments(dth, dv, np.zeros((R, 3)), np.zeros((R, 3)))
        C_out, V_out = np.empty((R, ckeep.size, 3, 3)), np.empty((R, vkeep.size, 3))
        P_out = np.empty((R, vkeep.size if integral else 0, 3))
        body_pass(
            np.ascontiguousarray(C_b), np.ascontiguousarray(dv_b), imu.dt, ckeep, vkeep, C_out, V_out, P_out)
        C_keep, V_keep = C_out[:, np.searchsorted(ckeep, keep)], V_out[:, np.searchsorted(vkeep, keep)]
        tk = t[keep] - imu.t0
        fit = np.unique(np.linspace(keep.size // 2, keep.size - 1, self.fit_points).round().astype(int))
        if rows is None:
            V_i0 = np.broadcast_to(gravity_integral_inertial(tk[fit], site.lat, site.g), (R, fit.size, 3))
            C_b0_i0, resid, excess = fit_rotation(V_i0, V_keep[:, fit])
            u = np.array([0.0, np.cos(site.lat), np.sin(site.lat)])
            C_n_i0 = np.broadcast_to(rotvec_to_dcm(np.outer(tk, u * earth.OMEGA_IE)), (R, keep.size, 3, 3))
            level_rows = None
        else:
            C_b0_i0, resid, excess, v, T, track = aided_fit(
                rows, pl, imu_at_rows(pl, V_out, P_out, vkeep, C_out, ckeep, dth, imu.dt, lever), site, t, imu.t0,
                self.fit_points, who)
            lat_k, dlon_k = (np.stack([np.interp(t[keep], T, x[r]) for r in range(R)]) for x in track[:2])
            C_n_i0 = c_n_i0(tk, site.lat, lat_k, dlon_k)
            level_rows = (rows.tau, v)
        hist = np.linspace(0, keep.size - 1, self.history_points).round().astype(int)
        hist = np.unique(hist[hist >= fit[0]])
        C_bn = np.swapaxes(C_n_i0[:, hist], -1, -2) @ C_b0_i0[:, None] @ C_keep[:, hist]
        if self.level_window_s:
            C_bn = relevel(C_bn, hist, keep, t, tk, C_n_i0, C_b0_i0, V_keep, level_rows, site, self.level_window_s,
                           self.level_noise_max)
        # not causal: every attitude of the history uses the fit over the second half of the whole record (its
        # settling is measured on prefixes; the attitude at the last sample is what a user gets)
        return AlignmentResult(self.name, t[keep][hist], C_bn, {"fit_residual_mps": resid, "gravity_excess": excess},
                               causal=False)

