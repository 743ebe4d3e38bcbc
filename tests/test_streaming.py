"""Long records streamed to the methods that take chunks (fusionbench.bench.streaming): the same numbers as the whole
record, bit for bit, and memory bounded by a batch, not by the number of runs."""

import numpy as np
import pytest

from fusionbench.bench import runner, scenarios, streaming
from fusionbench.simulation import imu
from fusionbench.simulation.trajectory import moored

# seed 004's navigation scenario cut to 25 min: the network switched in at 400 s, an east manoeuvre at 900 s, the
# adaptive scheme reading the (noisy) reference's acceleration, so the chunks carry a reference too
SCENARIO = """
name = "nav-stream"
description = "damped navigation streamed in chunks"
experiment = "navigation"
duration_s = 1500.0
rate_hz = 5.0
runs = 3
methods = ["fixed", "adaptive"]
[quick]
duration_s = 1500.0
runs = 3
[site]
lat_deg = 35.0
[attitude]
heading_deg = 90.0
sway_amplitude_deg = [1.2, 1.2, 0.8]
sway_frequency_hz = [0.14285714285714285, 0.125, 0.09090909090909091]
[motion]
start_s = 900.0
segments = [{accel_mps2 = [0.02, 0.0, 0.0], duration_s = 300.0}]
[imu]
preset = "seed004"
[vref]
sigma_mps = [0.01, 0.01, 0.01]
[init]
misalignment_deg = [0.05, 0.05, 0.083333]
[metrics]
rmse_window_s = [1200.0, 1500.0]
[variants.fixed]
method = "damped-nav"
scheme = "fixed"
damp_from_s = 400.0
[variants.adaptive]
method = "damped-nav"
scheme = "adaptive"
accel_source = "vref"
damp_from_s = 400.0
"""


@pytest.fixture(scope="module")
def scn(tmp_path_factory):
    path = tmp_path_factory.mktemp("scn") / "nav-stream.toml"
    path.write_text(SCENARIO)
    return scenarios.load(path)


def _run(scn, monkeypatch, stream_min_s, chunk_s=streaming.CHUNK_S, batch_size=None):
    monkeypatch.setattr(streaming, "STREAM_MIN_S", stream_min_s)
    monkeypatch.setattr(streaming, "CHUNK_S", chunk_s)
    return runner.run_alignment(scn, batch_size=batch_size)


def _strip(d):
    return {k: _strip(v) for k, v in d.items() if k != "wall_s"} if isinstance(d, dict) else d


def test_streamed_record_gives_the_whole_records_numbers(scn, monkeypatch):
    """Streamed in the simulator's own 600-s chunks, the metrics, the histories and the q series equal the whole
    record's, bit for bit."""
    whole = _run(scn, monkeypatch, float("inf"))
    calls = []
    real = streaming.SimulatedStream.__iter__
    monkeypatch.setattr(streaming.SimulatedStream, "__iter__", lambda self: calls.append(1) or real(self))
    streamed = _run(scn, monkeypatch, 0.0)
    assert calls, "the stream was not used"
    assert _strip(streamed.metrics) == _strip(whole.metrics)
    for name, oc in whole.outcomes.items():
        np.testing.assert_array_equal(streamed.outcomes[name].t, oc.t)
        np.testing.assert_array_equal(streamed.outcomes[name].phi, oc.phi)
        for key, val in oc.series.items():
            np.testing.assert_array_equal(streamed.outcomes[name].series[key], val)
    # the errors are not trivially equal: the adaptive network moved, and the level error is arcminutes
    assert np.min(whole.outcomes["adaptive"].series["q_E"]) < 6.0
    assert 0.1 < whole.metrics["methods"]["fixed"]["window_rmse_arcmin"]["level"] < 30


