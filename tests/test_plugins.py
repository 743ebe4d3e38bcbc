"""Plug-in points: a new metric feature and a new experiment kind are one class plus registration.

The classes below stand for a user's package: registered here by patching the entry-point lookups (what
``pip install`` of a package with entry points does), they run through the same public path as the built-in
ones (a scenario file, ``run_scenario``, ``write_scenario_report``, ``check``) without any change to the core.
"""

from dataclasses import dataclass
from importlib.metadata import EntryPoint

import numpy as np
import pytest

from fusionbench.bench import experiment, feature as features, scenarios
from fusionbench.bench.check import compare
from fusionbench.bench.experiment import run_scenario, write_scenario_report
from fusionbench.bench.feature import FeatureBase
from fusionbench.experiments.alignment import AlignmentExperiment
from fusionbench.simulation import earth, units

TOML = """
name = "tiny-plugin"
description = "tiny static scenario for the plug-in tests"
duration_s = 30.0
rate_hz = 50.0
runs = 3
methods = ["coarse"]
[site]
lat_deg = 34.0
[imu]
preset = "tactical"
"""


@dataclass(frozen=True)
class WorstAzimuth(FeatureBase):
    """A user's metric feature: ``[metrics] worst_azimuth = true`` adds the largest final |phiU| over runs."""

    name = "worst-azimuth"
    keys = frozenset({"worst_azimuth"})

    @classmethod
    def parse(cls, table, src, duration_s, methods):
        if not isinstance(table["worst_azimuth"], bool):
            raise ValueError(f"{src}: field 'metrics.worst_azimuth': expected true or false, found "
                             f"{table['worst_azimuth']!r}")
        return cls() if table["worst_azimuth"] else None

    def collect(self, t, phi, band, limit_u):
        return {"phiu_end": phi[:, -1, 2]}

    def summarise(self, per_run):
        return {"worst_azimuth_arcmin": float(np.abs(per_run["phiu_end"]).max() / units.ARCMIN)}

    def markdown(self, out):
        rows = "".join(f"| {n} | {r['worst_azimuth_arcmin']:.3f} |\n" for n, r in out.metrics["methods"].items())
        return f"## Worst azimuth\n\n| method | largest final abs(phiU), arcmin |\n|---|---|\n{rows}"

    @staticmethod
    def check(new, ref):
        return [(n, "worst azimuth (arcmin)", r["worst_azimuth_arcmin"], new["methods"][n]["worst_azimuth_arcmin"],
                 r["worst_azimuth_arcmin"]) for n, r in ref["methods"].items() if "worst_azimuth_arcmin" in r
                and not new["methods"][n].get("worst_azimuth_arcmin", np.inf) <= r["worst_azimuth_arcmin"]]


class Repeated(AlignmentExperiment):
    """A user's experiment kind: an alignment Monte Carlo repeated at several latitudes (its own ``[repeat]``
    table), one metrics.json with a figure per latitude."""

    name = "repeated"
    kind = "alignment"

    @staticmethod
    def _table(table, src, duration_s):
        lats = table.get("lat_deg")
        if not isinstance(lats, list) or not lats:
            raise ValueError(f"{src}: field 'repeat.lat_deg': expected a list of latitudes, found {lats!r}")
        return [float(x) for x in lats]

    def load(self, data, src):
        return scenarios.parse(data, src, tables={"repeat": self._table})

    def run(self, scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, refusals=False):
        from dataclasses import replace

        from fusionbench.methods.aligner import Site

        outs = {lat: super(Repeated, self).run(replace(scn, site=Site.from_degrees(lat), experiment="alignment"),
                                               methods, runs, seed, quick, n_jobs, False)
                for lat in scn.setup["repeat"]}
        first = next(iter(outs.values()))
        first.metrics["by_latitude"] = {f"{lat:g}": {"limits_arcmin": o.metrics["limits_arcmin"],
                                                     "methods": o.metrics["methods"]} for lat, o in outs.items()}
        first.scenario = scn
        return first

    def check(self, new, ref):
        return [("-", f"latitude {lat}", "present", "absent", "present") for lat in ref.get("by_latitude", {})
                if lat not in new.get("by_latitude", {})]


@pytest.fixture
def plugins(monkeypatch):
    """Register the two classes as a package's entry points would."""
    found = experiment.available_experiments()
    found["repeated"] = EntryPoint("repeated", f"{__name__}:Repeated", experiment.EXPERIMENTS_GROUP)
    monkeypatch.setattr(experiment, "available_experiments", lambda: found)
    classes = features.feature_classes() + (WorstAzimuth,)
    monkeypatch.setattr(features, "feature_classes", lambda: classes)


