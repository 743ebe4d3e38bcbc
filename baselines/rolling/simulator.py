"""The compiled RK4 platform simulator (:mod:`baselines.rolling` module notes, "Simulator")."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np

from scipy.spatial.transform import Rotation

from fusionbench.simulation import earth

from .angles import dcm_to_angles
from .model import N_COEFFS, PAPER_ACCEL_NOISE, PAPER_GYRO_NOISE, _check_coeffs, _check_dcm, _check_site, gyro_matrix
from .scheme import Scheme, _check_scheme, commands
from .terms import accel_terms, drift_terms

# --------------------------------------------------------------------------------------------------
# simulator

_drift_nb = numba.njit(cache=True)(drift_terms)
_accel_nb = numba.njit(cache=True)(accel_terms)


@numba.njit(cache=True)
def _qdot(q0, q1, q2, q3, c, Gi, b0, b1, b2, g, wN, wU):
    """dq/dt for quaternion q (p to n): 1/2 q (x) w_ip - 1/2 w_ie (x) q, drift at the attitude q."""
    f0 = g * 2.0 * (q1 * q3 - q0 * q2)  # f^p = g * (third row of C_pn)
    f1 = g * 2.0 * (q2 * q3 + q0 * q1)
    f2 = g * (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3)
    e0, e1, e2 = _drift_nb(c, f0, f1, f2)
    u0, u1, u2 = b0 + e0, b1 + e1, b2 + e2
    w0 = Gi[0, 0] * u0 + Gi[0, 1] * u1 + Gi[0, 2] * u2
    w1 = Gi[1, 0] * u0 + Gi[1, 1] * u1 + Gi[1, 2] * u2
    w2 = Gi[2, 0] * u0 + Gi[2, 1] * u1 + Gi[2, 2] * u2
    # q (x) [0, w]: scalar -qv.w, vector q0 w + qv x w;  [0, W] (x) q: -W.qv, q0 W + W x qv (W = [0, wN, wU])
    d0 = -(q1 * w0 + q2 * w1 + q3 * w2) + (wN * q2 + wU * q3)
    d1 = q0 * w0 + (q2 * w2 - q3 * w1) - (wN * q3 - wU * q2)
    d2 = q0 * w1 + (q3 * w0 - q1 * w2) - (q0 * wN + wU * q1)
    d3 = q0 * w2 + (q1 * w1 - q2 * w0) - (q0 * wU - wN * q1)
    return 0.5 * d0, 0.5 * d1, 0.5 * d2, 0.5 * d3


def _simulate_kernel(q, coeffs, Ginv, cmd, wN, wU, g, dt, spc, spf, k_start, noise, out_C, out_y):
    """RK4 over the samples k_start .. k_start + len - 1 of each run (q updated in place).

    ``noise`` (runs, len, 3) is the gyro white drift of each sample (rad/s), or empty (runs, 0, 3) for
    none; ``len`` is its length or, when empty, ``cmd``'s remaining samples. Records C_pn and the
    noise-free accelerometer output after every spf-th sample (global sample count).
    """
    runs = q.shape[0]
    n = noise.shape[1]
    noisy = n > 0
    if not noisy:
        n = cmd.shape[1] * spc - k_start
    for r in numba.prange(runs):
        c = coeffs[r]
        Gi = Ginv[r]
        k0, k1, k2 = 1.0 + c[39], 1.0 + c[40], 1.0 + c[41]
        q0, q1, q2, q3 = q[r, 0], q[r, 1], q[r, 2], q[r, 3]
        h = 0.5 * dt
        for i in range(n):
            k = k_start + i
            j = k // spc
            b0, b1, b2 = k0 * cmd[r, j, 0], k1 * cmd[r, j, 1], k2 * cmd[r, j, 2]
            if noisy:
                b0 += noise[r, i, 0]
                b1 += noise[r, i, 1]
                b2 += noise[r, i, 2]
            a0, a1, a2, a3 = _qdot(q0, q1, q2, q3, c, Gi, b0, b1, b2, g, wN, wU)
            e0, e1, e2, e3 = _qdot(q0 + h * a0, q1 + h * a1, q2 + h * a2, q3 + h * a3, c, Gi, b0, b1, b2, g, wN, wU)
            f0, f1, f2, f3 = _qdot(q0 + h * e0, q1 + h * e1, q2 + h * e2, q3 + h * e3, c, Gi, b0, b1, b2, g, wN, wU)
            g0, g1, g2, g3 = _qdot(q0 + dt * f0, q1 + dt * f1, q2 + dt * f2, q3 + dt * f3, c, Gi, b0, b1, b2, g, wN, wU)
            q0 += dt / 6.0 * (a0 + 2.0 * (e0 + f0) + g0)
            q1 += dt / 6.0 * (a1 + 2.0 * (e1 + f1) + g1)
            q2 += dt / 6.0 * (a2 + 2.0 * (e2 + f2) + g2)
            q3 += dt / 6.0 * (a3 + 2.0 * (e3 + f3) + g3)
            nq = 1.0 / np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
            q0, q1, q2, q3 = q0 * nq, q1 * nq, q2 * nq, q3 * nq
            if (k + 1) % spf == 0:
                m = (k + 1) // spf - 1
                C = out_C[r, m]
                C[0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
                C[0, 1] = 2.0 * (q1 * q2 - q0 * q3)
                C[0, 2] = 2.0 * (q1 * q3 + q0 * q2)
                C[1, 0] = 2.0 * (q1 * q2 + q0 * q3)
                C[1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
                C[1, 2] = 2.0 * (q2 * q3 - q0 * q1)
                C[2, 0] = 2.0 * (q1 * q3 - q0 * q2)
                C[2, 1] = 2.0 * (q2 * q3 + q0 * q1)
                C[2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
                y0, y1, y2 = _accel_nb(c, g * C[2, 0], g * C[2, 1], g * C[2, 2])
                out_y[r, m, 0], out_y[r, m, 1], out_y[r, m, 2] = y0, y1, y2
        q[r, 0], q[r, 1], q[r, 2], q[r, 3] = q0, q1, q2, q3


_simulate_serial = numba.njit(cache=True)(_simulate_kernel)
#: Gyro noise is drawn (NumPy) and integrated in chunks of about this many samples per run.
_CHUNK_SAMPLES = 50000
_simulate_parallel = numba.njit(cache=True, parallel=True)(_simulate_kernel)


@dataclass
class PlatformRun:
    """Result of :func:`simulate` (SI units; leading axis: Monte Carlo runs).

    Attributes
    ----------
    t : ndarray, shape (m,)
        Output times ``k filter_s``, k = 1 .. m, s.
    y : ndarray, shape (runs, m, 3)
        Accelerometer outputs at t (X, Y, Z), m/s^2, noise included.
    y_clean : ndarray, shape (runs, m, 3)
        The same without accelerometer noise (``measurement`` of the true state).
    C_pn : ndarray, shape (runs, m, 3, 3)
        True attitude at t, p to ENU.
    w_cmd : ndarray, shape (runs, m, 3)
        Torque command held over ``(t_k - filter_s, t_k]``, rad/s.
    commands : ndarray, shape (runs, n_commands, 3)
        The command of every command period, rad/s.
    C0 : ndarray, shape (runs, 3, 3)
        Initial attitude (t = 0).
    coeffs : ndarray, shape (runs, 42)
        True coefficients, SI.
    scheme, lat, h, g :
        Scheme, latitude (rad), height (m) and gravity (m/s^2) of the run.
    wall_s : float
        Wall time of the compiled loop, s.
    """

    t: np.ndarray
    y: np.ndarray
    y_clean: np.ndarray
    C_pn: np.ndarray
    w_cmd: np.ndarray
    commands: np.ndarray
    C0: np.ndarray
    coeffs: np.ndarray
    scheme: Scheme
    lat: float
    h: float
    g: float
    wall_s: float

    @property
    def angles(self):
        """True attitude angles ``[phi, theta, psi]`` at t, rad, unwrapped along time, (runs, m, 3)."""
        a0 = dcm_to_angles(self.C0)[:, None]
        a = np.unwrap(np.concatenate([a0, dcm_to_angles(self.C_pn)], axis=1), axis=1)
        return a[:, 1:]

    @property
    def states(self):
        """True 45-vectors ``[coeffs, phi, theta, psi]`` at t, (runs, m, 45)."""
        runs, m = self.y.shape[:2]
        return np.concatenate([np.broadcast_to(self.coeffs[:, None], (runs, m, N_COEFFS)), self.angles], axis=-1)


def _per_run(x, tail, runs, name):
    x = np.asarray(x, dtype=float)
    if x.shape == tail:
        return np.ascontiguousarray(np.broadcast_to(x, (runs,) + tail))
    if x.shape == (runs,) + tail:
        return np.ascontiguousarray(x)
    raise ValueError(f"{name}: expected shape {tail} or ({runs},) + {tail}, found {x.shape}")


def _noise(x, runs, name):
    x = np.asarray(x, dtype=float)
    try:
        x = np.broadcast_to(x, (runs, 3))
    except ValueError:
        raise ValueError(f"{name}: expected a standard deviation, one per axis (3) or per run (runs, 3), "
                         f"found shape {x.shape}") from None
    if not np.all(np.isfinite(x)) or np.any(x < 0):
        raise ValueError(f"{name}: expected finite standard deviations >= 0, found {x.ravel()[:3].tolist()}")
    return np.ascontiguousarray(x)


def simulate(scheme, coeffs, C0, lat, h=0.0, gyro_noise=PAPER_GYRO_NOISE, accel_noise=PAPER_ACCEL_NOISE,
             seed=0, runs=None):
    """Simulate the floated platform rolling through a scheme; batched over Monte Carlo runs.

    Parameters
    ----------
    scheme : Scheme
        Torquing scheme (segments, command period, sample and filter intervals).
    coeffs : array_like, shape (42,) or (runs, 42)
        True error coefficients, SI (see :data:`COEFF_NAMES`).
    C0 : array_like, shape (3, 3) or (runs, 3, 3)
        Initial attitude ``C_pn`` (p to ENU); the commands follow the scheme from it.
    lat : float
        Latitude, rad.
    h : float, optional
        Height, m.
    gyro_noise : float or array_like (3,) or (runs, 3), optional
        White gyro drift, standard deviation per sample (held over ``sample_s``), rad/s.
    accel_noise : float or array_like (3,) or (runs, 3), optional
        Accelerometer noise, standard deviation of each output, m/s^2.
    seed : int, optional
        Seed of all noise (runs draw independent streams; same seed, same numbers).
    runs : int, optional
        Number of runs; default from the leading axis of ``coeffs`` or ``C0``, else 1.

    Returns
    -------
    PlatformRun
    """
    scheme = _check_scheme(scheme)
    lat, h = _check_site(lat, h)
    c = _check_coeffs(coeffs)
    C0a = _check_dcm(C0, "C0")
    if c.ndim > 2:
        raise ValueError(f"coeffs: expected shape (42,) or (runs, 42), found {c.shape}")
    if C0a.ndim > 3:
        raise ValueError(f"C0: expected shape (3, 3) or (runs, 3, 3), found {C0a.shape}")
    if runs is None:
        runs = c.shape[0] if c.ndim == 2 else (C0a.shape[0] if C0a.ndim == 3 else 1)
    if not isinstance(runs, (int, np.integer)) or runs < 1:
        raise ValueError(f"runs: expected a positive integer, found {runs!r}")
    runs = int(runs)
    c = _per_run(c, (N_COEFFS,), runs, "coeffs")
    C0a = _per_run(C0a, (3, 3), runs, "C0")
    sg = _noise(gyro_noise, runs, "gyro_noise")
    sa = _noise(accel_noise, runs, "accel_noise")
    G = gyro_matrix(c)
    if np.any(np.abs(np.linalg.det(G)) < 0.5):
        raise ValueError("coeffs: expected small gyro mounting angles (G_XY ... G_ZY), found a near-singular G")
    Ginv = np.ascontiguousarray(np.linalg.inv(G))
    try:
        seq = np.random.SeedSequence(seed)
    except (TypeError, ValueError):
        raise ValueError(f"seed: expected a non-negative integer, found {seed!r}") from None
    # one independent stream per run (gyro noise, then accelerometer noise): run r's numbers do not
    # depend on how many runs are batched with it
    rngs = [np.random.default_rng(s) for s in seq.spawn(runs)]

    cmd = np.ascontiguousarray(commands(scheme, C0a, lat))
    q = np.ascontiguousarray(Rotation.from_matrix(C0a).as_quat(scalar_first=True))
    g = float(earth.gravity(lat, h))
    w_ie = earth.earth_rate_n(lat)
    spc, spf, n, m = scheme.samples_per_command, scheme.samples_per_filter, scheme.n_samples, scheme.n_outputs
    out_C = np.empty((runs, m, 3, 3))
    out_y = np.empty((runs, m, 3))
    kernel = _simulate_parallel if runs > 1 else _simulate_serial
    args = (c, Ginv, cmd, float(w_ie[1]), float(w_ie[2]), g, scheme.sample_s, spc, spf)
    t0 = time.perf_counter()
    if np.any(sg > 0):
        chunk = spc * max(1, _CHUNK_SAMPLES // spc)
        buf = np.empty((runs, chunk, 3))
        for k in range(0, n, chunk):
            noise = buf if n - k >= chunk else np.empty((runs, n - k, 3))
            for r in range(runs):
                rngs[r].standard_normal(out=noise[r])
            noise *= sg[:, None, :]
            kernel(q, *args, k, noise, out_C, out_y)
    else:
        kernel(q, *args, 0, np.zeros((runs, 0, 3)), out_C, out_y)
    wall = time.perf_counter() - t0
    y = out_y + sa[:, None, :] * np.stack([rng.standard_normal((m, 3)) for rng in rngs])
    t = (np.arange(m) + 1) * scheme.filter_s
    w_cmd = cmd[:, (np.arange(m) * spf) // spc]
    return PlatformRun(t=t, y=y, y_clean=out_y, C_pn=out_C, w_cmd=w_cmd, commands=cmd, C0=C0a, coeffs=c,
                       scheme=scheme, lat=lat, h=h, g=g, wall_s=wall)

