"""The backward covariance recursion over a QR-eliminated Bayes net, compiled (:class:`baselines.graph_posterior.Posterior`).

A Bayes net of ``n`` conditionals ``R x_f + S x_P = d + e`` (one frontal variable each, in elimination order) is
held in flat arrays, its *structure*:

- ``dims`` (n,): each frontal variable's tangent dimension; a variable is named by its conditional's position;
- ``par_ptr`` (n + 1,), ``par_idx``: the positions of each conditional's parents (``par_idx[par_ptr[i]:par_ptr[i+1]]``,
  in the order of the columns of its ``S``), and ``par_col``: where each parent's columns start in that ``S``;
- ``D`` (n,): the columns of each ``S``; ``sq_off`` (n + 1,), ``rect_off`` (n + 1,): where each conditional's
  ``d x d`` and ``d x D`` blocks start in the flat arrays (row-major).

The covariances come back as ``sig`` (the ``d x d`` marginal of each variable, at ``sq_off``) and ``cross`` (its
``d x D`` covariance with its parents, at ``rect_off``). Any two variables in one clique are a variable and one of its
parents, so these blocks hold every covariance of a clique (:func:`joint_covariance`). Units are those of the
variables' tangent spaces. Explicit loops over blocks of at most a few dozen columns: no BLAS call, whose threads and
kernels would differ from machine to machine. The dictionary-based recursion they replaced is the NumPy oracle
``tests/oracles/graph_posterior.py``.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _column(par_ptr, par_idx, par_col, a, b):
    """Where parent ``b``'s columns start in conditional ``a``'s ``S``; -1 when ``b`` is not a parent of ``a``."""
    for j in range(par_ptr[a], par_ptr[a + 1]):
        if par_idx[j] == b:
            return par_col[j]
    return -1


@numba.njit(cache=True)
def _joint(pos, dims, par_ptr, par_idx, par_col, D, sq_off, rect_off, sig, cross, P):
    """The joint covariance of the variables at positions ``pos`` into ``P`` (zeros where two never share a
    clique)."""
    P[:] = 0.0
    oa = 0
    for a in range(pos.shape[0]):
        pa = pos[a]
        da = dims[pa]
        for r in range(da):
            for c in range(da):
                P[oa + r, oa + c] = sig[sq_off[pa] + r * da + c]
        ob = oa + da
        for b in range(a + 1, pos.shape[0]):
            pb = pos[b]
            db = dims[pb]
            # the earlier-eliminated of the two holds the later among its parents
            first, other, r0, c0, dr, dc = (pa, pb, oa, ob, da, db) if pa < pb else (pb, pa, ob, oa, db, da)
            col = _column(par_ptr, par_idx, par_col, first, other)
            if col >= 0:
                base, width = rect_off[first], D[first]
                for r in range(dr):
                    for c in range(dc):
                        v = cross[base + r * width + col + c]
                        P[r0 + r, c0 + c] = v
                        P[c0 + c, r0 + r] = v
            ob += db
        oa += da


@numba.njit(cache=True)
def _recursion(dims, par_ptr, par_idx, par_col, D, sq_off, rect_off, R_inv, sigmas, S, sig, cross):
    n = dims.shape[0]
    v0 = 0
    for i in range(n):
        v0 += dims[i]
    for i in range(n - 1, -1, -1):  # each variable after its parents
        d, w, s0 = dims[i], D[i], rect_off[i]
        v0 -= d  # where its sigmas start
        Ri = R_inv[sq_off[i]:sq_off[i] + d * d].reshape((d, d))
        # cov(x_f | x_P) = R^-1 diag(sigma^2) R^-T
        for r in range(d):
            for c in range(d):
                acc = 0.0
                for m in range(d):
                    acc += Ri[r, m] * Ri[c, m] * sigmas[v0 + m] * sigmas[v0 + m]
                sig[sq_off[i] + r * d + c] = acc
        if w == 0:
            continue
        A = np.zeros((d, w))  # R^-1 S
        for r in range(d):
            for m in range(d):
                x = Ri[r, m]
                if x != 0.0:
                    for c in range(w):
                        A[r, c] += x * S[s0 + m * w + c]
        P = np.empty((w, w))
        _joint(par_idx[par_ptr[i]:par_ptr[i + 1]], dims, par_ptr, par_idx, par_col, D, sq_off, rect_off, sig, cross,
               P)
        # Sigma_fP = -A Sigma_PP; Sigma_ff = R^-1 diag(sigma^2) R^-T - Sigma_fP A^T
        for r in range(d):
            for c in range(w):
                acc = 0.0
                for m in range(w):
                    acc += A[r, m] * P[m, c]
                cross[s0 + r * w + c] = -acc
        for r in range(d):
            for c in range(d):
                acc = 0.0
                for m in range(w):
                    acc += cross[s0 + r * w + m] * A[c, m]
                sig[sq_off[i] + r * d + c] -= acc


def structure(dims, parents):
    """The structure arrays of a Bayes net (module docstring) from its conditionals' dimensions and parents.

    Parameters
    ----------
    dims : sequence of int, length n
        Each frontal variable's tangent dimension, in elimination order.
    parents : sequence of sequences of int
        Each conditional's parents, as positions in that order (each after its child), in the order of ``S``'s columns.

    Returns
    -------
    tuple of ndarray of int
        ``(dims, par_ptr, par_idx, par_col, D, sq_off, rect_off)``.
    """
    dims = np.asarray(dims, dtype=np.int64)
    n_par = np.fromiter((len(p) for p in parents), dtype=np.int64, count=dims.size)
    par_ptr = np.r_[0, np.cumsum(n_par)].astype(np.int64)
    par_idx = np.fromiter((q for p in parents for q in p), dtype=np.int64, count=int(par_ptr[-1]))
    cols = np.r_[0, np.cumsum(dims[par_idx])].astype(np.int64)
    D = cols[par_ptr[1:]] - cols[par_ptr[:-1]]
    par_col = cols[:-1] - np.repeat(cols[par_ptr[:-1]], n_par)
    sq_off = np.r_[0, np.cumsum(dims * dims)].astype(np.int64)
    rect_off = np.r_[0, np.cumsum(dims * D)].astype(np.int64)
    return dims, par_ptr, par_idx, par_col, D, sq_off, rect_off


def covariances(net, R_inv, sigmas, S):
    """The covariances of every variable and of each with its parents, from the conditionals.

    Parameters
    ----------
    net : tuple
        The net's structure (:func:`structure`).
    R_inv : ndarray, shape (sq_off[-1],)
        Each conditional's ``R^-1``, row-major, one after the other.
    sigmas : ndarray, shape (sum(dims),)
        The noise sigma of each row of each conditional (1 where its model is unit).
    S : ndarray, shape (rect_off[-1],)
        Each conditional's ``S``, row-major (columns in the order of its parents).

    Returns
    -------
    sig, cross : ndarray
        Flat ``d x d`` marginal covariances (at ``sq_off``) and ``d x D`` covariances with the parents (at
        ``rect_off``).
    """
    sig, cross = np.empty(int(net[5][-1])), np.empty(int(net[6][-1]))
    _recursion(*net, np.ascontiguousarray(R_inv, dtype=float), np.ascontiguousarray(sigmas, dtype=float),
               np.ascontiguousarray(S, dtype=float), sig, cross)
    return sig, cross


def joint_covariance(net, cov, pos):
    """The joint covariance of the variables at positions ``pos`` (which share a clique: a factor's do), from
    ``cov = (sig, cross)`` (:func:`covariances`); zero between two that share none."""
    pos = np.asarray(pos, dtype=np.int64)
    n = int(net[0][pos].sum())
    P = np.empty((n, n))
    _joint(pos, *net, *cov, P)
    return P


@numba.njit(cache=True)
def _traces(fac_ptr, fac_pos, J, J_off, rows, dims, par_ptr, par_idx, par_col, D, sq_off, rect_off, sig, cross,
            out):
    for f in range(rows.shape[0]):
        pos = fac_pos[fac_ptr[f]:fac_ptr[f + 1]]
        n = 0
        for a in range(pos.shape[0]):
            n += dims[pos[a]]
        P = np.empty((n, n))
        _joint(pos, dims, par_ptr, par_idx, par_col, D, sq_off, rect_off, sig, cross, P)
        m = rows[f]
        Jf = J[J_off[f]:J_off[f] + m * n].reshape((m, n))
        acc = 0.0
        for r in range(m):
            for i in range(n):
                x = 0.0
                for j in range(n):
                    x += P[i, j] * Jf[r, j]
                acc += Jf[r, i] * x
        out[f] = acc


def quad_traces(net, cov, fac_ptr, fac_pos, J, J_off, rows):
    """``tr(J Sigma J^T)`` of each factor: its whitened Jacobian ``J`` (``rows[f]`` x the dimensions of its
    variables, row-major at ``J_off[f]`` in ``J``) and the joint covariance ``Sigma`` of its variables (positions
    ``fac_pos[fac_ptr[f]:fac_ptr[f+1]]``, in ``J``'s column order), from ``cov`` (:func:`covariances`)."""
    out = np.empty(len(rows))
    _traces(np.asarray(fac_ptr, dtype=np.int64), np.asarray(fac_pos, dtype=np.int64),
            np.ascontiguousarray(J, dtype=float), np.asarray(J_off, dtype=np.int64), np.asarray(rows, dtype=np.int64),
            *net, *cov, out)
    return out
