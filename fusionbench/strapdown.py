"""Strapdown mechanization in the ENU navigation frame, batched over Monte Carlo runs.

State per run: attitude ``C_bn`` (body RFU to ENU), velocity ``v_n`` (ENU, m/s), position
(latitude, longitude in rad, height in m). Inputs are IMU increments over one sample interval
``dt``: angle increments ``dtheta`` (rad) and velocity increments ``dvel`` (m/s) in the body frame,
shape ``(runs, samples, 3)``.

One step k (Savage's "one sample plus previous" form, the two-sample coning and sculling
compensation used by pyins and PSINS):

* coning: ``phi_b = dth_k + dth_{k-1} x dth_k / 12``;
* rotation and sculling: ``dv_b = dv_k + dth_k x dv_k / 2 + (dth_{k-1} x dv_k + dv_{k-1} x dth_k) / 12``;
* navigation-frame rotation ``zeta = (omega_ie^n + omega_en^n + omega_c) dt``, with the
  earth and transport rates at the mid-interval state (velocity extrapolated from the last two
  steps) and ``omega_c`` an optional commanded angular rate (rad/s, resolved in the computed
  n frame) for compass and damping loops;
* attitude ``C_bn <- exp(-[zeta x]) C_bn exp([phi_b x])``;
* velocity ``v <- v + (I - [zeta x]/2) C_bn dv_b + (g^n - (2 omega_ie^n + omega_en^n) x v_mid) dt``;
* position by the trapezoid rule on velocity.

Two engines do the same arithmetic: ``"numba"`` (default), a compiled loop over runs and samples,
and ``"numpy"``, a Python loop over samples with NumPy arrays over runs; the second is the
readable reference the tests compare the first with (``benchmarks/perf_core.py`` shows the gain).

Long recordings are processed in chunks (:meth:`Strapdown.run` takes any number of samples and
keeps its state between calls), so a 20-hour, 100 Hz run never holds more than a chunk.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from . import earth

_somigliana = numba.njit(cache=True)(earth.somigliana)
_radii = numba.njit(cache=True)(earth.radii_from_sin2)
_W_IE = earth.OMEGA_IE

_I3 = np.eye(3)


def _cross(a, b):
    """Cross product along the last axis (faster than np.cross for small batches)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def rodrigues(rv):
    """Rotation matrices exp([rv x]) for rotation vectors ``rv`` (rad), ``(..., 3)`` -> ``(..., 3, 3)``.

    Uses series expansions of sin(x)/x and (1 - cos x)/x^2 for tiny angles, so increments of
    1e-9 rad keep full relative precision.
    """
    rv = np.asarray(rv, dtype=float)
    x2 = np.einsum("...i,...i->...", rv, rv)
    small = x2 < 1e-6
    x = np.sqrt(x2)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(small, 1 - x2 / 6 * (1 - x2 / 20), np.sin(x) / np.where(small, 1, x))
        b = np.where(small, 0.5 * (1 - x2 / 12 * (1 - x2 / 30)), (1 - np.cos(x)) / np.where(small, 1, x2))
    K = np.zeros(rv.shape + (3,))
    K[..., 0, 1] = -rv[..., 2]
    K[..., 0, 2] = rv[..., 1]
    K[..., 1, 0] = rv[..., 2]
    K[..., 1, 2] = -rv[..., 0]
    K[..., 2, 0] = -rv[..., 1]
    K[..., 2, 1] = rv[..., 0]
    return _I3 + a[..., None, None] * K + b[..., None, None] * (K @ K)


def coning_sculling(dtheta, dvel, dtheta_prev, dvel_prev):
    """Coning- and sculling-compensated increments for a chunk (the two-sample forms)::

        phi  = dtheta + dtheta_prev x dtheta / 12
        dv_b = dvel + dtheta x dvel / 2 + (dtheta_prev x dvel + dvel_prev x dtheta) / 12

    Parameters
    ----------
    dtheta, dvel : ndarray, shape (runs, n, 3)
        Angle (rad) and velocity (m/s) increments, body frame.
    dtheta_prev, dvel_prev : ndarray, shape (runs, 3)
        The increments of the sample before the chunk (zeros at the very start).

    Returns
    -------
    phi : ndarray, shape (runs, n, 3)
        Rotation vector of each sample interval, rad, body frame.
    dv_b : ndarray, shape (runs, n, 3)
        Rotation- and sculling-compensated velocity increments, body frame at the interval start.
    """
    th_prev = np.concatenate([dtheta_prev[:, None], dtheta[:, :-1]], axis=1)
    dv_prev = np.concatenate([dvel_prev[:, None], dvel[:, :-1]], axis=1)
    phi = dtheta + _cross(th_prev, dtheta) / 12.0
    dv_b = dvel + 0.5 * _cross(dtheta, dvel) + (_cross(th_prev, dvel) + _cross(dv_prev, dtheta)) / 12.0
    return phi, dv_b


