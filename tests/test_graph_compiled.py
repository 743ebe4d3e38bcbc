"""The factor graph's compiled rotation loop (baselines.graph_compiled) against rotations composed by scipy and
against the NumPy loops it replaced (tests/oracles/graph_rotations.py), on a three-axis sway with an uneven last
interval and on a prefix whose keyframes end before its samples."""

import importlib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from baselines import graph_compiled, graph_rows, graph_support
from baselines.graph_support import keyframe_counts
from tests.oracles import graph_rotations as oracle

DT = 0.01


def _sway(n, amp=0.1, seed=0):
    """Rotation vectors (n, 3), rad, of a three-axis sway of ``amp`` rad/s with white gyro noise."""
    t = np.arange(n) * DT
    w = amp * np.stack([np.cos(0.5 * t), 1.2 * np.sin(0.3 * t + 1), 0.8 * np.cos(0.2 * t)], axis=1)
    return (w + 1e-4 * np.random.default_rng(seed).standard_normal((n, 3))) * DT


def test_the_products_are_scipys_composed_rotations_interval_by_interval():
    phi = _sway(1230)
    counts = keyframe_counts(phi.shape[0], 100)  # the last interval 130 samples
    assert np.diff(counts)[-1] == 130
    after = graph_compiled.interval_products(phi, counts)
    for j in (0, 5, counts.size - 2):
        C = np.eye(3)
        for k in range(counts[j], counts[j + 1]):
            C = C @ Rotation.from_rotvec(phi[k]).as_matrix()
            assert after[k] == pytest.approx(C, abs=1e-14)
    start = graph_compiled.interval_starts(after, counts)
    assert np.array_equal(start[counts[:-1]], np.broadcast_to(np.eye(3), (counts.size - 1, 3, 3)))
    assert np.array_equal(start[counts[3] + 7], after[counts[3] + 6])  # a shift by one sample would fail


def test_samples_past_a_prefixs_last_keyframe_are_left_as_they_are():
    phi = _sway(1000)
    counts = keyframe_counts(1000, 100)[:6]  # keyframes up to sample 500
    after = graph_compiled.interval_products(phi, counts)
    assert np.array_equal(after[500:], np.broadcast_to(np.eye(3), (500, 3, 3)))
    rates = graph_compiled.interval_rates(phi, counts, DT)
    assert np.array_equal(rates[500:], phi[500:] / DT)


def _library(phi, counts, u_kf, dv, tile):
    return (graph_support.tangent_rates(phi, counts, DT), *graph_support._interval_rotations(phi, counts, u_kf),
            *graph_rows.tile_increments(phi, dv, counts, tile))


@pytest.mark.parametrize("amp", [1e-4, 0.1, 1.0])
def test_the_library_functions_equal_what_they_give_with_the_loops_the_kernels_replaced(amp, monkeypatch):
    # the same formulas in another order (a compiled product, the quaternion's logarithm): rounding apart
    phi = _sway(3050, amp)
    counts = keyframe_counts(phi.shape[0], 100)
    u_kf = np.random.default_rng(1).standard_normal((counts.size - 1, 3))
    dv = np.random.default_rng(2).standard_normal(phi.shape)
    t_end = (np.arange(phi.shape[0]) + 1) * DT
    tile = graph_rows.tiles(t_end, np.concatenate([[0.0], t_end[counts[1:] - 1]]))
    got = _library(phi, counts, u_kf, dv, tile)
    for mod, attr, fn in oracle.PATCH:
        monkeypatch.setattr(importlib.import_module(mod), attr, fn)
    ref = _library(phi, counts, u_kf, dv, tile)
    scale = np.abs(phi).max() / DT
    assert got[0] == pytest.approx(ref[0], abs=1e-12 * scale)  # the rates
    for g, r in zip(got[1:], ref[1:]):
        assert g == pytest.approx(r, abs=1e-13)
    if amp >= 0.1:  # not the samples' own rates (second order in the turn: nothing to see at 1e-4 rad/s)
        assert np.abs(got[0] - phi / DT).max() > 1e-6 * scale


def test_a_sample_in_the_next_keyframes_tile_is_carried_into_that_keyframes_body_frame():
    phi = _sway(400, 0.3)
    counts = keyframe_counts(400, 100)
    t_end = (np.arange(400) + 1) * DT
    tile = graph_rows.tiles(t_end, np.concatenate([[0.0], t_end[counts[1:] - 1]]))
    dv = np.random.default_rng(3).standard_normal((400, 3))
    u, R_start = graph_rows.tile_increments(phi, dv, counts, tile)
    i = 170  # in interval 1 (samples 100-199), nearer keyframe 2 (the end of sample 199)
    assert tile[i] == 2
    back = np.eye(3)  # from the start of sample i to keyframe 2: the samples i..199 composed, inverted
    for k in range(i, 200):
        back = back @ Rotation.from_rotvec(phi[k]).as_matrix()
    assert R_start[i] == pytest.approx(back.T, abs=1e-14)
    assert u[i] == pytest.approx(back.T @ dv[i], abs=1e-14)
    assert graph_support._interval_rotations(phi, counts, None)[0] is None


def test_the_logarithm_holds_on_every_branch_of_the_quaternion():
    # Shepperd's four cases: the trace largest, then each diagonal element; angles up to just below pi
    out = np.empty(3)
    rng = np.random.default_rng(4)
    for angle in (1e-9, 1e-3, 1.0, 2.5, np.pi - 1e-6):
        for axis in (np.eye(3)[0], np.eye(3)[1], np.eye(3)[2], rng.standard_normal(3)):
            rv = angle * axis / np.linalg.norm(axis)
            graph_compiled._log(Rotation.from_rotvec(rv).as_matrix(), out)
            assert out == pytest.approx(rv, rel=1e-9, abs=1e-15)
