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

:class:`InertialCoarseAligner` (``coarse-i0``) fits in the inertial frame instead: robust to sway, in
motion with a velocity reference, and it refuses a moving base without one (see its docstring).
"""

from __future__ import annotations

import numpy as np

from scipy.spatial.transform import Rotation

from . import earth
from .aligner import AlignmentResult, Site
from .claims import Supports, check_not_accelerating
from .aligner_base import AlignerBase, per_increment_velocity
from .attitude import rotvec_to_dcm
from .imu import load_spec
from .imudata import IMUData
from .strapdown import body_increments

from .coarse_kernel import body_pass
from .coarse_level import relevel
from .compass import check_engine


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


def gravity_integral_inertial(t, lat, g):
    """Velocity integral of the stationary specific force in the inertial frame i0.

    i0 is the ENU frame at ``t = 0`` frozen in inertial space; the site turns about the earth axis
    ``u = [0, cos L, sin L]`` (in i0) at ``W = OMEGA_IE``, so the specific force
    ``[0, 0, g]`` of a stationary IMU is ``exp([u x] W tau) [0, 0, g]`` in i0 and its integral is::

        V(t) = t f + (1 - cos W t) / W [u x] f + (t - sin(W t) / W) [u x]^2 f

    Parameters
    ----------
    t : array_like, shape (M,)
        Times since the start, s.
    lat : float
        Latitude, rad.
    g : float
        Gravity, m/s^2.

    Returns
    -------
    ndarray, shape (M, 3)
        V(t) in i0, m/s.
    """
    W = earth.OMEGA_IE
    u = np.array([0.0, np.cos(lat), np.sin(lat)])
    K = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    f = np.array([0.0, 0.0, g])
    t = np.asarray(t, dtype=float)[:, None]
    return t * f + (1 - np.cos(W * t)) / W * (K @ f) + (t - np.sin(W * t) / W) * (K @ K @ f)


def _c_ne(lat, dlon):
    """C_n^e (..., 3, 3): the ENU axes (columns E, N, U) in an earth-fixed frame whose x axis is the
    start meridian, at latitude ``lat`` and longitude ``dlon`` from that meridian (rad)."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(dlon), np.cos(dlon)
    z = np.zeros_like(sl)
    return np.stack([np.stack([-so, -sl * co, cl * co], -1),
                     np.stack([co, -sl * so, cl * so], -1),
                     np.stack([z, cl, sl], -1)], -2)


