"""The metric features' protocol and registry. A feature gives optional figures a scenario asks for, one class in one
module (the built-in ones are in :mod:`fusionbench.features`).

A feature owns some keys of one table of the scenario file (``[metrics]`` or ``[paper]``) and everything that
follows from them: it validates its keys (:meth:`Feature.parse`), collects per-run figures from each method's
misalignment history on each batch (:meth:`Feature.collect`), summarises them into the method's metrics.json
entry (:meth:`Feature.summarise`) and the run's top level (:meth:`Feature.summarise_run`), writes its report
section and figures (:meth:`Feature.markdown`, :meth:`Feature.report_figures`), marks its events on the
figures (:meth:`Feature.events`) and gives its regression rules to ``fusionbench check`` (:meth:`Feature.check`,
which reads only metrics.json). The features are found in the entry-point group ``fusionbench.features``: a new
metric feature is one module with one class and one line of registration in pyproject.toml.

Built in: :class:`~fusionbench.features.jump.JumpWindow` (``jump_window_s``: before / during / after a noise
jump), :class:`~fusionbench.features.windows.AttitudeWindows` (``rmse_window_s``, ``amplitude_windows_s``),
:class:`~fusionbench.features.compare.Comparison` (``compare``: seed 004's (Gu 2017, adaptive Schuler damping) eq. 14
reduction between two methods)
and :class:`~fusionbench.features.paper.PaperClaims` (``[paper]``: the source paper's claims beside ours).
"""

from __future__ import annotations

from functools import lru_cache
from importlib.metadata import entry_points
from typing import Protocol, runtime_checkable

FEATURES_GROUP = "fusionbench.features"


@runtime_checkable
class Feature(Protocol):
    """Protocol of a metric feature (structural; :class:`FeatureBase` gives the do-nothing defaults).

    Attributes
    ----------
    name : str
        Short name (``Scenario.feature(name)`` finds it).
    table : str
        The scenario file's table holding its keys: ``"metrics"`` or ``"paper"``.
    keys : frozenset of str
        Its keys in that table.
    """

    name: str
    table: str
    keys: frozenset

    @classmethod
    def parse(cls, table: dict, src: str, duration_s: float, methods: list):
        """The feature for this scenario from its ``table`` (the whole ``[metrics]`` or ``[paper]`` mapping), or
        None when the table has none of its keys; ValueError naming ``src`` and the field when a value is wrong."""

    def collect(self, t, phi, band, limit_u) -> dict:
        """Per-run figures of one method on one batch: ``t`` (M,) s, ``phi`` (R, M, 3) rad misalignment (E, N, U)
        against truth, ``band`` rad the settling band, ``limit_u`` (M,) rad the azimuth limit. Returns arrays (or
        dicts of arrays) with the runs first; the runner joins the batches along that axis."""

    def summarise(self, per_run: dict) -> dict:
        """Entries added to a method's metrics.json entry from its joined per-run figures."""

    def summarise_run(self, metrics: dict, outcomes: dict) -> dict:
        """Entries added to the top level of metrics.json (e.g. a comparison between two methods)."""

    def markdown(self, out) -> str:
        """Its report.md section ("" for none) from a finished run ``out`` (``scenario``, ``metrics``)."""

    def report_figures(self, out, folder) -> dict:
        """Figures it draws into ``folder``: ``{file name: caption}``."""

    def events(self) -> list:
        """Its spans or instants on the figures' time axis (:class:`fusionbench.reports.figure_events.Event`)."""

    def validate(self, duration_s: float, quick: bool, where: str):
        """Raise ValueError (one line naming ``where`` and its field) when it does not fit a record of
        ``duration_s`` (e.g. a window that ends after a ``--quick`` record)."""

    @staticmethod
    def check(new: dict, ref: dict) -> list:
        """Regression rows ``(method, figure, reference, new, allowed)`` of its figures, read from two
        metrics.json mappings; [] when ``ref`` has none of them."""


class FeatureBase:
    """Do-nothing defaults of the :class:`Feature` hooks; a feature overrides what it uses."""

    name = ""
    table = "metrics"
    keys = frozenset()
    #: Place of its report section among the features' (smaller first).
    order = 50

    def collect(self, t, phi, band, limit_u):
        return {}

    def summarise(self, per_run):
        return {}

    def summarise_run(self, metrics, outcomes):
        return {}

    def markdown(self, out):
        return ""

    def report_figures(self, out, folder):
        return {}

    def events(self):
        return []

    def validate(self, duration_s, quick, where):
        return None

    @staticmethod
    def check(new, ref):
        return []


@lru_cache(maxsize=1)
def feature_classes():
    """The registered feature classes in the order of their report sections (their ``order``, then name)."""
    classes = [ep.load() for ep in entry_points(group=FEATURES_GROUP)]
    return tuple(sorted(classes, key=lambda cls: (getattr(cls, "order", 50), cls.name)))


def table_keys(table: str) -> frozenset:
    """Every key the registered features own in ``table`` (``"metrics"`` or ``"paper"``)."""
    return frozenset().union(*(cls.keys for cls in feature_classes() if cls.table == table))


def parse_features(data: dict, src: str, duration_s: float, methods: list) -> tuple:
    """The features a scenario mapping asks for (instances, in :func:`feature_classes` order)."""
    found = []
    for cls in feature_classes():
        table = data.get(cls.table, {})
        if set(table) & cls.keys:
            found.append(cls.parse(table, src, duration_s, list(methods)))
    return tuple(f for f in found if f is not None)
