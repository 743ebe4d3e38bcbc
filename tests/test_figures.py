"""Report figures: the divergence rule, the events of built-in scenarios and methods, what each scenario kind
draws, the time unit, and a diverged method drawn apart. Synthetic histories: no simulation, seconds."""

import tomllib
from importlib import resources

import numpy as np
import pytest

from fusionbench.bench import scenarios
from fusionbench.bench.runner import MethodOutcome, RunOutput
from fusionbench.reports import figure_events as fev, figures as fg
from fusionbench.reports.report import _table, azimuth_figure, error_figure
from fusionbench.simulation import units


def _toml(name):
    return tomllib.loads((resources.files("fusionbench.bench.scenarios") / f"{name}.toml").read_text())


def _run(scn_name, histories, duration, limits_arcmin=(0.1, -0.1, -3.0)):
    """A RunOutput of the scenario with the given error histories, name to (t (M,) s, phi (R, M, 3) arcmin)."""
    scn = scenarios.get(scn_name)
    outcomes = {n: MethodOutcome(n, "", t, phi * units.ARCMIN, 0.0) for n, (t, phi) in histories.items()}
    metrics = {"scenario": scn.name, "runs": next(iter(histories.values()))[1].shape[0], "duration_s": duration}
    return RunOutput(scn, metrics, outcomes, np.asarray(limits_arcmin) * units.ARCMIN)


def _converging(t, runs, seed, scale=1.0):
    rng = np.random.default_rng(seed)
    return scale * (30 * np.exp(-t / (t[-1] / 8))[None, :, None] + rng.normal(0, 0.3, (runs, t.size, 3)))


def _labels(fig):
    return [a.get_label() for ax in fig.axes for a in ax.lines + ax.patches + ax.collections]


def test_the_divergence_rule_flags_the_diverging_method_only():
    sizes = {"kf": [0.2, 0.3, 1.2], "akf": [0.3, 0.4, 1.4], "gtsam": [0.2, 0.3, 1.1], "eso": [0.3, 0.3, 2.2],
             "slow": [0.6, 0.5, 7.4], "paper": [400.0, 33.0, 4000.0]}
    assert fg.diverged(sizes, 1.0) == ["paper"]
    # half of the methods bad still leaves a reference from the better half
    assert fg.diverged({"a": [1, 1, 2], "b": [1, 1, 3], "c": [90, 1, 2], "d": [1, 1, 500]}, 1.0) == ["c", "d"]
    assert fg.diverged({"a": [1, 1, 1], "b": [np.nan, 1, 1]}, 1.0) == ["b"]  # not finite: diverged
    assert fg.diverged({"alone": [1e4, 1e4, 1e4]}, 1.0) == []  # nothing to compare with
    # the floor: 0.01 arcmin methods do not make a 2-arcmin one diverge
    assert fg.diverged({"a": [0.01] * 3, "b": [0.01] * 3, "c": [2.0] * 3}, 1.0) == []


def test_divergence_from_histories_uses_the_end_of_the_record():
    t = np.linspace(0, 500, 201)
    good = {n: (t, _converging(t, 3, k)) for k, n in enumerate(("kf", "akf", "gtsam"))}
    wild = np.random.default_rng(9).normal(0, 3000, (3, t.size, 3))
    assert fg.diverged_histories({**good, "eso-td-paper": (t, wild)}) == ["eso-td-paper"]
    assert fg.diverged_histories(good) == []  # a large start (30 arcmin) is no divergence


def test_time_axis_switches_to_hours_for_long_records():
    assert fg.time_axis(600.0) == (1.0, "s")
    assert fg.time_axis(2 * 3600.0) == (1.0, "s")
    assert fg.time_axis(72000.0) == (3600.0, "h")