def body_increments(dtheta, dvel, dtheta_prev, dvel_prev):
    """Coning- and sculling-compensated body increments for a chunk (:func:`coning_sculling`).

    Returns
    -------
    C_b : ndarray, shape (runs, n, 3, 3)
        Body attitude increments exp([phi_b x]).
    dv_b : ndarray, shape (runs, n, 3)
        Rotation- and sculling-compensated velocity increments, body frame at the interval start.
    """
    phi, dv_b = coning_sculling(dtheta, dvel, dtheta_prev, dvel_prev)
    return rodrigues(phi), dv_b


@dataclass
class NavState:
    """Navigation state of a batch of runs.

    Attributes
    ----------
    C_bn : ndarray, shape (runs, 3, 3)
        Attitude, body RFU to ENU.
    v_n : ndarray, shape (runs, 3)
        Velocity over the earth, ENU, m/s.
    lat, lon, h : ndarray, shape (runs,)
        Geodetic latitude and longitude (rad), height (m).
    """

    C_bn: np.ndarray
    v_n: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray

    @classmethod
    def broadcast(cls, runs, C_bn, v_n=(0.0, 0.0, 0.0), lat=0.0, lon=0.0, h=0.0):
        """State for ``runs`` runs from one value or per-run values of each quantity (SI)."""
        C = np.broadcast_to(np.asarray(C_bn, dtype=float), (runs, 3, 3)).copy()
        v = np.broadcast_to(np.asarray(v_n, dtype=float), (runs, 3)).copy()
        b = lambda x: np.broadcast_to(np.asarray(x, dtype=float), (runs,)).copy()  # noqa: E731
        return cls(C, v, b(lat), b(lon), b(h))

    def copy(self):
        return NavState(self.C_bn.copy(), self.v_n.copy(), self.lat.copy(), self.lon.copy(), self.h.copy())


