"""The inertial-frame coarse alignment's pass over the samples, compiled (``coarse-i0``'s default engine).

:class:`fusionbench.coarse.InertialCoarseAligner` carries, for every run, the body attitude since the start
``C`` (the product of the per-sample body rotations, body frame at t0 to body frame now) and the integrated
specific force ``V`` (m/s, in the body frame at t0) over every sample, and keeps them at a few hundred samples. In
NumPy that is a Python loop over the samples with a few (R, 3, 3) products each (``engine="numpy"``, the reference);
here it is one compiled loop over runs and samples, the same arithmetic.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def body_pass(C_b, dv_b, block, keep, V_blk, C_keep, V_keep):
    """For each run r and sample k: ``V += C dv_b[r, k]``, ``C = C C_b[r, k]`` from ``C = I``, ``V = 0``.

    Parameters
    ----------
    C_b : ndarray, shape (R, N, 3, 3)
        Body rotation over each sample (body frame at its end to body frame at its start).
    dv_b : ndarray, shape (R, N, 3)
        Velocity increment of each sample in the body frame at its start, m/s.
    block : ndarray of int, shape (N,)
        Block of each sample (-1: none): ``V`` after the sample is added to ``V_blk[r, block[k]]``.
    keep : ndarray of int, shape (K,)
        Increasing sample indices at which ``C`` and ``V`` are stored in ``C_keep[r, j]``, ``V_keep[r, j]``.
    V_blk : ndarray, shape (R, B, 3)
        Block sums, added to in place (m/s).
    C_keep, V_keep : ndarray, shape (R, K, 3, 3) and (R, K, 3)
        Outputs, written in place.
    """
    R, N = dv_b.shape[0], dv_b.shape[1]
    K = keep.shape[0]
    C = np.empty((3, 3))
    T = np.empty((3, 3))
    V = np.empty(3)
    for r in range(R):
        C[:] = 0.0
        C[0, 0] = C[1, 1] = C[2, 2] = 1.0
        V[:] = 0.0
        j = 0
        for k in range(N):
            d0, d1, d2 = dv_b[r, k, 0], dv_b[r, k, 1], dv_b[r, k, 2]
            for i in range(3):
                V[i] = V[i] + (C[i, 0] * d0 + C[i, 1] * d1 + C[i, 2] * d2)
            B = C_b[r, k]
            for i in range(3):
                for m in range(3):
                    T[i, m] = C[i, 0] * B[0, m] + C[i, 1] * B[1, m] + C[i, 2] * B[2, m]
            C[:] = T
            b = block[k]
            if b >= 0:
                for i in range(3):
                    V_blk[r, b, i] += V[i]
            if j < K and keep[j] == k:
                C_keep[r, j] = C
                V_keep[r, j] = V
                j += 1
