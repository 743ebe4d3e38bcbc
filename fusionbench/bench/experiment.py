"""Experiments: what a scenario file runs, as plug-ins.

A scenario file names its experiment (``experiment = "..."``, default ``alignment``); the experiment reads the
file, runs the Monte Carlo, writes metrics.json and report.md, and gives the check rules of the figures it adds.
Experiments are found by name in the entry-point group ``fusionbench.experiments``, like methods: the core's
own (``alignment``: IMU data to aligners, :mod:`fusionbench.experiments.alignment`; ``conformance``: the method x
condition matrix, :mod:`fusionbench.experiments.conformance`) are registered in pyproject.toml exactly as a family's
are (a method family's own experiment lives in the family's package). Adding an experiment kind is one module with a
class following :class:`Experiment` and one line of registration; the runner, report and check do not change.

The data path of every experiment: scenario file -> :meth:`Experiment.load` -> :meth:`Experiment.run` (an
outcome with ``scenario`` and ``metrics``: the metrics.json mapping) -> :meth:`Experiment.write_report`
(metrics.json, report.md, figures) and :meth:`Experiment.check` (its regression rules beside the common ones of
:mod:`fusionbench.bench.check`).
"""

from __future__ import annotations

import functools
from importlib.metadata import entry_points
from pathlib import Path
from typing import Protocol, runtime_checkable

from fusionbench.bench.memory import fresh_workers_after_compiling
from fusionbench.files import reportdir
from fusionbench.files.pages import write_page

EXPERIMENTS_GROUP = "fusionbench.experiments"


@runtime_checkable
class Experiment(Protocol):
    """Protocol of an experiment kind (structural: no base class needed).

    Attributes
    ----------
    name : str
        The value of a scenario file's ``experiment`` key.
    kind : str or None
        The scenario kind it gives (:data:`fusionbench.bench.scenarios.SCENARIO_KINDS`: what the figures draw and the
        overview scores) when the file names none; None: inferred from the scenario's content.
    method_group : str
        Entry-point group of the methods it runs (``fusionbench.methods`` for aligners).
    """

    name: str
    kind: str | None
    method_group: str

    def load(self, data: dict, src: str):
        """Validate a scenario mapping (as read from TOML, ``src`` its file for messages) and build the scenario: an
        instance of a :class:`ScenarioBase` subclass with ``sized(quick) -> (duration_s, runs)``. An invalid field
        raises one line naming the file and field."""

    def load_method(self, scn, spec: str, **options):
        """Instantiate one of the experiment's methods for scenario ``scn`` by registered name or ``module:Class``."""

    def run(self, scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, refusals=False):
        """Run the Monte Carlo; returns an outcome with ``scenario`` and ``metrics`` (the metrics.json mapping).
        Same scenario and seed give the same numbers whatever ``n_jobs``."""

    def write_report(self, out, folder: Path) -> Path:
        """Write metrics.json, report.md and the figures of outcome ``out`` into ``folder``; returns report.md."""

    def check(self, new: dict, ref: dict) -> list:
        """Regression rows ``(method, figure, reference, new, allowed)`` of the figures this experiment adds to
        metrics.json (the common ones are :func:`fusionbench.bench.check.compare`'s); [] when ``ref`` has none."""


class ScenarioBase:
    """What every experiment's scenario type has: the experiment that runs it, loaded once, and the attributes the
    core reads on any scenario (a type without one of them declares its neutral value as a class variable).
    An experiment's :meth:`Experiment.load` returns an instance of its own subclass.

    Attributes
    ----------
    name, description, experiment, kind, source : str
        The scenario's name, its one-line description, the experiment and scenario kind, the file it came from.
    methods : tuple or None
        The methods it runs by default.
    template : bool
        A template of the user's sensor (needs ``--imu`` and ``--site`` to run).
    conditions : tuple
        A matrix's conditions (empty: one condition, the scenario itself).
    features : tuple
        Metric features (:mod:`fusionbench.features`).
    variants : mapping
        Named method variants of the scenario file, ``{name: options}``.
    init_misalignment : tuple or None
        Initial misalignment handed to the methods (deg), or None: each starts on its own.
    """

    @functools.cached_property
    def experiment_type(self) -> "Experiment":
        """The experiment that runs this scenario (its ``experiment`` name resolved once, then kept)."""
        return load_experiment(self.experiment, f"{self.source or self.name}: experiment")

    def method(self, name):
        """One of the experiment's methods for this scenario, by registered name or ``module:Class``
        (:meth:`Experiment.load_method`)."""
        return self.experiment_type.load_method(self, name)



def available_experiments():
    """Registered experiments: ``{name: entry point}`` of the ``fusionbench.experiments`` group."""
    return {ep.name: ep for ep in entry_points(group=EXPERIMENTS_GROUP)}


def load_experiment(name: str, where: str = "experiment") -> Experiment:
    """The registered experiment ``name``; ValueError naming ``where`` and the registered names otherwise."""
    eps = available_experiments()
    if not isinstance(name, str) or name not in eps:
        raise ValueError(f"{where}: expected one of {sorted(eps)}, found {name!r}")
    return eps[name].load()()


def all_experiments():
    """An instance of every registered experiment, by name."""
    return {name: ep.load()() for name, ep in sorted(available_experiments().items())}


def run_scenario(scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, batch_size=None,
                 refusals=False):
    """Run scenario ``scn`` with its experiment (:meth:`Experiment.run`).

    Parameters
    ----------
    scn : scenario object
        From :func:`fusionbench.bench.scenarios.get` or an experiment's ``load``.
    methods : sequence of str, optional
        Method names or ``module:Class`` paths (default: the scenario's list).
    runs : int, optional
        Monte Carlo runs (default: the scenario's full or quick size).
    seed : int
        Seed; run k of seed s gives the same numbers whatever the batch size or worker count.
    quick : bool
        Use the scenario's reduced duration and run count.
    n_jobs : int
        Parallel workers (joblib; -1: all cores).
    progress : bool or bar, optional
        A bar over runs (default: only when stderr is a terminal).
    batch_size : int, optional
        Runs per batch, for experiments that batch (the alignment Monte Carlo); others ignore it.
    refusals : bool
        Record a method that refuses the data instead of stopping (the conformance matrix).

    Returns
    -------
    The experiment's outcome: ``scenario``, ``metrics`` (the metrics.json mapping) and what its report draws.
    """
    exp = scn.experiment_type
    options = {"batch_size": batch_size} if batch_size is not None else {}
    with fresh_workers_after_compiling(n_jobs):  # what the compiler held stays out of the next scenario's workers
        return exp.run(scn, methods=methods, runs=runs, seed=seed, quick=quick, n_jobs=n_jobs, progress=progress,
                       refusals=refusals, **options)


def write_scenario_report(out, folder):
    """Write metrics.json, report.md, report.html and the figures of a run into ``folder`` with the run's
    experiment (:meth:`Experiment.write_report`), all or nothing (:func:`fusionbench.files.reportdir.staged`): the
    report is written into a temporary folder beside ``folder`` and replaces it whole when complete. ``folder``
    must be absent, empty or a previous report (else ValueError, one line). Returns the report's path."""
    folder = Path(folder)
    exp = out.scenario.experiment_type
    with reportdir.staged(folder) as tmp:
        report = Path(exp.write_report(out, tmp))
        write_page(report)
    return folder / report.relative_to(tmp)