class Strapdown:
    """Batched ENU strapdown integrator that keeps its state between chunks.

    Parameters
    ----------
    state : NavState
        Initial state at the start of the first sample interval.
    dt : float
        Sample interval, s.
    position_fixed : bool, optional
        If True, latitude, longitude and height stay at their initial values and the transport rate
        is zero (the usual choice for alignment on a stationary base, where the velocity is an
        error, not motion).
    engine : {"numba", "numpy"}, optional
        Compiled loop (default) or the NumPy reference loop; results agree to rounding.
    height_fixed : bool, optional
        Hold the height and zero the vertical velocity (the vertical channel of a free inertial
        solution diverges with time constant sqrt(R / 2g), about 9.5 min); implied by
        ``position_fixed``.

    Notes
    -----
    ``run`` returns the history of the state after every ``record_every``-th sample; memory is
    therefore ``O(chunk)`` however long the recording.
    """

    def __init__(self, state: NavState, dt: float, position_fixed: bool = False, engine: str = "numba",
                 height_fixed: bool = False):
        if engine not in ("numba", "numpy"):
            raise ValueError(f"engine: expected 'numba' or 'numpy', found {engine!r}")
        self.engine = engine
        self.state = state.copy()
        self.dt = float(dt)
        self.position_fixed = position_fixed
        self.height_fixed = height_fixed or position_fixed
        runs = state.C_bn.shape[0]
        self._th_prev = np.zeros((runs, 3))
        self._dv_prev = np.zeros((runs, 3))
        self._v_prev = self.state.v_n.copy()

    @property
    def runs(self):
        return self.state.C_bn.shape[0]

    def compiled_state(self):
        """The state arrays :func:`integrate_compiled` updates in place, in its argument order:
        ``C_bn, v_n, lat, lon, h, v_prev, dtheta_prev, dvel_prev``.

        For loops that feed back into the strapdown every few samples (damping networks, compass
        loops) written as compiled code: they call ``integrate_compiled(*state, dtheta, dvel, cmd,
        dt, position_fixed, height_fixed, record_every, out_C, out_v, out_p)`` on consecutive slices,
        exactly as :meth:`run` does, and this object stays consistent for later :meth:`run` calls.
        """
        s = self.state
        return s.C_bn, s.v_n, s.lat, s.lon, s.h, self._v_prev, self._th_prev, self._dv_prev

    def run(self, dtheta, dvel, omega_cmd=None, record_every=1):
        """Integrate a chunk of increments.

        Parameters
        ----------
        dtheta, dvel : array_like, shape (runs, n, 3)
            Body-frame angle (rad) and velocity (m/s) increments.
        omega_cmd : array_like, shape (runs, n, 3) or (runs, 3), optional
            Commanded angular rate of the computed n frame, rad/s, ENU; added to the frame rate.
        record_every : int, optional
            Record the state after every this many samples.

        Returns
        -------
        dict
            ``C_bn`` (runs, m, 3, 3), ``v_n`` (runs, m, 3), ``lat``, ``lon``, ``h`` (runs, m) after
            samples ``record_every - 1, 2 record_every - 1, ...`` of the chunk, ``m = n // record_every``.
        """
        dtheta = np.ascontiguousarray(dtheta, dtype=float)
        dvel = np.ascontiguousarray(dvel, dtype=float)
        if dtheta.ndim != 3 or dtheta.shape[0] != self.runs or dtheta.shape[2] != 3:
            raise ValueError(f"dtheta: expected shape ({self.runs}, n, 3), found {dtheta.shape}")
        if dvel.shape != dtheta.shape:
            raise ValueError(f"dvel: expected shape {dtheta.shape}, found {dvel.shape}")
        runs, n, _ = dtheta.shape
        record_every = int(record_every)
        if omega_cmd is None:
            cmd = np.zeros((runs, 0, 3))
        else:
            cmd = np.asarray(omega_cmd, dtype=float)
            cmd = np.ascontiguousarray(np.broadcast_to(cmd[:, None] if cmd.ndim == 2 else cmd, (runs, n, 3)))
        m = n // record_every
        out_C = np.empty((runs, m, 3, 3))
        out_v = np.empty((runs, m, 3))
        out_p = np.empty((runs, m, 3))
        s = self.state
        args = (s.C_bn, s.v_n, s.lat, s.lon, s.h, self._v_prev, self._th_prev, self._dv_prev,
                dtheta, dvel, cmd, self.dt, self.position_fixed, self.height_fixed, record_every, out_C, out_v, out_p)
        if self.engine == "numba":
            _integrate_numba(*args)
        else:
            _integrate_numpy(*args)
        return {"C_bn": out_C, "v_n": out_v, "lat": out_p[..., 0], "lon": out_p[..., 1], "h": out_p[..., 2]}


def _integrate_numpy(C0, v0, lat0, lon0, h0, v_prev0, th_prev, dv_prev, dtheta, dvel, cmd, dt,
                     position_fixed, height_fixed, record_every, out_C, out_v, out_p):
    """Reference engine: loop over samples, NumPy over runs. Updates the state arrays in place."""
    n = dtheta.shape[1]
    C_b, dv_b = body_increments(dtheta, dvel, th_prev, dv_prev)
    C, v, lat, lon, h, v_prev = C0.copy(), v0.copy(), lat0.copy(), lon0.copy(), h0.copy(), v_prev0.copy()
    for k in range(n):
        v_mid = 1.5 * v - 0.5 * v_prev
        rm, rn = earth.radii(lat)
        rmh, rnh = rm + h, rn + h
        g_n = earth.gravity_n(lat, h)
        w_ie = earth.earth_rate_n(lat)
        w_en = earth.transport_rate_n(v_mid, lat, h) * (not position_fixed)
        w_in = w_ie + w_en
        if cmd.shape[1]:
            w_in = w_in + cmd[:, k]
        zeta = w_in * dt
        dv_n = (C @ dv_b[:, k, :, None])[..., 0]
        dv_n = dv_n - 0.5 * _cross(zeta, dv_n)
        v_new = v + dv_n + (g_n - _cross(2.0 * w_ie + w_en, v_mid)) * dt
        if height_fixed:
            v_new[:, 2] = 0.0
        C = np.swapaxes(rodrigues(zeta), -1, -2) @ C @ C_b[:, k]
        if not position_fixed:
            vm = 0.5 * (v + v_new)
            h = h if height_fixed else h + vm[:, 2] * dt
            lat = lat + vm[:, 1] / rmh * dt
            lon = lon + vm[:, 0] / (rnh * np.cos(lat)) * dt
        v_prev, v = v, v_new
        if (k + 1) % record_every == 0:
            j = (k + 1) // record_every - 1
            out_C[:, j] = C
            out_v[:, j] = v
            out_p[:, j] = np.stack([lat, lon, h], -1)
    C0[:] = 1.5 * C - 0.5 * C @ np.swapaxes(C, -1, -2) @ C  # first-order re-orthonormalisation
    v0[:], lat0[:], lon0[:], h0[:], v_prev0[:] = v, lat, lon, h, v_prev
    th_prev[:] = dtheta[:, -1]
    dv_prev[:] = dvel[:, -1]


