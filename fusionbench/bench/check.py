"""Compare a run's metrics.json with committed reference metrics: the accuracy regression check.

A figure regresses when it is worse than the reference beyond the tolerance (improvements pass):

* final error per axis, ``rms`` and ``|mean|``: new > ref * (1 + REL_TOL) + max(ABS_TOL_ARCMIN, std / N);
* azimuth settling time (against the truth: the limit's band), mean: new > ref * (1 + REL_TOL)
  + max(ABS_TOL_S, std / N);
* the fraction of runs that end inside that band (``settled_fraction_U``): new < ref - ABS_TOL_FRACTION;
* a method of the reference missing from the run;
* and the rules of every registered experiment and metric feature for the figures they add
  (:meth:`fusionbench.bench.experiment.Experiment.check`, :meth:`fusionbench.bench.feature.Feature.check`): the level
  RMSE in a window as the final error (``window_rmse_arcmin``); a comparison's ``reduction_percent``: new < ref -
  ABS_TOL_PERCENT; a conformance matrix's cells: a cell that passed must pass, its azimuth efficiency not beyond
  ref * (1 + REL_TOL) + ABS_TOL_EFFICIENCY; a family's experiment
  documents its own there (e.g. a platform calibration's coefficient groups).

Where the tolerance comes from: the same scenario, seed and size give identical numbers on one machine, so
the Monte Carlo sampling noise cancels between a run and its reference. What remains across platforms and
library versions is floating-point rounding, which a chaotic run (an adaptive filter, 20 h of free-inertial
navigation) can amplify until one run of the N lands elsewhere in the distribution. The tolerance admits that:
on a final error or a settling time, ``max(absolute floor, std / N)`` with the reference's own standard deviation
over its N runs (one run moving by one Monte Carlo standard deviation shifts a mean by std / N), plus 10 % of
the reference for slow drift. A behaviour change moves every run and exceeds it.

The references ship with the package (``fusionbench/references/<size>/<scenario>.json``, size ``quick`` or
``default``: the metrics.json of ``fusionbench run all [--quick]`` with seed 0); :func:`packaged_reference`
picks the folder by the size a run's metrics.json records.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

from fusionbench.bench import experiment, feature as features

REL_TOL = 0.10
ABS_TOL_ARCMIN = 0.05
ABS_TOL_S = 5.0
ABS_TOL_PERCENT = 5.0
ABS_TOL_FRACTION = 0.1
ABS_TOL_EFFICIENCY = 0.05


def _allowed(value, std, runs, floor):
    """The largest accepted figure: 10 % above the reference plus the larger of the floor and std / runs."""
    return abs(value) * (1 + REL_TOL) + max(floor, std / max(runs, 1))


def packaged_reference(quick: bool) -> Path:
    """The folder of references shipped with fusionbench for runs of the ``--quick`` or the default size."""
    return Path(str(resources.files("fusionbench") / "references" / ("quick" if quick else "default")))


def compare(new: dict, ref: dict):
    """Rows ``(method, figure, reference, new, allowed)`` of every figure that regressed."""
    bad = []
    runs = ref.get("runs", 1)
    for name, r in ref["methods"].items():
        n = new["methods"].get(name)
        if n is None:
            bad.append((name, "method missing from run", "present", "absent", "present"))
            continue
        for ax in "ENU":
            for stat in ("rms", "mean"):
                rv = abs(r["final_error_arcmin"][ax][stat])
                nv = abs(n["final_error_arcmin"][ax][stat])
                allowed = _allowed(rv, r["final_error_arcmin"][ax].get("std", 0.0), runs, ABS_TOL_ARCMIN)
                if not nv <= allowed:
                    bad.append((name, f"final phi{ax} |{stat}| (arcmin)", rv, nv, allowed))
        rv = r["settling_time_s"]["U"]["mean"]
        nv = n["settling_time_s"]["U"]["mean"]
        allowed = _allowed(rv, r["settling_time_s"]["U"].get("std", 0.0), runs, ABS_TOL_S)
        if not nv <= allowed:
            bad.append((name, "settling U mean (s)", rv, nv, allowed))
        if "settled_fraction_U" in r:
            rv, nv = r["settled_fraction_U"], n.get("settled_fraction_U", float("nan"))
            if not nv >= rv - ABS_TOL_FRACTION:
                bad.append((name, "runs settled in the band", rv, nv, rv - ABS_TOL_FRACTION))
    for exp in experiment.all_experiments().values():  # the figures each experiment adds (it finds none in another's metrics)
        bad += exp.check(new, ref)
    for feature in features.feature_classes():  # and each metric feature
        bad += feature.check(new, ref)
    return bad


def metrics_files(folder):
    """metrics.json of ``folder`` itself, or of each scenario sub-folder (a ``run all`` output)."""
    folder = Path(folder)
    if (folder / "metrics.json").is_file():
        return [folder / "metrics.json"]
    # a hidden folder is a report being assembled or set aside (fusionbench.files.reportdir), not a scenario's
    found = sorted(p for p in folder.glob("*/metrics.json") if not p.parent.name.startswith("."))
    if not found:
        raise ValueError(f"{folder}: no metrics.json in it or in its sub-folders")
    return found


def load_json(path, what):
    try:
        with open(path) as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise ValueError(f"{path}: {what} not found") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: {what} is not valid JSON ({exc})") from None


def load_metrics(path, what):
    """A metrics.json (a run's or a reference) checked for the keys :func:`compare` reads
    (:func:`check_shape`)."""
    metrics = load_json(path, what)
    check_shape(metrics, path)
    return metrics


#: What :func:`compare` reads of each method of a metrics.json, (keys, required); the experiments' and the metric
#: features' own rules read their optional figures with ``.get``.
METHOD_KEYS = ([(("final_error_arcmin", ax, stat), True) for ax in "ENU" for stat in ("mean", "rms")]
               + [(("final_error_arcmin", ax, "std"), False) for ax in "ENU"]
               + [(("settling_time_s", "U", "mean"), True), (("settling_time_s", "U", "std"), False),
                  (("settled_fraction_U",), False)])
_MISSING = object()


def _found(value):
    if value is _MISSING:
        return "none"
    if value is None or isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, str):
        return f"the string {value[:40]!r}"
    if isinstance(value, (list, dict)):
        return "a list" if isinstance(value, list) else "an object"
    return f"{type(value).__name__} {value!r}"


def _expect(metrics, keys, kind, path, required=True):
    """The value at ``keys`` if it is of ``kind`` ("a number", "a string", "an object"), else ValueError naming
    ``path`` and the key; None when it is absent and not ``required``."""
    value = metrics
    for i, key in enumerate(keys):
        if not isinstance(value, dict):
            raise ValueError(f"{path}: key {'.'.join(keys[:i])!r}: expected an object, found {_found(value)}")
        value = value.get(key, _MISSING)
        if value is _MISSING:
            break
    if value is _MISSING and not required:
        return None
    ok = {"a number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
          "a string": lambda v: isinstance(v, str), "an object": lambda v: isinstance(v, dict)}[kind]
    if not ok(value):
        raise ValueError(f"{path}: key {'.'.join(keys)!r}: expected {kind}, found {_found(value)}")
    return value


def check_shape(metrics, path):
    """Raise ValueError, one line naming ``path`` and the first key, unless ``metrics`` has what :func:`compare`
    and ``fusionbench check`` read: ``scenario`` (a string), ``runs`` (a number, optional), ``methods`` (an
    object) and for each method the :data:`METHOD_KEYS` (numbers)."""
    if not isinstance(metrics, dict):
        raise ValueError(f"{path}: expected a JSON object, found {_found(metrics)}")
    _expect(metrics, ("scenario",), "a string", path)
    _expect(metrics, ("runs",), "a number", path, required=False)
    for name in _expect(metrics, ("methods",), "an object", path):
        _expect(metrics, ("methods", name), "an object", path)
        for keys, required in METHOD_KEYS:
            _expect(metrics, ("methods", name, *keys), "a number", path, required)


def reference_for(reference, scenario):
    """The reference file for ``scenario`` under ``reference`` (a folder of ``<scenario>.json`` or one file)."""
    reference = Path(reference)
    path = reference / f"{scenario}.json" if reference.is_dir() else reference
    if reference.is_dir() and not path.is_file():
        have = sorted(p.stem for p in reference.glob("*.json"))
        raise ValueError(f"{reference}: no reference for scenario {scenario!r} (it has {', '.join(have) or 'none'}); "
                         f"give one with --reference")
    ref = load_metrics(path, "reference metrics")
    if ref.get("scenario") != scenario:
        raise ValueError(f"{path}: reference is for scenario {ref.get('scenario')!r}, the run is {scenario!r}")
    return ref, path


def format_table(rows):
    lines = [f"{'method':<14} {'figure':<30} {'reference':>10} {'now':>10} {'allowed':>10}"]
    for m, fig, rv, nv, al in rows:
        fmt = (lambda v: f"{v:10.3f}") if isinstance(rv, float) else (lambda v: f"{v!s:>10}")
        lines.append(f"{m:<14} {fig:<30} {fmt(rv)} {fmt(nv)} {fmt(al)}")
    return "\n".join(lines)
