"""The graphs' posterior (baselines.graph_posterior on the compiled recursion of baselines.posterior_compiled):
against theory (the redundancy numbers of a whole graph sum to its rows less its unknowns; a factor's keys that
share no clique have no block) and against the dictionary recursion it replaced (tests/oracles/graph_posterior.py)
on the graph of a 300-s navigation-grade sway. The dense-inverse check of the covariances is in
tests/test_factor_graph_model.py."""

import numpy as np
import pytest

import gtsam
from gtsam.symbol_shorthand import B, V, X

from baselines import graph_adaptive, graph_posterior
from baselines.graph_posterior import Posterior, residual_statistics
from fusionbench.methods.aligner import Site, load_method
from fusionbench.simulation.imu import IMUSpec, simulate
from fusionbench.simulation import trajectory as tj
from tests.oracles import graph_posterior as oracle
from tests.test_factor_graph_model import _small_graph

LAT, LON = np.radians(45.0), np.radians(10.0)


def _factor_keys(graph):
    return [list(graph.at(i).keys()) for i in range(graph.size())]


def test_the_redundancy_numbers_of_a_whole_graph_sum_to_its_rows_less_its_unknowns():
    # tr(A (A^T A)^-1 A^T) = n over every factor: sum of m_i - tr(A_i Sigma A_i^T) = m - n
    graph, values, K = _small_graph(smart=False)
    post = Posterior(graph, values, K, [B(0), B(1)])
    keys = _factor_keys(graph)
    e2, red = residual_statistics(post, keys, list(range(graph.size())))
    rows = sum(graph.at(i).dim() for i in range(graph.size()))
    unknowns = 6 * K + 3 * K + 12
    assert red.sum() == pytest.approx(rows - unknowns, abs=1e-6)
    assert np.all(red > -1e-9) and np.all(red < np.array([graph.at(i).dim() for i in range(graph.size())]) + 1e-9)
    # b^T b: twice each factor's error at the solution
    assert e2 == pytest.approx([2 * graph.at(i).error(values) for i in range(graph.size())], rel=1e-9, abs=1e-15)
    # a factor left out (negative index) gets zeros, the others the same numbers
    e2_s, red_s = residual_statistics(post, keys, [-1] + list(range(1, graph.size())))
    assert e2_s[0] == red_s[0] == 0.0 and np.array_equal(red_s[1:], red[1:])


def test_keys_that_share_no_clique_have_no_covariance_block():
    graph, values, K = _small_graph(smart=False)
    post = Posterior(graph, values, K, [B(0), B(1)])
    P = post.cov([V(0), V(K - 1)])  # the two ends of the chain are eliminated apart
    assert np.abs(P[:3, :3]).max() > 0 and np.abs(P[3:, 3:]).max() > 0
    assert np.all(P[:3, 3:] == 0.0) and np.all(P[3:, :3] == 0.0)


@pytest.fixture(scope="module")
def sway_graph():
    """The last graph gtsam-adaptive's variance estimation linearises, on a 300-s navigation-grade sway at 45 N."""
    sway = tj.EulerSway(mean=(0.01, -0.02, 0.5), amplitude=(0.02, 0.03, 0.01), frequency=(0.12, 0.1, 0.08))
    tr = tj.Trajectory(LAT, LON, 50.0, sway, duration=300.0)
    data = simulate(tr, IMUSpec(), 0.01, seed=3)
    seen = []
    real = graph_adaptive.Posterior

    def keep(graph, values, K, bias_keys):
        seen.append((graph, values, K, bias_keys))
        return real(graph, values, K, bias_keys)

    graph_adaptive.Posterior = keep
    try:
        load_method("gtsam-adaptive", imu="navigation").align(data, Site(LAT, LON, 50.0))
    finally:
        graph_adaptive.Posterior = real
    return seen[-1]


def _scaled(P, ref):
    d = np.sqrt(np.abs(np.diag(ref)))
    return np.abs(P - ref) / np.outer(d, d)


def test_the_posterior_equals_what_the_dictionary_recursion_gives(sway_graph, monkeypatch):
    # the same recursion summed in another order: rounding apart, on blocks whose conditioning makes that 1e-8 of
    # their scale (measured against an 80-bit run of the oracle: the kernel 4.9e-8, the oracle 1.1e-8)
    graph, values, K, bias_keys = sway_graph
    post = Posterior(graph, values, K, bias_keys)
    imu = [i for i in range(graph.size()) if isinstance(graph.at(i), gtsam.ImuFactor)]
    keys = _factor_keys(graph)
    ask = [[X(k), V(k), X(k + 1), V(k + 1), bias_keys[0]] for k in (0, K // 2, K - 2)] + [[X(k)] for k in range(K)]
    C = np.stack([values.atPose3(X(k)).rotation().matrix() for k in range(K)])
    got = ([post.cov(k) for k in ask], [post.cov(k[:4], bias=False) for k in ask[:3]], post.attitude_sigmas(C),
           residual_statistics(post, [keys[i] for i in imu], imu))
    for name, fn in ((n, getattr(oracle, f"{n}_numpy")) for n in ("covariances", "joint_covariance", "quad_traces")):
        monkeypatch.setattr(graph_posterior, name, fn)
    post = Posterior(graph, values, K, bias_keys)
    ref = ([post.cov(k) for k in ask], [post.cov(k[:4], bias=False) for k in ask[:3]], post.attitude_sigmas(C),
           residual_statistics(post, [keys[i] for i in imu], imu))
    for P, R in zip(got[0] + got[1], ref[0] + ref[1]):
        assert _scaled(P, R).max() < 1e-6
    for s, r in zip(got[2], ref[2]):
        assert s == pytest.approx(r, rel=1e-9)
    assert np.array_equal(got[3][0], ref[3][0])  # b^T b: the same gtsam numbers
    assert got[3][1] == pytest.approx(ref[3][1], abs=1e-4)  # redundancies of 0.1 to 0.5 of the 9 rows
    assert ref[3][1].min() > 0.05 and ref[3][1].max() < 9.0