def test_events_of_built_in_scenarios_come_from_their_files():
    for name, label in (("static-r-jump", "reference-velocity noise variance x100"),
                        ("static-q-jump", "IMU white-noise PSD x100")):
        jump = _toml(name)["metrics"]["jump_window_s"]
        ev = fev.scenario_events(scenarios.get(name), 600.0)
        assert [(e.t0_s, e.t1_s, e.label) for e in ev] == [(jump[0], jump[1], label)]  # the window once
    raw = _toml("paper004-accel-0.02")
    scn = scenarios.get("paper004-accel-0.02")
    start, dur = raw["motion"]["start_s"], raw["motion"]["segments"][0]["duration_s"]
    ev = fev.scenario_events(scn, raw["duration_s"])
    assert [(e.t0_s, e.t1_s) for e in ev] == [(start, start + dur)] and ev[0].label.startswith("manoeuvre")
    # the damping switch-in, from the methods (damped-nav's damp_from_s, 3 h), once for the three damped variants
    methods = {n: scn.method(n) for n in raw["methods"]}
    mev = fev.method_events(methods, init_given=True)
    assert [(e.t0_s, e.t1_s, e.methods) for e in mev] == [(3 * 3600.0, None, ("fixed", "adaptive", "adaptive-ins"))]
    # a moving base whose motion covers the whole record has no manoeuvre to mark
    assert fev.scenario_events(scenarios.get("paper001-moving-base"), 500.0) == []
    # the platform's roll phases, scaled with the scheme
    roll = fev.scenario_events(scenarios.get("paper002-rolling"), 5400.0)
    assert [(e.t0_s, e.t1_s) for e in roll] == [(0, 1800), (1800, 2700), (2700, 4500), (4500, 5400)]


def test_a_drive_marks_its_turns_and_accelerations_at_their_times():
    """A user's drive (legs from start_s) is marked leg by leg where it changes speed or heading: the events are
    the legs' own times (a leg shifted by one sample moves them), straight legs at constant speed are not marked.
    A drive has no segments: its report used to stop on an AttributeError."""
    data = {"name": "my-drive", "duration_s": 120.0, "rate_hz": 50.0, "runs": 1, "methods": ["kf"],
            "site": {"lat_deg": 45.0}, "attitude": {"heading_deg": 30.0},
            "motion": {"start_s": 4.0, "legs": [{"duration_s": 20.0, "accel_mps2": 0.5}, {"duration_s": 30.0},
                                                {"duration_s": 8.0, "turn_rate_dps": -5.0},
                                                {"duration_s": 2.0, "accel_mps2": -1.0}]},
            "aiding": {"rate_hz": 10.0, "velocity_sigma_mps": 0.05}}
    ev = fev.scenario_events(scenarios.parse(data, "my-drive.toml"), 120.0)
    assert [(e.t0_s, e.t1_s, e.label) for e in ev] == [
        (4.0, 24.0, "accelerate 0.5 m/s^2"), (54.0, 62.0, "left turn 5 deg/s"), (62.0, 64.0, "brake 1 m/s^2")]


def test_a_filter_with_its_own_coarse_stage_marks_the_hand_over_only_when_it_runs():
    scn = scenarios.get("sway-34n")
    kf, eso = scn.method("kf"), scn.method("eso-td")
    assert fev.method_events({"kf": kf, "eso-td": eso}, init_given=False)[0] == \
        fev.Event(kf.coarse_s, None, "coarse -> fine hand-over", ("kf", "eso-td"))
    assert fev.method_events({"kf": kf, "eso-td": eso}, init_given=True) == []
    pid = scn.method("pid")  # the narrower level loops (30 s), then the shot and the compass loop's closing at 70 s
    assert [(e.t0_s, e.label) for e in fev.method_events({"pid": pid}, True)] == \
        [(30.0, "level loops narrowed (60 s)"), (70.0, "azimuth shot, compass loop closed")]
    later = scn.method("pid").__class__(compass_stages=((90.0, 60.0, 190.0),))
    assert [e.t0_s for e in fev.method_events({"pid": later}, True)] == [30.0, 70.0, 90.0]


def test_no_limit_or_band_for_navigation_and_hours_on_the_axis(tmp_path):
    t = np.linspace(0, 72000.0, 300)
    out = _run("paper004-accel-0.02", {"undamped": (t, _converging(t, 2, 0)), "fixed": (t, _converging(t, 2, 1))},
               72000.0)
    for fig in (error_figure(out, tmp_path / "e.png"), azimuth_figure(out, tmp_path / "a.png")):
        labels = _labels(fig)
        assert not any("limit" in lab for lab in labels), labels
        assert {ax.get_xlabel() for ax in fig.axes} - {""} == {"time (h)"}
        # the switch-in (3 h) and the manoeuvre (12 h) marked on the time axis, in hours
        xs = {round(x, 3) for ax in fig.axes for ln in ax.lines if ln.get_linestyle() == ":" for x in ln.get_xdata()}
        assert 3.0 in xs
        spans = [p for ax in fig.axes for p in ax.patches if p.get_x() == pytest.approx(12.0)]
        assert spans
    assert (tmp_path / "e.png").stat().st_size > 10_000