def velocity_integral_inertial(t, t_start, vref, lat, h, chunk=20000):
    """Velocity integral of the specific force in the inertial frame i0 from a velocity reference.

    i0 is the ENU frame at ``t_start`` frozen in inertial space. With ``C_n^i0(t)`` the attitude of the
    local ENU frame at the vehicle's position (the earth's rotation and the vehicle's transport over the
    earth, from the reference's latitude and longitude changes), the velocity equation
    ``v' = C_bn f^b - (2 w_ie + w_en) x v + g^n`` gives, since ``d/dt (C_n^i0 v) = C_n^i0 (v' + w_in x v)``
    with ``w_in = w_ie + w_en`` (the transport rate cancels with its share of the Coriolis term)::

        V_i0(t) = int_t0^t C_n^i0 C_bn f^b = C_n^i0(t) v(t) - C_n^i0(t0) v(t0) + int_t0^t C_n^i0 (w_ie x v - g^n)

    from the first increment end ``t0 = t[0]`` on (where the reference has its first sample). The
    integral is the trapezoid rule on the samples; position (latitude, longitude, height) the trapezoid
    integral of the reference from (``lat``, ``h``) at ``t_start``.

    Neglected: the trapezoid rule's error on ``C_n^i0 (w_ie x v - g^n)`` (dt^2 / 12 times its second
    derivative, g W^2 dt^2 t / 12 for the turning gravity: below 1e-6 m/s over an hour at 100 Hz; for the
    Coriolis term, W a dt^2 t / 12 at an acceleration a); the deflection of the vertical and gravity
    anomalies (the normal gravity of :func:`fusionbench.earth.gravity`), as on a stationary base. The
    reference's errors pass as they are: its noise at ``t`` and ``t0`` directly (the aligner averages both
    sides of the fit over blocks), its integrated noise in the Coriolis term as W sigma sqrt(t dt)
    (1e-5 m/s for 0.1 m/s over 300 s at 10 Hz) and in the position as sigma sqrt(t dt) (0.5 m: 1e-7 rad of
    frame transport).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Increment end times, s.
    t_start : float
        Start of the first increment (the instant of i0), s.
    vref : ndarray, shape (R, N, 3)
        Reference velocity over the earth, ENU, m/s, at the increment ends.
    lat, h : float
        Latitude (rad) and height (m) at ``t_start``.

    Returns
    -------
    V : ndarray, shape (R, N, 3)
        ``V_i0(t[k]) - V_i0(t[0])`` in i0, m/s.
    C_n_i0 : ndarray, shape (R, N, 3, 3)
        The local ENU frame at each ``t[k]`` in i0.
    """
    R, N, _ = vref.shape
    tau = t - t_start
    # position: trapezoid rule on the reference (the first half increment with its first sample)
    dtau = np.diff(np.concatenate([[0.0], tau]))
    v_prev = np.concatenate([vref[:, :1], vref[:, :-1]], axis=1)
    v_mid = 0.5 * (vref + v_prev)
    h_k = float(h) + np.cumsum(v_mid[..., 2] * dtau, axis=1)
    lat_k = np.full((R, N), float(lat))
    for _ in range(2):  # the radii depend weakly on the latitude: two passes are exact to 1e-12
        rm, rn = earth.radii(lat_k)
        lat_k = lat + np.cumsum(v_mid[..., 1] / (rm + h_k) * dtau, axis=1)
    rm, rn = earth.radii(lat_k)
    dlon = np.cumsum(v_mid[..., 0] / ((rn + h_k) * np.cos(lat_k)) * dtau, axis=1)
    C0T = np.swapaxes(_c_ne(np.asarray(lat, dtype=float), np.asarray(0.0)), -1, -2)
    C_n_i0 = np.empty((R, N, 3, 3))
    F = np.empty((R, N, 3))
    for a in range(0, N, chunk):
        b = min(N, a + chunk)
        wt = earth.OMEGA_IE * tau[a:b]
        c, s = np.cos(wt), np.sin(wt)
        Rz = np.zeros((b - a, 3, 3))
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
        C = C0T @ Rz[None] @ _c_ne(lat_k[:, a:b], dlon[:, a:b])
        C_n_i0[:, a:b] = C
        f = np.cross(earth.earth_rate_n(lat_k[:, a:b]), vref[:, a:b]) - earth.gravity_n(lat_k[:, a:b], h_k[:, a:b])
        F[:, a:b] = np.einsum("rkij,rkj->rki", C, f)
    integral = np.concatenate([np.zeros((R, 1, 3)),
                               np.cumsum(0.5 * (F[:, 1:] + F[:, :-1]) * np.diff(t)[None, :, None], axis=1)], axis=1)
    Cv = np.einsum("rkij,rkj->rki", C_n_i0, vref)
    return Cv - Cv[:, :1] + integral, C_n_i0


