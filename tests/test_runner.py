"""Scenarios as data, the Monte Carlo runner's determinism, the report and the regression check."""

import json

import numpy as np
import pytest

from fusionbench.bench import scenarios
from fusionbench.bench.check import compare
from fusionbench.bench.experiment import run_scenario, write_scenario_report

TOML = """
name = "tiny"
description = "tiny static test scenario"
duration_s = 30.0
rate_hz = 50.0
runs = 3
methods = ["coarse"]
[site]
lat_deg = -45.0
[attitude]
heading_deg = 200.0
[imu]
preset = "tactical"
"""


def test_builtin_scenarios_load():
    names = scenarios.builtin_names()
    assert {"static-34n", "sway-34n"} <= set(names)
    s = scenarios.get("sway-34n")
    assert s.sway_frequency == (0.2, 0.1, 0.05)
    assert np.degrees(s.site.lat) == pytest.approx(34.0)


def test_a_jump_window_beyond_the_quick_record_is_one_line_before_the_run(tmp_path):
    p = tmp_path / "j.toml"
    p.write_text(TOML.replace("duration_s = 30.0", "duration_s = 60.0") + "[metrics]\njump_window_s = [20, 40]\n"
                 "[quick]\nduration_s = 30.0\n")
    scn = scenarios.load(p)  # valid for the full record
    with pytest.raises(ValueError) as exc:
        run_scenario(scn, quick=True, progress=False)
    assert "metrics.jump_window_s" in str(exc.value) and "30 s" in str(exc.value) and str(p) in str(exc.value)
    assert "\n" not in str(exc.value)


def test_scenario_kind_is_given_or_inferred(tmp_path):
    # what the figures draw hangs on it: a stationary limit means nothing in free-inertial navigation
    kinds = {n: scenarios.get(n).kind for n in scenarios.builtin_names()}
    assert kinds["static-34n"] == kinds["sway-34n"] == "alignment"
    assert kinds["paper001-moving-base"] == "moving-alignment"
    assert kinds["paper004-accel-0.02"] == "navigation" and kinds["paper002-rolling"] == "calibration"
    assert kinds["conformance"] == "conformance"
    p = tmp_path / "s.toml"
    p.write_text(TOML)
    assert scenarios.load(p).kind == "alignment"  # no motion, no RMSE window
    p.write_text(TOML + '[motion]\nsegments = [{accel_mps2 = [1.0, 0, 0], duration_s = 10.0}]\n')
    assert scenarios.load(p).kind == "moving-alignment"
    p.write_text('kind = "sailing"\n' + TOML)
    with pytest.raises(scenarios.ScenarioError, match="field 'kind': expected one of"):
        scenarios.load(p)


@pytest.mark.parametrize("edit,field", [
    ('lat_deg = -45.0', "lat_deg"),
    ('preset = "tactical"', "imu.preset"),
    ('duration_s = 30.0', "duration_s"),
    ('heading_deg = 200.0', "attitude.color"),
])
def test_bad_fields_are_named(tmp_path, edit, field):
    bad = {"lat_deg": 'lat_deg = 95.0', "imu.preset": 'preset = "gold"', "duration_s": 'duration_s = "long"',
           "attitude.color": 'heading_deg = 200.0\ncolor = "red"'}[field]
    p = tmp_path / "bad.toml"
    p.write_text(TOML.replace(edit, bad))
    with pytest.raises(scenarios.ScenarioError) as exc:
        scenarios.load(p)
    assert field in str(exc.value) and str(p) in str(exc.value)
    assert "\n" not in str(exc.value)