def test_limit_and_band_drawn_for_an_alignment_scenario(tmp_path):
    t = np.linspace(0, 300.0, 200)
    out = _run("static-34n", {"coarse": (t, _converging(t, 3, 0)), "coarse-i0": (t, _converging(t, 3, 1))}, 300.0)
    labels = _labels(azimuth_figure(out, tmp_path / "a.png"))
    assert "limit" in labels and "limit +- 1 arcmin" in labels
    fig = error_figure(out, tmp_path / "e.png")
    assert "limit" in _labels(fig) and {ax.get_xlabel() for ax in fig.axes} - {""} == {"time (s)"}


def test_a_diverged_method_is_drawn_apart_and_does_not_rescale_the_others(tmp_path):
    t = np.linspace(0, 500.0, 250)
    hist = {n: (t, _converging(t, 3, k)) for k, n in enumerate(("kf", "akf", "eso-td", "gtsam"))}
    hist["eso-td-paper"] = (t, np.random.default_rng(5).normal(0, 3000, (3, t.size, 3)))
    fig = error_figure(_run("paper001-moving-base", hist, 500.0), tmp_path / "e.png")
    apart = [ax for ax in fig.axes if ax.get_title() == "diverged: own scale"]
    assert len(apart) == 1
    grid = fig.axes[0].get_gridspec()
    bad_col = [ax for ax in fig.axes if ax.get_subplotspec().colspan.start == grid.ncols - 1]
    others = [ax for ax in fig.axes if ax not in bad_col]
    assert {ln.get_label() for ax in bad_col for ln in ax.lines} >= {"eso-td-paper"}
    assert "eso-td-paper" not in {ln.get_label() for ax in others for ln in ax.lines}
    assert all(max(abs(y) for y in ax.get_ylim()) < 50 for ax in others)  # not +-10^4
    # five methods at most in a panel
    assert all(len([ln for ln in ax.lines if ln.get_label() in hist]) <= fg.MAX_PER_PANEL for ax in fig.axes)


def test_report_table_marks_a_diverged_method_and_leaves_out_the_limit_where_it_does_not_apply():
    st = {"mean": 1.0, "std": 0.1, "rms": 1.0, "max_abs": 1.0}
    r = {"final_error_arcmin": {ax: st for ax in "ENU"}, "settling_time_s": {"U": st, "band_arcmin": 2.0}, "wall_s": 1.0}
    m = {"limits_arcmin": {"E": 0.1, "N": 0.1, "U": -1.0}, "methods": {"kf": r, "eso-td-paper": r},
         "diverged": ["eso-td-paper"]}
    text = _table(m, "moving-alignment")
    assert "| eso-td-paper **(diverged)** |" in text and "| kf |" in text and "theoretical limit" not in text
    assert "theoretical limit" in _table(m, "alignment")


def test_many_methods_are_spread_over_panels():
    assert [len(g) for g in fg.groups([f"m{i}" for i in range(10)])] == [5, 5]
    assert [len(g) for g in fg.groups([f"m{i}" for i in range(7)])] == [4, 3]
    assert fg.groups(["a", "b"]) == [["a", "b"]]


def test_the_band_is_numpys_nan_aware_percentiles_at_every_time():
    # spread() sends the times without a NaN to np.percentile at once and the others to np.nanpercentile: each time's
    # band must be the 16th and 84th percentiles of the runs it has, a time where no run has a value staying NaN.
    # Independent computation: the percentiles of each time's finite values, by the definition (linear between the
    # order statistics, numpy's default)
    rng = np.random.default_rng(7)
    values = rng.normal(size=(7, 400)) * 10.0 ** rng.uniform(-6, 3, size=400)
    values[rng.random(values.shape) < 0.04] = np.nan
    values[:, 5] = np.nan
    lo, hi = fg.spread(values)
    assert np.isnan(values).any(axis=0).sum() > 20 and np.isnan(lo[5]) and np.isnan(hi[5])
    for m in range(values.shape[1]):
        x = np.sort(values[:, m][np.isfinite(values[:, m])])
        for q, got in zip(fg.BAND_PERCENTILES, (lo[m], hi[m])):
            if x.size == 0:
                continue
            pos = q / 100.0 * (x.size - 1)
            i = int(np.floor(pos))
            want = x[i] + (pos - i) * (x[min(i + 1, x.size - 1)] - x[i])
            assert got == pytest.approx(want, rel=1e-12, abs=1e-300)