class InertialCoarseAligner(AlignerBase):
    """Inertial-frame coarse alignment (method ``coarse-i0``), robust to sway; in motion with a velocity reference.

    The gyros carry the body frame from its inertially frozen start b0: ``C_b^b0(t)`` (with the
    strapdown's coning compensation); the specific force integrated in b0 gives ``V_b0(t)``
    (with rotation and sculling compensation). The same integral in the inertial frame i0 is
    ``V_i0(t) = C_b0^i0 V_b0(t)``; ``C_b0^i0`` is the least-squares rotation between the two (Wahba's
    problem, :meth:`scipy.spatial.transform.Rotation.align_vectors`) over the second half of the
    record. Then ``C_bn(t) = C_i0^n(t) C_b0^i0 C_b^b0(t)``. Sway enters only through bounded velocity
    terms, so the azimuth comes from how gravity turns with the earth (about OMEGA_IE t cos L rad),
    not from the mean gyro rate. Needs the latitude.

    * **Stationary or swaying base** (``vref=None``): ``V_i0`` is the closed form of
      :func:`gravity_integral_inertial`, fitted at ``fit_points`` times, and ``C_n^i0(t) = exp([u x]
      OMEGA_IE t)``.
    * **Moving base with a velocity reference**: ``V_i0`` comes from the reference
      (:func:`velocity_integral_inertial`: the motion terms ``C_n^i0 v`` and the Coriolis integral, the
      local frame carried over the earth by the reference's position). The reference's noise enters
      ``V_i0`` sample by sample (0.1 m/s against an earth-rotation signal of about 1 m/s after 60 s), so
      both sides of ``V_i0 = C_b0^i0 V_b0`` are averaged over ``fit_points`` blocks that tile the second
      half, less their means over the first quarter (the anchor: the identity holds between any two
      times, so no model of the motion is needed). With a constant acceleration the axis left weakly
      observable is the specific force's direction, not the vertical: a gyro bias's azimuth limit
      -epsE / (W cos L) comes with a level error of about fE / fU times it.

    **Moving base without a reference: refused.** Without ``vref`` the data are checked for a
    stationary or swaying base; ``extra`` reports both figures per recording:

    * ``fit_residual_mps``: the rms residual of the fit once a common scale is allowed
      (``|V_i0 - s C_b0^i0 V_b0|``; the scale takes the accelerometers' scale and vertical bias errors).
      On a stationary or moored base it is the base's velocity disturbance (sqrt(3) 0.05 m/s for
      0.05 m/s rms per axis: 0.087, at most 0.10 over 40 disturbances) plus the gyro errors' share, which
      grows with the record (a tactical gyro, 1 deg/h and 0.5 deg/h instability: 0.49 m/s over 300 s,
      1.5 over 600 s; 0.1 or less for navigation grade). A change of velocity during the record adds
      about a fifth of the change (0.01 g from a quarter, half or three quarters of a 60-s record on:
      0.28, 0.57, 0.41 m/s; of a 300-s record: 1.5, 2.8, 2.1). Refused above
      ``motion_mps + motion_mps_per_s2 T^2`` (T the record's length: 0.17 m/s over 60 s, 0.69 over
      300 s, 2.3 over 600 s), which leaves margins of 1.4 to 1.7 on both sides for gyros up to tactical
      grade and records up to 600 s; beyond, pass a reference or ``motion_mps=None``.
    * ``gravity_excess``: ``1 / s - 1``, the mean specific force's excess over normal gravity (in g).
      A horizontal acceleration a that lasts the whole record is, to first order, a tilt (the
      equivalence principle: the fit turns the frame by a / g and its residual stays that of a
      stationary base), but it raises the specific force to sqrt(g^2 + a^2), a^2 / 2g^2 = 4.9e-3 at
      0.1 g. Refused beyond ``max_gravity_excess`` (3e-3: four times a tactical IMU's bias and scale
      error; it detects a constant acceleration from about 0.08 g. A constant 0.01 g from the first
      sample on, 5e-5, cannot be told from a tilt by any method).

    Parameters
    ----------
    history_points : int
        Number of times at which the estimate is reported.
    fit_points : int
        Number of fit times (blocks with a reference) in the second half of the record.
    motion_mps, motion_mps_per_s2 : float
        Threshold of ``fit_residual_mps`` without a reference: ``motion_mps + motion_mps_per_s2 T^2``
        (m/s, m/s^3; T the record's length, s). ``motion_mps=None`` disables both checks.
    max_gravity_excess : float
        Threshold of ``|gravity_excess|`` without a reference (in g).
    caller : str, optional
        Name of the method whose start this is, for the refusal message (``"eso-td"`` gives
        ``eso-td (coarse-i0 start): ...``).
    level_window_s : float or None
        Each attitude's level is taken from the mean specific force of this many seconds before it (20 s;
        None: the fit's level; see :func:`fusionbench.coarse_level.relevel`).
    level_noise_max : float
        The largest level error (rad, 3e-5: 0.1 arcmin) the window's noise may cause for the level to be taken
        that way: with a reference, its slope's noise; without, the scatter of the specific force between
        four sub-windows (a base moving a little, e.g. a moored ship), over 2.
    imu : str, path or IMUSpec, optional
        The IMU, used only to refuse when its gyro bias hides the earth rate; None: not checked.
    engine : {"numba", "numpy"}
        The pass over the samples compiled (:func:`fusionbench.coarse_kernel.body_pass`, default) or in NumPy, a
        Python step per sample (the reference: the same results to rounding, ten to a hundred times slower).
    """

    positive_options = ("history_points", "fit_points")

    name = "coarse-i0"
    uses_aiding = True
    supports = Supports(bases=("static", "sway", "moving"), max_abs_lat_deg=80.0)
    description = "inertial-frame coarse alignment (gravity turning with the earth), robust to sway; in motion with vref"
    min_duration_s = 10.0
    max_latitude_deg = 89.0  # as the analytic coarse alignment: no north at the pole

    def __init__(self, history_points: int = 100, fit_points: int = 50, motion_mps: float | None = 0.15,
                 motion_mps_per_s2: float = 6e-6, max_gravity_excess: float = 3e-3, caller: str | None = None,
                 imu=None, level_window_s: float | None = 20.0, level_noise_max: float = 3e-5, engine: str = "numba"):
        self.engine = check_engine(self.name, engine)
        self.spec = None if imu is None else load_spec(imu)
        self.level_window_s = None if not level_window_s else float(level_window_s)
        self.level_noise_max = float(level_noise_max)
        self.history_points = int(history_points)
        self.fit_points = int(fit_points)
        self.motion_mps = None if motion_mps is None else float(motion_mps)
        self.motion_mps_per_s2 = float(motion_mps_per_s2)
        self.max_gravity_excess = float(max_gravity_excess)
        self.caller = caller

    @property
    def label(self) -> str:
        """The method's name in a refusal: ``coarse-i0``, or ``"<caller> (coarse-i0 start)"`` as another method's
        first stage."""
        return self.name if self.caller is None else f"{self.caller} (coarse-i0 start)"

    def motion_threshold_mps(self, duration):
        """Largest ``fit_residual_mps`` (m/s) accepted without a reference on a record of ``duration`` s."""
        return np.inf if self.motion_mps is None else self.motion_mps + self.motion_mps_per_s2 * float(duration) ** 2

    def _align(self, imu: IMUData, site: Site, aiding, init) -> AlignmentResult:
        """Align every recording of ``imu``; ``init`` is not used.

        Parameters
        ----------
        imu : IMUData
            Body RFU increments or rates.
        site : Site
            Position at the start of the record.
        vref : ndarray, shape (R, M, 3), optional
            Reference velocity over the earth (ENU, m/s) at the increment ends. None: a stationary or
            swaying base, checked (see the class docstring): a ValueError naming the method and the
            figure when the data show a moving base.
        """
        who = self.label
        vref = per_increment_velocity(aiding, imu, who)
        t, dth, dv = imu.increments()
        R, N, _ = dth.shape
        keep = np.unique(np.linspace(0, N - 1, max(self.history_points, self.fit_points) * 4).round().astype(int))
        # with a reference: block 0 the anchor (first quarter), blocks 1..F tile the second half
        block = np.full(N, -1)
        if vref is not None:
            block[: max(1, N // 4)] = 0
            edges = np.linspace(N // 2, N, self.fit_points + 1).round().astype(int)
            for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
                block[a:b] = i + 1
        nb = self.fit_points + 1
        V_blk = np.zeros((R, nb, 3))
        C_b, dv_b = body_increments(dth, dv, np.zeros((R, 3)), np.zeros((R, 3)))
        C = np.broadcast_to(np.eye(3), (R, 3, 3)).copy()
        V = np.zeros((R, 3))
        C_keep = np.empty((R, keep.size, 3, 3))
        V_keep = np.empty((R, keep.size, 3))
        if self.engine == "numba":
            body_pass(np.ascontiguousarray(C_b), np.ascontiguousarray(dv_b), block, keep, V_blk, C_keep, V_keep)
        else:  # the reference: the same pass in NumPy, a Python step per sample
            j = 0
            for k in range(N):
                V = V + (C @ dv_b[:, k, :, None])[..., 0]
                C = C @ C_b[:, k]
                if block[k] >= 0:
                    V_blk[:, block[k]] += V
                if j < keep.size and keep[j] == k:
                    C_keep[:, j], V_keep[:, j] = C, V
                    j += 1
        tk = t[keep] - imu.t0
        fit = np.unique(np.linspace(keep.size // 2, keep.size - 1, self.fit_points).round().astype(int))
        if vref is None:
            V_i0 = np.broadcast_to(gravity_integral_inertial(tk[fit], site.lat, site.g), (R, fit.size, 3))
            V_b0 = V_keep[:, fit]
            u = np.array([0.0, np.cos(site.lat), np.sin(site.lat)])
            C_n_i0 = np.broadcast_to(rotvec_to_dcm(np.outer(tk, u * earth.OMEGA_IE)), (R, keep.size, 3, 3))
        else:
            V_all, C_all = velocity_integral_inertial(t, imu.t0, vref, site.lat, site.h)
            C_n_i0 = C_all[:, keep]
            # block sums from cumulative sums (the blocks are contiguous: [starts[i], stops[i]))
            starts = np.concatenate([[0], edges[:-1]])
            stops = np.concatenate([[max(1, N // 4)], edges[1:]])
            cs = np.concatenate([np.zeros((R, 1, 3)), np.cumsum(V_all, axis=1)], axis=1)
            counts = (stops - starts).astype(float)[None, :, None]
            Vi_blk = (cs[:, stops] - cs[:, starts]) / counts
            Vb_blk = V_blk / counts
            V_i0, V_b0 = Vi_blk[:, 1:] - Vi_blk[:, :1], Vb_blk[:, 1:] - Vb_blk[:, :1]
        C_b0_i0 = np.empty((R, 3, 3))
        resid = np.empty(R)
        excess = np.empty(R)
        for r in range(R):
            rot, _ = Rotation.align_vectors(V_i0[r], V_b0[r])
            C_b0_i0[r] = rot.as_matrix()
            a = rot.apply(V_b0[r])
            s = np.sum(a * V_i0[r]) / np.sum(a * a)  # the common scale (the same rotation is optimal)
            resid[r] = np.sqrt(np.mean(np.sum((V_i0[r] - s * a) ** 2, axis=-1)))
            excess[r] = 1.0 / s - 1.0
        if vref is None and self.motion_mps is not None:
            T = imu.duration
            thr = self.motion_threshold_mps(T)
            r = int(np.argmax(resid))
            if resid[r] > thr:
                raise ValueError(f"{who}: the base moves (recording {r}: the inertial-frame fit leaves {resid[r]:.2f} m/s "
                                 f"rms, a stationary or swaying base less than {thr:.2f} m/s over {T:g} s); a moving "
                                 f"base needs a velocity reference (vref)")
            check_not_accelerating(excess, self.max_gravity_excess, who)
        hist = np.linspace(0, keep.size - 1, self.history_points).round().astype(int)
        hist = np.unique(hist[hist >= fit[0]])
        C_bn = np.swapaxes(C_n_i0[:, hist], -1, -2) @ C_b0_i0[:, None] @ C_keep[:, hist]
        if self.level_window_s:
            C_bn = relevel(C_bn, hist, keep, t, tk, C_n_i0, C_b0_i0, V_keep, vref, site, self.level_window_s,
                           self.level_noise_max)
        # not causal: every attitude of the history uses the fit over the second half of the whole record (its
        # settling is measured on prefixes; the attitude at the last sample is what a user gets)
        return AlignmentResult(self.name, t[keep][hist], C_bn, {"fit_residual_mps": resid, "gravity_excess": excess},
                               causal=False)