def test_a_metric_feature_is_one_class_and_a_registration(plugins, tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(TOML + "[metrics]\nworst_azimuth = true\n")
    scn = scenarios.load(p)
    assert [f.name for f in scn.features] == ["worst-azimuth"]
    out = run_scenario(scn, progress=False)
    entry = out.metrics["methods"]["coarse"]
    # the feature's figure is the largest final |phiU|, which the core's own statistics give independently
    assert entry["worst_azimuth_arcmin"] == pytest.approx(entry["final_error_arcmin"]["U"]["max_abs"], rel=1e-12)
    report = write_scenario_report(out, tmp_path / "out").read_text()
    assert "## Worst azimuth" in report
    worse = {**out.metrics, "methods": {"coarse": {**entry, "worst_azimuth_arcmin": 2 * entry["worst_azimuth_arcmin"]}}}
    assert [row[1] for row in compare(worse, out.metrics)] == ["worst azimuth (arcmin)"]  # its check rule
    assert compare(out.metrics, out.metrics) == []
    p.write_text(TOML + "[metrics]\nworst_azimuth = 1\n")
    with pytest.raises(scenarios.ScenarioError, match="metrics.worst_azimuth"):
        scenarios.load(p)


def test_without_its_registration_a_features_key_is_an_unknown_field(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(TOML + "[metrics]\nworst_azimuth = true\n")
    with pytest.raises(scenarios.ScenarioError, match="'metrics.worst_azimuth': unknown"):
        scenarios.load(p)


def test_an_experiment_kind_is_one_class_and_a_registration(plugins, tmp_path):
    p = tmp_path / "r.toml"
    p.write_text(TOML.replace('name = "tiny-plugin"', 'name = "tiny-plugin"\nexperiment = "repeated"')
                 + "[repeat]\nlat_deg = [0.0, 60.0]\n")
    scn = scenarios.load(p)
    assert scn.experiment == "repeated" and scn.setup["repeat"] == [0.0, 60.0]
    out = run_scenario(scn, progress=False)
    by_lat = out.metrics["by_latitude"]
    assert set(by_lat) == {"0", "60"}
    # each latitude is its own alignment: on the equator, level and heading north (body x east), the azimuth
    # limit is -east gyro bias / earth rate (no tan L term); at 60 deg the earth rate's horizontal part halves
    bg, ba = scn.imu_spec.gyro.bias, scn.imu_spec.accel.bias
    assert by_lat["0"]["limits_arcmin"]["U"] == pytest.approx(-bg[0] / earth.OMEGA_IE / units.ARCMIN, rel=1e-3)
    lat = np.radians(60.0)
    expect = (-bg[0] / (earth.OMEGA_IE * np.cos(lat)) + np.tan(lat) * ba[0] / earth.gravity(lat)) / units.ARCMIN
    assert by_lat["60"]["limits_arcmin"]["U"] == pytest.approx(expect, rel=1e-3)
    write_scenario_report(out, tmp_path / "out")
    assert (tmp_path / "out" / "report.md").is_file()
    missing = {**out.metrics, "by_latitude": {"0": by_lat["0"]}}
    assert ("-", "latitude 60", "present", "absent", "present") in compare(missing, out.metrics)
    p.write_text(p.read_text().replace("lat_deg = [0.0, 60.0]", "lat_deg = 5"))
    with pytest.raises(scenarios.ScenarioError, match="repeat.lat_deg"):
        scenarios.load(p)


def test_an_unregistered_experiment_is_one_line_naming_the_registered_ones(tmp_path):
    p = tmp_path / "r.toml"
    p.write_text(TOML.replace('name = "tiny-plugin"', 'name = "tiny-plugin"\nexperiment = "repeated"'))
    with pytest.raises(scenarios.ScenarioError) as exc:
        scenarios.load(p)
    msg = str(exc.value)
    assert "\n" not in msg and "experiment" in msg and "'alignment'" in msg and "'repeated'" in msg


def test_every_scenario_type_has_the_common_attributes_and_resolves_its_experiment_once():
    """A scenario (Scenario) and a matrix (Matrix) answer the attributes the core reads on any scenario, and the
    experiment named in the file is loaded once per scenario (the same object on every use)."""
    from fusionbench.experiments.conformance import ConformanceExperiment

    for name, exp_type, conditions in (("static-r-jump", AlignmentExperiment, 0),
                                       ("conformance", ConformanceExperiment, 28)):
        scn = scenarios.get(name)
        assert isinstance(scn, experiment.ScenarioBase) and scn.template is False
        assert len(scn.conditions) == conditions and isinstance(scn.experiment_type, exp_type)
        assert scn.experiment_type is scn.experiment_type
    matrix = scenarios.get("conformance")
    assert matrix.features == () and dict(matrix.variants) == {} and matrix.init_misalignment is None
    assert type(matrix.method("kf")).__name__ == "KalmanAligner"  # through the matrix's own experiment
    assert scenarios.get("twin", {"imu": "tactical", "site": {"lat_deg": 34.0}}).template is True
