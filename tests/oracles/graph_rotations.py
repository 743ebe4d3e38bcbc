"""The NumPy reference of the factor graph's compiled rotation loop (:mod:`baselines.graph_compiled`).

The loops the kernels replaced (2026-12-05): one NumPy step per sample of a keyframe interval with arrays over the
intervals, the rotation vector by scipy. The tests hold the library's functions to what they give with these in place
of the kernels (``tests/test_graph_compiled.py``), and ``benchmarks/perf_methods.py --numpy-oracles`` times the graphs
with them. ``PATCH`` names the library's functions they stand in for, where the library calls them; ``USED_BY`` the
modules of the methods that run them.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation.attitude import dcm_to_rotvec, skew
from fusionbench.simulation.strapdown import rodrigues


def _steps(counts):
    """Per step s of an interval: the intervals that have an s-th sample, and its index."""
    starts, lengths = counts[:-1], np.diff(counts)
    for s in range(int(lengths.max())):
        sel = lengths > s
        yield sel, starts[sel] + s


def interval_products_numpy(phi, counts):
    """:func:`baselines.graph_compiled.interval_products`, a NumPy step per sample of an interval."""
    out = np.empty((phi.shape[0], 3, 3))
    out[:] = np.eye(3)
    if counts.size < 2:
        return out
    Rcur = np.broadcast_to(np.eye(3), (counts.size - 1, 3, 3)).copy()
    for sel, idx in _steps(counts):
        Rcur[sel] = Rcur[sel] @ rodrigues(phi[idx])
        out[idx] = Rcur[sel]
    return out


def interval_rates_numpy(phi, counts, dt):
    """:func:`baselines.graph_compiled.interval_rates`, a NumPy step per sample of an interval."""
    rates = np.asarray(phi, dtype=float) / dt
    if counts.size < 2:
        return rates
    Rcur = np.broadcast_to(np.eye(3), (counts.size - 1, 3, 3)).copy()
    theta = np.zeros((counts.size - 1, 3))
    for sel, idx in _steps(counts):
        Rcur[sel] = Rcur[sel] @ rodrigues(phi[idx])
        new = dcm_to_rotvec(Rcur[sel])
        th = theta[sel]
        a = np.linalg.norm(th, axis=-1)[:, None, None]
        S = skew(th)
        small = a < 1e-8
        a = np.where(small, 1.0, a)
        J_r = np.eye(3) + np.where(small, 0.0, -(1 - np.cos(a)) / a**2 * S + (a - np.sin(a)) / a**3 * (S @ S))
        rates[idx] = np.einsum("kij,kj->ki", J_r, new - th) / dt
        theta[sel] = new
    return rates


PATCH = [("baselines.graph_support", "interval_products", interval_products_numpy),
         ("baselines.graph_support", "interval_rates", interval_rates_numpy),
         ("baselines.graph_rows", "interval_products", interval_products_numpy)]
USED_BY = ("baselines.factor_graph", "baselines.graph_adaptive")