def test_run_is_identical_whatever_the_batch_size_and_workers(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(TOML)
    scn = scenarios.load(p)
    a = run_scenario(scn, runs=3, seed=7, batch_size=3, progress=False)
    b = run_scenario(scn, runs=3, seed=7, batch_size=1, progress=False)
    c = run_scenario(scn, runs=3, seed=7, batch_size=1, n_jobs=2, progress=False)
    for other in (b, c):
        assert np.array_equal(a.outcomes["coarse"].phi, other.outcomes["coarse"].phi)
    d = run_scenario(scn, runs=3, seed=8, progress=False)
    assert not np.array_equal(a.outcomes["coarse"].phi, d.outcomes["coarse"].phi)


def test_metrics_follow_the_contract_and_the_report_is_written(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(TOML)
    out = run_scenario(scenarios.load(p), runs=2, seed=1, progress=False)
    folder = tmp_path / "out"
    write_scenario_report(out, folder)
    m = json.loads((folder / "metrics.json").read_text())
    assert set(m) >= {"scenario", "runs", "seed", "duration_s", "quick", "limits_arcmin", "methods"}
    r = m["methods"]["coarse"]
    for ax in "ENU":
        assert set(r["final_error_arcmin"][ax]) == {"mean", "std", "rms", "max_abs"}
    assert set(r["settling_time_s"]) <= {"U", "band_arcmin", "U_settled"} and "wall_s" in r
    # an alignment scenario: the attainable bound and each method's efficiency against it
    assert set(m["bound_arcmin"]) == {"E", "N", "U"} and r["efficiency_U"] > 0
    assert 0.0 <= r["settled_fraction_U"] <= 1.0
    # coarse alignment of a tactical IMU: level errors at the accelerometer-bias limit within noise
    assert abs(r["final_error_arcmin"]["E"]["mean"] - m["limits_arcmin"]["E"]) < 0.5
    assert (folder / "report.md").read_text().count("errors.png") == 1
    assert (folder / "errors.png").stat().st_size > 10000


def test_check_flags_only_regressions():
    ref = {"methods": {"m": {"final_error_arcmin": {ax: {"mean": 1.0, "rms": 2.0} for ax in "ENU"},
                             "settling_time_s": {"U": {"mean": 100.0}}}}}
    same = json.loads(json.dumps(ref))
    assert compare(same, ref) == []
    better = json.loads(json.dumps(ref))
    better["methods"]["m"]["final_error_arcmin"]["U"]["rms"] = 0.5
    assert compare(better, ref) == []
    worse = json.loads(json.dumps(ref))
    worse["methods"]["m"]["final_error_arcmin"]["U"]["rms"] = 2.5
    worse["methods"]["m"]["settling_time_s"]["U"]["mean"] = 200.0
    rows = compare(worse, ref)
    assert [r[1] for r in rows] == ["final phiU |rms| (arcmin)", "settling U mean (s)"]
    assert compare({"methods": {}}, ref)[0][1] == "method missing from run"
    # a calibration scenario's coefficient groups are guarded too
    cal = json.loads(json.dumps(ref))
    cal["methods"]["m"]["groups"] = {"torquer scale": {"max_abs_error_mean": 2.0, "unit": "ppm"}}
    ok = json.loads(json.dumps(cal))
    ok["methods"]["m"]["groups"]["torquer scale"]["max_abs_error_mean"] = 2.1
    assert compare(ok, cal) == []
    bad = json.loads(json.dumps(cal))
    bad["methods"]["m"]["groups"]["torquer scale"]["max_abs_error_mean"] = 2.5
    assert [r[1] for r in compare(bad, cal)] == ["torquer scale max |mean error| (ppm)"]


def test_imu_overrides_are_converted_from_customary_units(tmp_path):
    from fusionbench.simulation import units
    p = tmp_path / "o.toml"
    p.write_text(TOML.replace('preset = "tactical"', 'preset = "tactical"\ngyro_bias_dph = [0.02, 0, 0]\n'
                              'vrw_ug_rthz = 7.0\nrandom = false'))
    spec = scenarios.load(p).imu_spec
    assert spec.gyro.bias == pytest.approx((0.02 * units.DEG_PER_H, 0, 0))
    assert spec.accel.white == (0.0, 0.0, 0.0)  # random = false keeps only deterministic errors
    assert spec.accel.scale == pytest.approx((300e-6,) * 3)


def test_jump_window_metrics_and_filter_consistency(tmp_path):
    p = tmp_path / "jump.toml"
    p.write_text(TOML.replace('methods = ["coarse"]', 'methods = ["coarse", "kf"]').replace("duration_s = 30.0", "duration_s = 120.0")
                 + "[vref]\nsigma_mps = 0.01\nschedule = [{start_s = 40.0, end_s = 80.0, factor = 100.0}]\n"
                 "[metrics]\njump_window_s = [40.0, 80.0]\nsettling_band_arcmin = 30.0\n"
                 "[variants.kf]\nmethod = \"kf\"\nimu = \"tactical\"\nvref_sigma = 0.01\ncoarse_s = 20.0\n")
    m = run_scenario(scenarios.load(p), runs=2, seed=1, progress=False).metrics
    j = m["methods"]["kf"]["jump"]
    assert j["window_s"] == [40.0, 80.0] and set(j["rms_arcmin"]) == {"before", "during", "after"}
    assert j["reconverge_s"]["max_abs"] >= 0.0
    assert set(m["methods"]["kf"]["consistency_rms_ratio"]) == {"E", "N", "U"}
    assert "consistency_rms_ratio" not in m["methods"]["coarse"]  # no predicted sigma, no figure


class Wobble:
    """Test method: the initial guess (the truth, when the scenario's misalignment is zero) turned by
    phi(t) = [A sin(2 pi t / P), c, 0] (arcmin), so every window figure has a closed form."""

    name = "wobble"
    description = "known misalignment history"
    min_duration_s = 1.0

    def __init__(self, amp_arcmin=1.0, offset_arcmin=0.5, period_s=10.0):
        self.a, self.c, self.p = amp_arcmin * 2.908882086657216e-4, offset_arcmin * 2.908882086657216e-4, period_s

    def align(self, imu, site, vref=None, init=None):
        from scipy.spatial.transform import Rotation

        from fusionbench.methods.aligner import AlignmentResult
        t = imu.t
        phi = np.stack([self.a * np.sin(2 * np.pi * t / self.p), np.full(t.size, self.c), np.zeros(t.size)], -1)
        C = Rotation.from_rotvec(-phi).as_matrix() @ np.asarray(init)
        return AlignmentResult(self.name, t, np.broadcast_to(C, (imu.runs,) + C.shape).copy(),
                               figures={"answer": 42.0}, series={"s": np.ones((imu.runs, t.size))})


def test_window_rmse_amplitude_and_comparison_have_their_closed_forms(tmp_path):
    p = tmp_path / "w.toml"
    p.write_text(TOML.replace('methods = ["coarse"]', 'methods = ["big", "small"]')
                 + "[init]\nmisalignment_deg = [0, 0, 0]\n"
                 "[metrics]\nrmse_window_s = [5.0, 25.0]\namplitude_windows_s = {all = [0.0, 30.0]}\n"
                 'compare = ["big", "small"]\n'
                 '[variants.big]\nmethod = "tests.test_runner:Wobble"\namp_arcmin = 2.0\n'
                 '[variants.small]\nmethod = "tests.test_runner:Wobble"\namp_arcmin = 1.0\n')
    out = run_scenario(scenarios.load(p), runs=2, seed=0, progress=False)
    m = out.metrics
    for name, amp in (("big", 2.0), ("small", 1.0)):
        r = m["methods"][name]
        w = r["window_rmse_arcmin"]
        assert w["E"] == pytest.approx(amp / np.sqrt(2), rel=2e-3) and w["N"] == pytest.approx(0.5, rel=1e-6)
        assert w["level"] == pytest.approx(np.hypot(amp / np.sqrt(2), 0.5), rel=2e-3)
        assert r["amplitude_arcmin"]["all"]["E"] == pytest.approx(amp, rel=1e-4)
        assert r["amplitude_arcmin"]["all"]["N"] == pytest.approx(0.0, abs=1e-9)
        assert r["answer"] == 42.0
    rb, rc = np.hypot(2 / np.sqrt(2), 0.5), np.hypot(1 / np.sqrt(2), 0.5)
    assert m["rmse_big_arcmin"] == pytest.approx(rb, rel=2e-3) and m["rmse_small_arcmin"] == pytest.approx(rc, rel=2e-3)
    assert m["reduction_percent"] == pytest.approx(100 * (rb - rc) / rb, rel=5e-3)
    assert m["answer"] == 42.0  # the candidate's own figures are carried to the top
    write_scenario_report(out, tmp_path / "rep")
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "level.png" in text and "series.png" in text and f"{m['reduction_percent']:.1f} %" in text
    # the check reads the new figures: a lower reduction or a higher window RMSE regresses
    worse = json.loads(json.dumps(m))
    worse["reduction_percent"] -= 6.0
    worse["methods"]["small"]["window_rmse_arcmin"]["level"] *= 1.2
    assert [r[1] for r in compare(worse, m)] == ["window level RMSE (arcmin)", "reduction (%)"]
    assert compare(m, m) == []


def test_window_fields_are_validated(tmp_path):
    p = tmp_path / "w.toml"
    base = TOML.replace('methods = ["coarse"]', 'methods = ["coarse", "pid"]')
    for text, field in (("rmse_window_s = [20.0, 40.0]", "metrics.rmse_window_s"),
                        ('compare = ["coarse", "kf"]\nrmse_window_s = [1.0, 2.0]', "metrics.compare"),
                        ('compare = ["coarse", "pid"]', "metrics.compare"),
                        ("amplitude_windows_s = {a = [3.0]}", "metrics.amplitude_windows_s")):
        p.write_text(base + "[metrics]\n" + text + "\n")
        with pytest.raises(scenarios.ScenarioError, match=field.replace(".", r"\.")):
            scenarios.load(p)


class WholeRecordCoarse:
    """A smoother stand-in: the TRIAD estimate of the whole record, reported at every time of the history."""

    name = "whole-record-coarse"
    description = "coarse alignment of the whole record at every time (not causal)"
    min_duration_s = 1.0

    def align(self, imu, site, vref=None, init=None):
        from fusionbench.methods.aligner import AlignmentResult
        from fusionbench.methods.coarse import CoarseAligner

        res = CoarseAligner(history_points=60).align(imu, site)
        return AlignmentResult(self.name, res.t, np.repeat(res.C_bn[:, -1:], res.t.size, axis=1), causal=False)


def test_settling_is_measured_against_the_limit_and_on_prefixes_for_a_smoother(tmp_path):
    # the whole-record stand-in reports, on each prefix of the record, what the causal coarse alignment
    # reports at the prefix's end; its own history (constant at its final value) would claim it settled at
    # once. Measured on prefixes every 25 s, its settling is the causal method's settling read at those times.
    from fusionbench.methods.coarse import CoarseAligner
    from fusionbench.scoring import metrics
    from fusionbench.simulation import units
    from fusionbench.simulation.imu import simulate
    from fusionbench.simulation.imudata import IMUData

    p = tmp_path / "settle.toml"
    p.write_text('name = "settle"\nduration_s = 200.0\nrate_hz = 20.0\nruns = 4\nmethods = ["coarse"]\n'
                 '[site]\nlat_deg = 34.0\n[imu]\npreset = "seed000"\n[metrics]\nsettling_band_arcmin = 15.0\n')
    scn = scenarios.load(p)
    smoother = "tests.test_runner:WholeRecordCoarse"
    out = run_scenario(scn, methods=["coarse", smoother], runs=4, seed=3, progress=False)
    # the definition, computed directly: the causal method's final error on each prefix, against the limit
    traj = scn.trajectory()
    data = simulate(traj, scn.imu_spec, scn.dt, runs=4, seed=3)
    ends = np.arange(25.0, 200.0 + 1e-9, 25.0)
    C_true = traj.truth(ends).C_bn
    prefixes = [IMUData(data.t[:n], data.gyro[:, :n], data.accel[:, :n]) for n in np.rint(ends / scn.dt).astype(int)]
    err = np.stack([metrics.misalignment_history(CoarseAligner().align(part, scn.site).C_bn[:, -1:], C_true[k:k + 1])
                    [:, 0, 2] for k, part in enumerate(prefixes)], axis=-1)
    limit = metrics.theoretical_limits(scn.imu_spec.gyro.bias, scn.imu_spec.accel.bias, C_true, scn.site.lat)[:, 2]
    expect = metrics.settling_time(ends, err, 15.0 * units.ARCMIN, limit)
    assert expect.max() >= 50.0  # it does take time to settle in a 15-arcmin band
    assert np.array_equal(out.outcomes[smoother].per_run["settle"], expect)
    assert np.all(out.outcomes[smoother].per_run["settled"])
    # the causal method measured on its own (denser) history settles no earlier than on the 25-s grid
    assert np.all(out.outcomes["coarse"].per_run["settle"] >= expect - 25.0)


def test_smoother_settling_on_the_first_runs_whatever_the_batching(tmp_path):
    """A smoother's prefix settling is measured on the seed's first PREFIX_RUNS runs only (each costs about five
    whole-record alignments): the same runs, the same figures, for any batch size; the others are NaN and the
    statistics are over the measured ones."""
    from fusionbench.bench.runner import PREFIX_RUNS

    p = tmp_path / "settle.toml"
    p.write_text('name = "settle"\nduration_s = 100.0\nrate_hz = 20.0\nruns = 7\nmethods = ["coarse"]\n'
                 '[site]\nlat_deg = 34.0\n[imu]\npreset = "seed000"\n[metrics]\nsettling_band_arcmin = 15.0\n')
    scn = scenarios.load(p)
    smoother = "tests.test_runner:WholeRecordCoarse"
    one = run_scenario(scn, methods=[smoother], runs=7, seed=2, progress=False)
    split = run_scenario(scn, methods=[smoother], runs=7, seed=2, progress=False, batch_size=3)
    s1, s2 = one.outcomes[smoother].per_run["settle"], split.outcomes[smoother].per_run["settle"]
    assert PREFIX_RUNS == 5 and np.all(np.isfinite(s1[:5])) and np.all(np.isnan(s1[5:]))
    assert np.array_equal(s1, s2, equal_nan=True)
    # metrics.json labels it by its name, not its import path
    assert one.metrics["methods"]["whole-record-coarse"]["settling_time_s"]["U"]["mean"] == pytest.approx(np.mean(s1[:5]))
    assert one.outcomes[smoother].per_run["settled"].shape == (7,)  # inside the band at the end: known for every run


class _Counter:
    """A bar as the command line shares it: counts the runs reported finished, in steps."""

    def __init__(self):
        self.steps = []

    def update(self, n=1):
        self.steps.append(n)


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_a_shared_bar_advances_by_finished_runs(n_jobs):
    """``run all`` shares one bar: each scenario advances it by exactly its runs, as each method finishes a batch
    (also under workers: a worker's unit is one method on one batch), and leaves it open for the next scenario."""
    from fusionbench.files import progress

    scn = scenarios.get("static-34n")
    bar = _Counter()
    run_scenario(scn, methods=["coarse"], runs=5, quick=True, n_jobs=n_jobs, batch_size=2, progress=bar)
    assert bar.steps == [2, 2, 1]
    bar = _Counter()  # two methods: half a batch's runs per finished method, whole runs shown
    run_scenario(scn, methods=["coarse", "coarse-i0"], runs=5, quick=True, n_jobs=n_jobs, batch_size=2, progress=bar)
    assert bar.steps == [1, 1, 1, 1, 1]
    assert progress.expected_runs(scn, 5, True) == 5
    conf = scenarios.get("conformance")
    assert progress.expected_runs(conf, None, True) == 3 * len(conf.conditions)


USER_METHODS = '''
from fusionbench.methods.coarse import CoarseAligner


class Mine(CoarseAligner):
    name = "my-coarse"


class Named(CoarseAligner):
    name = "coarse"
'''


def test_a_user_method_is_labelled_by_its_name(tmp_path, monkeypatch):
    # a module:Class method appears in metrics.json and the report by its name; the path stays where it was given
    # (RunOutput.outcomes) and beside the name in the report's list of methods
    (tmp_path / "fb_label_user.py").write_text(USER_METHODS)
    monkeypatch.syspath_prepend(str(tmp_path))
    p = tmp_path / "tiny.toml"
    p.write_text(TOML)
    scn = scenarios.load(p)
    out = run_scenario(scn, methods=["coarse", "fb_label_user:Mine"], runs=2, seed=1, progress=False)
    assert list(out.metrics["methods"]) == ["coarse", "my-coarse"]
    assert out.outcomes["fb_label_user:Mine"].name == "my-coarse"
    mine, coarse = out.metrics["methods"]["my-coarse"], out.metrics["methods"]["coarse"]
    assert mine["final_error_arcmin"] == coarse["final_error_arcmin"]  # the same algorithm on the same data
    write_scenario_report(out, tmp_path / "rep")
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "\n| my-coarse | " in text and "- `my-coarse` (`fb_label_user:Mine`):" in text
    assert "| fb_label_user:Mine |" not in text
    # a name another method of the run has: the path, so that neither hides the other
    out = run_scenario(scn, methods=["coarse", "fb_label_user:Named"], runs=2, seed=1, progress=False)
    assert list(out.metrics["methods"]) == ["coarse", "fb_label_user:Named"]
    # alone, a user's class named like a registered method is checked against that method's reference
    ref = run_scenario(scn, methods=["coarse"], runs=2, seed=1, progress=False).metrics
    alone = run_scenario(scn, methods=["fb_label_user:Named"], runs=2, seed=1, progress=False).metrics
    assert list(alone["methods"]) == ["coarse"] and compare(alone, ref) == []
    ref["methods"]["kf"] = ref["methods"]["coarse"]
    assert [r[:2] for r in compare(alone, ref)] == [("kf", "method missing from run")]
