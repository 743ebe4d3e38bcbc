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

The loop over runs and samples is compiled (:mod:`fusionbench.simulation.strapdown_compiled`); the tests hold it to a
NumPy loop over samples with arrays over runs that makes the same operations (``tests/oracles/strapdown.py``).

Long recordings are processed in chunks (:meth:`Strapdown.run` takes any number of samples and
keeps its state between calls), so a 20-hour, 100 Hz run never holds more than a chunk.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusionbench.simulation.strapdown_compiled import StrapdownState, _integrate_numba

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
    """Coning- and sculling-compensated increments for a chunk.

    The two-sample forms::

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
    height_fixed : bool, optional
        Hold the height and zero the vertical velocity (the vertical channel of a free inertial
        solution diverges with time constant sqrt(R / 2g), about 9.5 min); implied by
        ``position_fixed``.

    Notes
    -----
    ``run`` returns the history of the state after every ``record_every``-th sample; memory is
    therefore ``O(chunk)`` however long the recording.
    """

    def __init__(self, state: NavState, dt: float, position_fixed: bool = False, height_fixed: bool = False):
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
        """The state arrays :func:`fusionbench.simulation.strapdown_compiled.integrate_compiled` updates in place, in
        its argument order, as a :data:`~fusionbench.simulation.strapdown_compiled.StrapdownState`: ``C_bn, v_n,
        lat, lon, h, v_prev, dtheta_prev, dvel_prev``.

        For loops that feed back into the strapdown every few samples (damping networks, compass
        loops) written as compiled code: they call ``integrate_compiled(*state, dtheta, dvel, cmd,
        dt, position_fixed, height_fixed, record_every, out_C, out_v, out_p)`` on consecutive slices,
        exactly as :meth:`run` does, and this object stays consistent for later :meth:`run` calls.
        """
        s = self.state
        return StrapdownState(s.C_bn, s.v_n, s.lat, s.lon, s.h, self._v_prev, self._th_prev, self._dv_prev)

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
        _integrate_numba(*args)
        return {"C_bn": out_C, "v_n": out_v, "lat": out_p[..., 0], "lon": out_p[..., 1], "h": out_p[..., 2]}
