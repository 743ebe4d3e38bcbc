"""The graphs' prefix aligner (what the runner's settling of a smoother uses): each prefix of the record it solved
starts from that solution and lands on the cold batch solution of the same prefix, to the solver's tolerance."""

import contextlib

import numpy as np
import pytest

from baselines.factor_graph import FactorGraphAligner, RobustFactorGraphAligner
from baselines.graph_adaptive import AdaptiveFactorGraphAligner
from baselines.graph_solve import GraphSolver
from fusionbench.bench import runner
from fusionbench.methods.aligner import Site
from fusionbench.simulation import attitude, trajectory as tj
from fusionbench.simulation.imu import PRESETS, simulate
from fusionbench.simulation.imudata import IMUData

D = np.pi / 180
LAT = 34 * D
DT = 0.02


def _record(amp_deg, seed, duration=240.0, runs=2):
    """Seed 000's navigation-grade IMU at 50 Hz on a fixed or swaying base at 34 N, heading 30 deg."""
    sway = tj.EulerSway(np.radians([0.0, 0.0, -30.0]), np.radians(amp_deg), (0.5, 0.3, 0.2))
    tr = tj.Trajectory(LAT, 0.3, 50.0, sway, duration=duration)
    return tr, simulate(tr, PRESETS["navigation"], DT, runs=runs, seed=seed), Site(LAT, 0.3, 50.0)


def _prefix(data, seconds):
    n = int(round(seconds / data.dt))
    return IMUData(data.t[:n], data.gyro[:, :n], data.accel[:, :n], data.kind)


def _arcmin(C_a, C_b):
    return np.abs(attitude.misalignment(C_a, C_b)).max(axis=-1) / D * 60.0