def test_chunks_that_end_inside_a_step(scn, monkeypatch):
    """Chunks of 77.3 s (386.5 samples) end inside the navigator's 1-s steps, so it carries samples over. The
    simulator's sample times then differ from the 600-s chunks' in the last bits (k0 dt + k dt), so the record is
    equal to rounding, not bit for bit: the histories agree to 1e-12 rad, a millionth of one sample's turn under
    this sway."""
    whole = _run(scn, monkeypatch, float("inf"))
    streamed = _run(scn, monkeypatch, 0.0, 77.3)
    for name, oc in whole.outcomes.items():
        np.testing.assert_allclose(streamed.outcomes[name].t, oc.t, rtol=0, atol=1e-9)
        np.testing.assert_allclose(streamed.outcomes[name].phi, oc.phi, rtol=0, atol=1e-12)
        np.testing.assert_allclose(streamed.outcomes[name].per_run["phi_end"], oc.per_run["phi_end"], rtol=0,
                                   atol=1e-12)


def test_streamed_batches_and_one_batch_agree(scn, monkeypatch):
    """Batches of one run (the memory bound on a streamed record) give the numbers of one batch of three."""
    one = _run(scn, monkeypatch, 0.0, batch_size=3)
    many = _run(scn, monkeypatch, 0.0, batch_size=1)
    assert _strip(one.metrics) == _strip(many.metrics)


def test_a_streamed_batch_keeps_no_view_of_its_histories(scn, monkeypatch):
    """What the runner keeps of a batch is copies: a view of the last sample would keep the batch's whole history
    (20 h at 1 s: 5 MB a run) alive until the end, and memory would grow with the number of runs."""
    out = _run(scn, monkeypatch, 0.0)
    for oc in out.outcomes.values():
        for key, val in oc.per_run.items():
            if isinstance(val, np.ndarray):
                assert val.base is None or val.base.size == val.size, key


def test_stream_batch_size_is_bounded(scn, monkeypatch):
    """A streamed record is run in batches of at most STREAM_BATCH_RUNS runs, whatever the number of runs."""
    seen = []
    real = runner._run_units

    def spy(scn_, names, first_run, runs, *args, **kw):
        seen.append(runs)
        return real(scn_, names, first_run, runs, *args, **kw)

    monkeypatch.setattr(runner, "_run_units", spy)
    monkeypatch.setattr(streaming, "STREAM_MIN_S", 0.0)
    monkeypatch.setattr(streaming, "STREAM_BATCH_RUNS", 2)
    runner.run_alignment(scn, methods=["fixed"], runs=5)
    assert seen == [2, 2, 1]


def test_vref_stream_equals_simulate_vref():
    """The reference drawn chunk by chunk equals the one drawn at once, bit for bit, noise schedule included."""
    traj = moored(np.radians(34.0), duration=100.0)
    spec = imu.VelocityReferenceSpec(sigma=(0.05, 0.02, 0.01),
                                     schedules=(imu.NoiseSchedule(30.0, 60.0, 9.0),))
    t = np.arange(1, 1001) * 0.1
    whole = imu.simulate_vref(traj, spec, t, runs=3, seed=7, first_run=2)
    f = imu.vref_stream(traj, spec, runs=3, seed=7, first_run=2)
    parts = np.concatenate([f(t[a:b]) for a, b in ((0, 1), (1, 334), (334, 1000))], axis=1)
    np.testing.assert_array_equal(parts, whole)
    assert np.std(whole[:, 400:500, 0]) > 2.5 * np.std(whole[:, :250, 0])  # the schedule's factor 9 (x3 in sigma)


def test_simulated_stream_time_grid_matches_the_whole_record(scn):
    """The stream's dt, t0 and last sample are those of the IMUData the whole record would give."""
    traj = scn.trajectory(scn.duration_s)
    s = streaming.SimulatedStream(scn, traj, 0, 2, 0, scn.duration_s)
    data = imu.simulate(traj, scn.imu_spec, scn.dt, runs=2, seed=0)
    assert (s.dt, s.t0, s.t_last, s.samples) == (data.dt, data.t0, data.t_last, data.samples)
    joined = np.concatenate([ch.gyro for ch, _ in s], axis=1)
    np.testing.assert_array_equal(joined, data.gyro)
