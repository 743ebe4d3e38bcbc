"""The NumPy reference of the posterior's compiled recursion (:mod:`baselines.posterior_compiled`).

The code the kernels replaced (2026-12-05): the backward recursion over the conditionals with the covariance blocks
in a dictionary keyed by pairs of variables, and each clique's joint covariance assembled from it, one NumPy
product per conditional and per factor. Here it reads and writes the kernels' flat arrays so that it can stand in
for them. The tests hold the library's posterior to what it gives with these in place of the kernels
(``tests/test_graph_posterior.py``), and ``benchmarks/perf_methods.py --numpy-oracles`` times the graphs with them.
``PATCH`` names the library's functions they stand in for; ``USED_BY`` the modules of the methods that run them.
"""

from __future__ import annotations

import numpy as np


def _blocks(net, R_inv, sigmas, S):
    """Per conditional: its parents, ``A = R^-1 S`` and ``Ri`` with ``cov(x_f | x_P) = Ri Ri^T``."""
    dims, par_ptr, par_idx, _, D, sq_off, rect_off = net
    v_off = np.r_[0, np.cumsum(dims)]
    for i in range(dims.size):
        d = dims[i]
        R = R_inv[sq_off[i]:sq_off[i + 1]].reshape(d, d)
        yield (list(par_idx[par_ptr[i]:par_ptr[i + 1]]), R @ S[rect_off[i]:rect_off[i + 1]].reshape(d, D[i]),
               R * sigmas[v_off[i]:v_off[i + 1]][None, :])


def _assemble(cov, dims, keys):
    """The joint covariance of ``keys`` from the blocks ``cov`` holds, each pair once as ``(a, b)`` or ``(b, a)``."""
    off = np.r_[0, np.cumsum([dims[k] for k in keys])]
    P = np.zeros((off[-1], off[-1]))
    for a, ka in enumerate(keys):
        P[off[a]:off[a + 1], off[a]:off[a + 1]] = cov[ka, ka]
        for b in range(a + 1, len(keys)):
            kb = keys[b]
            blk = cov.get((ka, kb))
            if blk is None:
                blk = cov.get((kb, ka))
                if blk is None:
                    continue
                blk = blk.T
            P[off[a]:off[a + 1], off[b]:off[b + 1]] = blk
            P[off[b]:off[b + 1], off[a]:off[a + 1]] = blk.T
    return P


def _dictionary(net, flat):
    """The flat blocks ``(sig, cross)`` as the dictionary of pairs."""
    dims, par_ptr, par_idx, par_col, D, sq_off, rect_off = net
    sig, cross = flat
    cov = {}
    for i in range(dims.size):
        d = dims[i]
        cov[i, i] = sig[sq_off[i]:sq_off[i + 1]].reshape(d, d)
        C = cross[rect_off[i]:rect_off[i + 1]].reshape(d, D[i])
        for j in range(par_ptr[i], par_ptr[i + 1]):
            cov[i, par_idx[j]] = C[:, par_col[j]:par_col[j] + dims[par_idx[j]]]
    return cov


def covariances_numpy(net, R_inv, sigmas, S):
    """:func:`baselines.posterior_compiled.covariances`, a dictionary of blocks and NumPy products."""
    dims, _, _, _, _, sq_off, rect_off = net
    R_inv, sigmas, S = (np.asarray(x) for x in (R_inv, sigmas, S))  # float64, or wider for a check of rounding
    blocks = list(_blocks(net, R_inv, sigmas, S))
    cov = {}
    for i in range(dims.size - 1, -1, -1):
        parents, A, Ri = blocks[i]
        if parents:
            cross = -A @ _assemble(cov, dims, parents)
            cov[i, i] = Ri @ Ri.T - cross @ A.T
            off = np.r_[0, np.cumsum([dims[p] for p in parents])]
            for j, p in enumerate(parents):
                cov[i, p] = cross[:, off[j]:off[j + 1]]
        else:
            cov[i, i] = Ri @ Ri.T
    sig, cross = np.empty(sq_off[-1], R_inv.dtype), np.empty(rect_off[-1], R_inv.dtype)
    for i, (parents, _, _) in enumerate(blocks):
        sig[sq_off[i]:sq_off[i + 1]] = cov[i, i].ravel()
        if parents:
            cross[rect_off[i]:rect_off[i + 1]] = np.hstack([cov[i, p] for p in parents]).ravel()
    return sig, cross


def joint_covariance_numpy(net, cov, pos):
    """:func:`baselines.posterior_compiled.joint_covariance` from the dictionary of blocks."""
    return _assemble(_dictionary(net, cov), net[0], [int(p) for p in pos])


def quad_traces_numpy(net, cov, fac_ptr, fac_pos, J, J_off, rows):
    """:func:`baselines.posterior_compiled.quad_traces`, one NumPy product per factor."""
    blocks, dims = _dictionary(net, cov), net[0]
    fac_pos, J = np.asarray(fac_pos, dtype=int), np.asarray(J, float)
    out = np.empty(len(rows))
    for f in range(len(rows)):
        keys = [int(p) for p in fac_pos[fac_ptr[f]:fac_ptr[f + 1]]]
        P = _assemble(blocks, dims, keys)
        A = J[J_off[f]:J_off[f] + rows[f] * P.shape[0]].reshape(rows[f], P.shape[0])
        out[f] = np.einsum("ij,jk,ik->", A, P, A)
    return out


PATCH = [("baselines.graph_posterior", "covariances", covariances_numpy),
         ("baselines.graph_posterior", "joint_covariance", joint_covariance_numpy),
         ("baselines.graph_posterior", "quad_traces", quad_traces_numpy)]
USED_BY = ("baselines.factor_graph", "baselines.graph_adaptive")