@contextlib.contextmanager
def _solves():
    """The keyframe counts of the records ``GraphSolver._solve`` is asked to solve inside the block (a list)."""
    solved = []
    original = GraphSolver._solve

    def spy(self, problem, *args, **kwargs):
        solved.append(problem["counts"].size)
        return original(self, problem, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(GraphSolver, "_solve", spy)
        yield solved


class _NoCoarse:
    """A coarse stage that fails the test if the prefix aligner falls back to it."""

    min_duration_s = 0.0

    def align(self, *args, **kwargs):
        raise AssertionError("a prefix of the solved record went through the coarse stage")


@pytest.mark.parametrize("cls, amp", [(FactorGraphAligner, (0.0, 0.0, 0.0)), (RobustFactorGraphAligner, (5, 7, 9)),
                                      (AdaptiveFactorGraphAligner, (0.0, 0.0, 0.0))])
def test_a_prefix_starts_from_the_record_and_lands_on_the_cold_solution(cls, amp):
    _, data, site = _record(amp, seed=4)
    cold = cls(imu="navigation").estimate_only()
    warm = cls(imu="navigation").prefix_aligner(data, site)
    assert warm.marginals is False and cold.marginals is False
    warm.coarse = _NoCoarse()
    # 60.5 s: a prefix whose last keyframe interval is not one of the record's (preintegrated again)
    for seconds in ((200.0, 60.5) if cls is AdaptiveFactorGraphAligner else (215.0, 125.0, 60.5)):
        part = _prefix(data, seconds)
        a, b = cold.align(part, site), warm.align(part, site)
        assert np.array_equal(a.t, b.t)
        # the same optimum of the same graph, from another start: LM stops within 1e-10 of the cost
        assert _arcmin(a.C_bn[:, -1], b.C_bn[:, -1]).max() < 0.01
        assert _arcmin(a.C_bn, b.C_bn).max() < 0.01  # every keyframe of the prefix, not only its end


def test_every_graph_offers_the_runner_a_keeper_and_a_prefix_aligner():
    for cls in (FactorGraphAligner, RobustFactorGraphAligner, AdaptiveFactorGraphAligner):
        assert callable(cls(imu="navigation").keeping_solutions) and callable(cls(imu="navigation").prefix_aligner)


def test_any_other_record_is_aligned_cold():
    _, data, site = _record((0.0, 0.0, 0.0), seed=4)
    _, other, _ = _record((0.0, 0.0, 0.0), seed=5)
    warm = FactorGraphAligner(imu="navigation").prefix_aligner(data, site)
    assert warm._warm_runs(_prefix(other, 120.0)) is None  # the same length, other samples
    assert warm._warm_runs(IMUData(data.t, data.gyro[::-1], data.accel[::-1], data.kind)) is None  # runs swapped
    res = warm.align(_prefix(other, 120.0), site)
    ref = FactorGraphAligner(imu="navigation").estimate_only().align(_prefix(other, 120.0), site)
    assert _arcmin(res.C_bn, ref.C_bn).max() < 1e-6  # the cold path itself


def test_the_runner_reads_the_same_settling_with_and_without_the_prefix_aligner():
    tr, data, site = _record((5, 7, 9), seed=6, duration=200.0)
    scn = type("Scn", (), {"settling_band_arcmin": 6.0, "site": site})()
    limit = np.zeros(1)

    class Cold:  # the aligner as the runner saw it before: estimate_only, no prefix_aligner
        def __init__(self):
            self.inner = FactorGraphAligner(imu="navigation")
            self.min_duration_s = self.inner.min_duration_s

        def align(self, *args, **kwargs):
            return self.inner.estimate_only().align(*args, **kwargs)

    full = FactorGraphAligner(imu="navigation").estimate_only().align(data, site)
    phi_end = attitude.misalignment(full.C_bn[:, -1], tr.truth([full.t[-1]]).C_bn[0])[:, 2]
    solved = []  # the records the runner had a prefix aligner solve: one, however many prefixes it reads
    original = FactorGraphAligner.prefix_aligner

    def spy(self, imu, *args):
        solved.append(imu.runs)
        return original(self, imu, *args)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(runner, "scenario_limits", lambda scn, traj, t, C: np.zeros((len(t), 3)))
        mp.setattr(FactorGraphAligner, "prefix_aligner", spy)
        warm = runner._prefix_settling(FactorGraphAligner(imu="navigation"), data, None, None, tr, scn, phi_end,
                                       limit[0])
        cold = runner._prefix_settling(Cold(), data, None, None, tr, scn, phi_end, limit[0])
    assert solved == [2]
    assert np.array_equal(warm[0], cold[0]) and np.array_equal(warm[1], cold[1])
    # a band of 6 arcmin about zero (the limit set to zero): settled after several prefix steps, both runs
    assert np.all(warm[0] >= 50.0) and np.all(warm[1])


def test_a_keeper_starts_the_prefixes_from_its_own_align_of_the_record_without_solving_it_again():
    _, data, site = _record((5, 7, 9), seed=6, duration=200.0)
    _, other, _ = _record((5, 7, 9), seed=7, duration=200.0)
    keeper = RobustFactorGraphAligner(imu="navigation").keeping_solutions()
    assert keeper.align(data, site).sigma_phi is not None  # the runner's align: the marginals too
    first = IMUData(data.t, data.gyro[:1], data.accel[:1], data.kind)  # the runs whose settling the runner reads
    with _solves() as solved:
        kept = keeper.estimate_only().prefix_aligner(first, site)  # as the runner asks for it
        assert solved == []
        fresh = RobustFactorGraphAligner(imu="navigation").prefix_aligner(first, site)
        assert solved == [201]  # the whole record (200 keyframe intervals), solved by the fresh one only
        assert kept.marginals is False
        for seconds in (150.0, 75.5):  # the same start (the record solved in a batch of 2 runs, and of 1), the same
            # solution: bit for bit here; held, as the cold solutions above, to LM's tolerance on another CPU
            a, b = kept.align(_prefix(first, seconds), site), fresh.align(_prefix(first, seconds), site)
            assert np.array_equal(a.t, b.t) and _arcmin(a.C_bn, b.C_bn).max() < 0.01
        del solved[:]
        keeper.prefix_aligner(other, site)  # another record: solved
        assert solved and solved[0] == 201


def test_a_prefixs_gyro_rates_are_the_records_own():
    # what lets a prefix reuse the record's rates (kept with its solution): each keyframe interval's rates depend on
    # its own samples only; the same operations, so equal to rounding whatever the CPU
    from baselines.graph_support import keyframe_counts, tangent_rates

    _, data, _ = _record((5, 7, 9), seed=3, duration=120.0, runs=1)
    phi = data.increments()[1][0]
    counts = keyframe_counts(phi.shape[0], 50)
    full = tangent_rates(phi, counts, DT)
    n = counts[60]
    part = tangent_rates(phi[:n], counts[:61], DT)
    assert part == pytest.approx(full[:n], rel=1e-12, abs=1e-18)
    assert np.abs(full - phi / DT).max() > 1e-9  # not the samples' own rates: the sway's turn within an interval


def test_a_keeper_of_the_first_runs_keeps_theirs_only_and_solves_a_longer_batch_again():
    # the runner reads the settling on the seed's first runs only: a keeper of a 25-run batch of 600 s at 100 Hz
    # held 8 MB a run it would never read (static-q-jump: 595 MB with gtsam against 383 with kf)
    _, data, site = _record((5, 7, 9), seed=6, duration=200.0)
    with pytest.raises(ValueError, match=r"^keeping_solutions: runs: expected a number of runs >= 0 or None, "
                                         r"found -1$"):
        FactorGraphAligner(imu="navigation").keeping_solutions(-1)
    keeper = FactorGraphAligner(imu="navigation").keeping_solutions(1)
    keeper.align(data, site)
    assert len(keeper._solved[1]) == 1
    with _solves() as solved:
        keeper.estimate_only().prefix_aligner(IMUData(data.t, data.gyro[:1], data.accel[:1], data.kind), site)
        assert solved == []
        keeper.estimate_only().prefix_aligner(data, site)  # both runs: the second was not kept, the record is solved
        assert solved == [201, 201]
