"""The alignment experiment (``experiment = "alignment"``, the default): every aligner on identical simulated IMU
data, errors against truth and the theoretical limits (:mod:`fusionbench.bench.runner`,
:mod:`fusionbench.reports.report`).

Its scenarios are the files of :mod:`fusionbench.bench.scenarios`; its methods the ``fusionbench.methods`` group. A
free-inertial navigation scenario (kind ``navigation``: a :class:`fusionbench.methods.aligner.Navigator` started from a
given attitude) runs through the same Monte Carlo.
"""

from __future__ import annotations

from fusionbench.bench import scenarios
from fusionbench.methods import aligner
from fusionbench.methods.aligner import METHODS_GROUP


class AlignmentExperiment:
    """The alignment Monte Carlo as an :class:`fusionbench.bench.experiment.Experiment`."""

    name = "alignment"
    kind = None  # inferred from the scenario: alignment, moving-alignment or navigation
    method_group = METHODS_GROUP

    def load(self, data, src):
        return scenarios.parse(data, src)

    def load_method(self, scn, spec, **options):
        """A method with the scenario's IMU spec (the true model) and velocity-reference noise (the largest axis,
        m/s per sample: ``[vref]``'s, or ``[aiding]``'s velocity noise) offered to a method that takes them
        (:func:`fusionbench.methods.aligner.load_method`)."""
        sigma = scn.vref_spec.sigma
        if scn.aiding_spec is not None and scn.aiding_spec.velocity_sigma is not None:
            sigma = scn.aiding_spec.velocity_sigma
        given = {"imu": scn.imu_spec, "vref_sigma": float(max(sigma))}
        return aligner.load_method(spec, **{**given, **options})  # a variant's own imu / vref_sigma win

    def run(self, scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, refusals=False,
            batch_size=None):
        from fusionbench.bench.runner import run_alignment

        return run_alignment(scn, methods, runs, seed, quick, n_jobs, progress, batch_size, refusals)

    def write_report(self, out, folder):
        from fusionbench.reports.report import write_alignment_report

        return write_alignment_report(out, folder)

    def check(self, new, ref):
        return []  # the common rules of fusionbench.bench.check and the metric features' rules cover its figures


class NavigationExperiment(AlignmentExperiment):
    """Free-inertial navigation (``experiment = "navigation"``): the same Monte Carlo, its methods navigators
    (:class:`fusionbench.methods.aligner.Navigator`, e.g. ``damped-nav``) started from the scenario's initial attitude,
    scored against the truth over hours (kind ``navigation``: no stationary limit, no settling band)."""

    name = "navigation"
    kind = "navigation"

    def load(self, data, src):
        scn = scenarios.parse(data, src)
        if scn.init_misalignment is None:
            raise scenarios.ScenarioError(f"{src}: field 'init.misalignment_deg': expected the initial attitude error a "
                                          f"navigator starts from, found none")
        return scn

    def load_method(self, scn, spec, **options):
        method = super().load_method(scn, spec, **options)
        if not isinstance(method, aligner.Navigator):
            raise ValueError(f"method {spec!r}: expected a navigator (navigate(imu, site, init)), found an aligner")
        return method