@numba.njit(cache=True)
def _rodrigues3(x, y, z, out):
    """exp([r x]) for r = (x, y, z), written into the 3x3 array ``out``."""
    x2 = x * x + y * y + z * z
    if x2 < 1e-6:
        a = 1.0 - x2 / 6.0 * (1.0 - x2 / 20.0)
        b = 0.5 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0))
    else:
        t = np.sqrt(x2)
        a = np.sin(t) / t
        b = (1.0 - np.cos(t)) / x2
    out[0, 0] = 1.0 - b * (y * y + z * z)
    out[1, 1] = 1.0 - b * (x * x + z * z)
    out[2, 2] = 1.0 - b * (x * x + y * y)
    out[0, 1] = -a * z + b * x * y
    out[1, 0] = a * z + b * x * y
    out[0, 2] = a * y + b * x * z
    out[2, 0] = -a * y + b * x * z
    out[1, 2] = -a * x + b * y * z
    out[2, 1] = a * x + b * y * z


def _integrate_kernel(C0, v0, lat0, lon0, h0, v_prev0, th_prev, dv_prev, dtheta, dvel, cmd, dt,
                     position_fixed, height_fixed, record_every, out_C, out_v, out_p):
    """Compiled engine: the same arithmetic as :func:`_integrate_numpy`, one run at a time.

    Compiled twice (below): serial, and with the run loop spread over threads (``prange``)."""
    runs, n = dtheta.shape[0], dtheta.shape[1]
    has_cmd = cmd.shape[1] > 0
    for r in numba.prange(runs):  # runs are independent: one thread each, results bit-identical
        B = np.empty((3, 3))
        N = np.empty((3, 3))
        T = np.empty((3, 3))
        C = np.empty((3, 3))
        dvb = np.empty(3)
        dvn = np.empty(3)
        C[:, :] = C0[r]
        vE, vN, vU = v0[r, 0], v0[r, 1], v0[r, 2]
        pE, pN, pU = v_prev0[r, 0], v_prev0[r, 1], v_prev0[r, 2]
        lat, lon, h = lat0[r], lon0[r], h0[r]
        a0, a1, a2 = th_prev[r, 0], th_prev[r, 1], th_prev[r, 2]
        u0, u1, u2 = dv_prev[r, 0], dv_prev[r, 1], dv_prev[r, 2]
        for k in range(n):
            t0, t1, t2 = dtheta[r, k, 0], dtheta[r, k, 1], dtheta[r, k, 2]
            w0, w1, w2 = dvel[r, k, 0], dvel[r, k, 1], dvel[r, k, 2]
            # coning and sculling
            f0 = t0 + (a1 * t2 - a2 * t1) / 12.0
            f1 = t1 + (a2 * t0 - a0 * t2) / 12.0
            f2 = t2 + (a0 * t1 - a1 * t0) / 12.0
            dvb[0] = w0 + 0.5 * (t1 * w2 - t2 * w1) + ((a1 * w2 - a2 * w1) + (u1 * t2 - u2 * t1)) / 12.0
            dvb[1] = w1 + 0.5 * (t2 * w0 - t0 * w2) + ((a2 * w0 - a0 * w2) + (u2 * t0 - u0 * t2)) / 12.0
            dvb[2] = w2 + 0.5 * (t0 * w1 - t1 * w0) + ((a0 * w1 - a1 * w0) + (u0 * t1 - u1 * t0)) / 12.0
            a0, a1, a2, u0, u1, u2 = t0, t1, t2, w0, w1, w2
            # navigation-frame rates at the extrapolated mid-interval velocity
            mE, mN, mU = 1.5 * vE - 0.5 * pE, 1.5 * vN - 0.5 * pN, 1.5 * vU - 0.5 * pU
            sl, cl = np.sin(lat), np.cos(lat)
            rm, rn = _radii(sl * sl)
            rmh, rnh = rm + h, rn + h
            g = _somigliana(sl * sl, h)
            ieN, ieU = _W_IE * cl, _W_IE * sl
            if position_fixed:
                enE, enN, enU = 0.0, 0.0, 0.0
            else:
                enE, enN, enU = -mN / rmh, mE / rnh, mE * (sl / cl) / rnh
            z0, z1, z2 = enE, ieN + enN, ieU + enU
            if has_cmd:
                z0 += cmd[r, k, 0]
                z1 += cmd[r, k, 1]
                z2 += cmd[r, k, 2]
            z0, z1, z2 = z0 * dt, z1 * dt, z2 * dt
            # velocity
            for i in range(3):
                dvn[i] = C[i, 0] * dvb[0] + C[i, 1] * dvb[1] + C[i, 2] * dvb[2]
            d0 = dvn[0] - 0.5 * (z1 * dvn[2] - z2 * dvn[1])
            d1 = dvn[1] - 0.5 * (z2 * dvn[0] - z0 * dvn[2])
            d2 = dvn[2] - 0.5 * (z0 * dvn[1] - z1 * dvn[0])
            c0, c1, c2 = enE, 2.0 * ieN + enN, 2.0 * ieU + enU
            nE = vE + d0 - (c1 * mU - c2 * mN) * dt
            nN = vN + d1 - (c2 * mE - c0 * mU) * dt
            nU = vU + d2 + (-g - (c0 * mN - c1 * mE)) * dt
            if height_fixed:
                nU = 0.0
            # attitude: C <- N^T C B
            _rodrigues3(f0, f1, f2, B)
            _rodrigues3(-z0, -z1, -z2, N)
            for i in range(3):
                for j in range(3):
                    T[i, j] = C[i, 0] * B[0, j] + C[i, 1] * B[1, j] + C[i, 2] * B[2, j]
            for i in range(3):
                for j in range(3):
                    C[i, j] = N[i, 0] * T[0, j] + N[i, 1] * T[1, j] + N[i, 2] * T[2, j]
            if not position_fixed:
                if not height_fixed:
                    h = h + 0.5 * (vU + nU) * dt
                lat = lat + 0.5 * (vN + nN) / rmh * dt
                lon = lon + 0.5 * (vE + nE) / (rnh * np.cos(lat)) * dt
            pE, pN, pU = vE, vN, vU
            vE, vN, vU = nE, nN, nU
            if (k + 1) % record_every == 0:
                j = (k + 1) // record_every - 1
                out_C[r, j] = C
                out_v[r, j, 0], out_v[r, j, 1], out_v[r, j, 2] = vE, vN, vU
                out_p[r, j, 0], out_p[r, j, 1], out_p[r, j, 2] = lat, lon, h
        # first-order re-orthonormalisation C <- 1.5 C - 0.5 C C^T C
        CtC = C.T @ C
        C0[r] = 1.5 * C - 0.5 * C @ CtC
        v0[r, 0], v0[r, 1], v0[r, 2] = vE, vN, vU
        v_prev0[r, 0], v_prev0[r, 1], v_prev0[r, 2] = pE, pN, pU
        lat0[r], lon0[r], h0[r] = lat, lon, h
        th_prev[r, 0], th_prev[r, 1], th_prev[r, 2] = a0, a1, a2
        dv_prev[r, 0], dv_prev[r, 1], dv_prev[r, 2] = u0, u1, u2


_integrate_serial = numba.njit(cache=True)(_integrate_kernel)
#: The serial compiled engine, callable from other numba code (see :meth:`Strapdown.compiled_state`).
integrate_compiled = _integrate_serial
_integrate_parallel = numba.njit(cache=True, parallel=True)(_integrate_kernel)
#: Batches smaller than this (runs x samples) run serially: waking threads for a control loop's tiny
#: steps costs more than it saves, and spinning threads hurt badly on a busy machine.
PARALLEL_MIN_WORK = 20000


def _integrate_numba(*args):
    runs, n = args[8].shape[0], args[8].shape[1]
    if runs > 1 and runs * n >= PARALLEL_MIN_WORK:
        _integrate_parallel(*args)
    else:
        _integrate_serial(*args)
