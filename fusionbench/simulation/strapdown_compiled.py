"""The compiled strapdown engine: the mechanization of :mod:`fusionbench.simulation.strapdown` as numba kernels.

One job: integrate a batch of body-frame increments (angle ``dtheta``, rad; velocity ``dvel``, m/s; shape
``(runs, n, 3)``) in the ENU navigation frame, updating the state arrays (``C_bn`` body RFU to ENU, ``v_n`` m/s ENU,
latitude and longitude rad, height m) in place, with the same arithmetic as its NumPy oracle
(``integrate_numpy`` in ``tests/oracles/strapdown.py``). :class:`fusionbench.simulation.strapdown.Strapdown` calls
:func:`_integrate_numba`; compiled loops (damping networks, compass loops) call :func:`integrate_compiled` on the
arrays of :meth:`fusionbench.simulation.strapdown.Strapdown.compiled_state`. This module does not import
:mod:`fusionbench.simulation.strapdown`.
"""

from __future__ import annotations

from collections import namedtuple

import numba
import numpy as np

from fusionbench.simulation import earth

#: The state arrays :func:`integrate_compiled` updates in place, in its argument order (numba types a namedtuple by
#: its fields): ``C_bn`` (R, 3, 3) body RFU to ENU, ``v_n`` (R, 3) m/s ENU, ``lat``, ``lon`` (R,) rad, ``h`` (R,) m,
#: and the previous sample's velocity (R, 3) m/s, angle and velocity increments (R, 3) rad, m/s (for the coning and
#: sculling terms). :meth:`fusionbench.simulation.strapdown.Strapdown.compiled_state` returns one.
StrapdownState = namedtuple("StrapdownState", "C_bn v_n lat lon h v_prev dtheta_prev dvel_prev")

_somigliana = numba.njit(cache=True)(earth.somigliana)
_radii = numba.njit(cache=True)(earth.radii_from_sin2)
_W_IE = earth.OMEGA_IE


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
    """Compiled engine: the same arithmetic as the NumPy oracle (``tests/oracles/strapdown.py``), one run at a time.

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
#: The serial compiled engine, callable from other numba code
#: (see :meth:`fusionbench.simulation.strapdown.Strapdown.compiled_state`).
integrate_compiled = _integrate_serial
_integrate_parallel = numba.njit(cache=True, parallel=True)(_integrate_kernel)
#: Batches smaller than this (runs x samples) run serially: waking threads for a control loop's tiny
#: steps costs more than it saves, and spinning threads hurt badly on a busy machine.
PARALLEL_MIN_WORK = 20000


def _integrate_numba(*args):
    """The numba engine of :meth:`fusionbench.simulation.strapdown.Strapdown.run` (arguments of
    :func:`integrate_compiled`): threaded for batches of at least :data:`PARALLEL_MIN_WORK` run-samples, serial
    below."""
    runs, n = args[8].shape[0], args[8].shape[1]
    if runs > 1 and runs * n >= PARALLEL_MIN_WORK:
        _integrate_parallel(*args)
    else:
        _integrate_serial(*args)
