"""A comparison of two methods (``[metrics] compare = [base, candidate]``): the reduction of the level RMSE in
the RMSE window, 100 (base - candidate) / base (seed 004's (Gu 2017, adaptive Schuler damping) eq. 14)."""

from __future__ import annotations

from dataclasses import dataclass

from fusionbench.bench.check import ABS_TOL_PERCENT
from fusionbench.bench.feature import FeatureBase
from fusionbench.simulation import fields


@dataclass(frozen=True)
class Comparison(FeatureBase):
    """Base and candidate method names.

    Top level of metrics.json: ``rmse_<base>_arcmin``, ``rmse_<candidate>_arcmin`` (their ``window_rmse_arcmin``
    level figures), ``reduction_percent`` and the figures the candidate reports about itself (e.g. ``map_mse``);
    written only when both methods ran."""

    base: str
    candidate: str

    name = "compare"
    order = 30
    keys = frozenset({"compare"})

    @classmethod
    def parse(cls, table, src, duration_s, methods):
        c = table["compare"]
        if not isinstance(c, list) or len(c) != 2 or not all(isinstance(x, str) for x in c) or not set(c) <= set(methods):
            raise fields.FieldError(f"{fields.where(src, 'metrics.compare')}: expected two of the scenario's methods "
                                    f"{methods}, found {c!r}")
        if "rmse_window_s" not in table:
            raise fields.FieldError(f"{fields.where(src, 'metrics.compare')}: needs metrics.rmse_window_s, found none")
        return cls(c[0], c[1])

    def summarise_run(self, metrics, outcomes):
        ms = metrics["methods"]
        if not all(n in ms and "window_rmse_arcmin" in ms[n] for n in (self.base, self.candidate)):
            return {}
        rb = ms[self.base]["window_rmse_arcmin"]["level"]
        rc = ms[self.candidate]["window_rmse_arcmin"]["level"]
        return {f"rmse_{self.base}_arcmin": rb, f"rmse_{self.candidate}_arcmin": rc,
                "reduction_percent": float(100.0 * (rb - rc) / rb) if rb > 0 else 0.0,  # seed 004 eq. 14
                **outcomes[self.candidate].figures}

    def markdown(self, out):
        m = out.metrics
        if "reduction_percent" not in m:
            return ""
        b, c = self.base, self.candidate
        return (f"Level RMSE in the window: `{b}` {m[f'rmse_{b}_arcmin']:.3f} arcmin, `{c}` {m[f'rmse_{c}_arcmin']:.3f} "
                f"arcmin; reduction 100 (base - candidate) / base = **{m['reduction_percent']:.1f} %**.\n")

    @staticmethod
    def check(new, ref):
        """The reduction may not fall more than 5 percentage points below the reference's."""
        if "reduction_percent" not in ref:
            return []
        rv, nv = ref["reduction_percent"], new.get("reduction_percent", float("nan"))
        return [] if nv >= rv - ABS_TOL_PERCENT else [("-", "reduction (%)", rv, nv, rv - ABS_TOL_PERCENT)]
