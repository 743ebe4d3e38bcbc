"""The inertial-frame coarse alignment's pass over the samples, compiled (``coarse-i0``'s loop).

:class:`fusionbench.methods.coarse.InertialCoarseAligner` carries, for every run, the body attitude since the start
``C`` (the product of the per-sample body rotations, body frame at t0 to body frame now) and the integrated
specific force ``V`` (m/s, in the body frame at t0) over every sample, and keeps ``C`` at a few hundred samples (the
history) and ``V`` at those and at the samples around each aiding row (and, for rows that give a mean velocity over
an interval, the integral of ``V``, m). In NumPy that is a Python loop over the
samples with a few (R, 3, 3) products each (``tests/oracles/coarse.py``, the reference the tests hold it to); here
it is one compiled loop over runs and samples, the same arithmetic.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def body_pass(C_b, dv_b, dt, ckeep, vkeep, C_out, V_out, P_out):
    """For each run r and sample k: ``V += C dv_b[r, k]``, ``C = C C_b[r, k]``, ``P += (V_before + V) dt / 2`` from
    ``C = I``, ``V = 0``, ``P = 0``.

    Parameters
    ----------
    C_b : ndarray, shape (R, N, 3, 3)
        Body rotation over each sample (body frame at its end to body frame at its start).
    dv_b : ndarray, shape (R, N, 3)
        Velocity increment of each sample in the body frame at its start, m/s.
    dt : float
        Sample interval, s.
    ckeep, vkeep : ndarray of int, shapes (Kc,) and (Kv,)
        Strictly increasing sample indices after which ``C`` and ``V`` are stored.
    C_out, V_out : ndarray, shapes (R, Kc, 3, 3) and (R, Kv, 3)
        Outputs (``C_out[r, j]`` after sample ``ckeep[j]``; ``V_out`` in m/s, body frame at t0), written in place.
    P_out : ndarray, shape (R, Kv, 3) or (R, 0, 3)
        The integral of ``V`` (trapezoid rule), m, after the samples ``vkeep`` (none stored when empty).
    """
    R, N = dv_b.shape[0], dv_b.shape[1]
    Kc, Kv = ckeep.shape[0], vkeep.shape[0]
    with_p = P_out.shape[1] > 0
    C = np.empty((3, 3))
    T = np.empty((3, 3))
    V = np.empty(3)
    P = np.empty(3)
    for r in range(R):
        C[:] = 0.0
        C[0, 0] = C[1, 1] = C[2, 2] = 1.0
        V[:] = 0.0
        P[:] = 0.0
        jc = 0
        jv = 0
        for k in range(N):
            d0, d1, d2 = dv_b[r, k, 0], dv_b[r, k, 1], dv_b[r, k, 2]
            for i in range(3):
                dV = C[i, 0] * d0 + C[i, 1] * d1 + C[i, 2] * d2
                P[i] = P[i] + (V[i] + 0.5 * dV) * dt
                V[i] = V[i] + dV
            B = C_b[r, k]
            for i in range(3):
                for m in range(3):
                    T[i, m] = C[i, 0] * B[0, m] + C[i, 1] * B[1, m] + C[i, 2] * B[2, m]
            C[:] = T
            if jc < Kc and ckeep[jc] == k:
                C_out[r, jc] = C
                jc += 1
            if jv < Kv and vkeep[jv] == k:
                V_out[r, jv] = V
                if with_p:
                    P_out[r, jv] = P
                jv += 1
