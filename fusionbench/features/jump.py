"""A noise-jump window (``[metrics] jump_window_s = [start, end]``, s): how each method's misalignment behaves
before, during and after it, and how long it takes to re-converge (seed 001's (Zhao 2007, ESO/TD alignment) R and Q
jumps)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusionbench.bench.feature import FeatureBase
from fusionbench.scoring import metrics
from fusionbench.simulation import fields, units


@dataclass(frozen=True)
class JumpWindow(FeatureBase):
    """The window ``[start_s, end_s)`` of a noise jump.

    Per method in metrics.json, ``jump``: ``window_s``; ``rms_arcmin`` before / during / after (RMS over runs and
    time, E, N, U); ``peak_arcmin`` (largest abs(error) from the jump on, over runs); ``reconverge_s`` (statistics
    over runs of the time after the window until phiU stays within the settling band of the limit)."""

    start_s: float
    end_s: float

    name = "jump"
    order = 10
    keys = frozenset({"jump_window_s"})

    @classmethod
    def parse(cls, table, src, duration_s, methods):
        w = fields.vector(table, "jump_window_s", f"{src} [metrics]", n=2)
        if not 0 < w[0] < w[1] < duration_s:
            raise fields.FieldError(f"{fields.where(src, 'metrics.jump_window_s')}: expected 0 < start < end < "
                                    f"duration_s, found {w}")
        return cls(float(w[0]), float(w[1]))

    def validate(self, duration_s, quick, where):
        if self.end_s >= duration_s:
            raise ValueError(f"{where}: metrics.jump_window_s {[self.start_s, self.end_s]} ends after the record of "
                             f"{duration_s:g} s{' (--quick: [quick] duration_s)' if quick else ''}: expected a window "
                             f"that ends before it")

    def collect(self, t, phi, band, limit_u):
        a, b = self.start_s, self.end_s
        parts = {"before": t < a, "during": (t >= a) & (t < b), "after": t >= b}
        after = t >= b
        return {"window_ms": {k: np.mean(phi[:, sel] ** 2, axis=1) for k, sel in parts.items() if sel.any()},
                "peak": np.max(np.abs(phi[:, t >= a]), axis=1),
                "reconverge": metrics.settling_time(t[after], phi[:, after, 2], band, limit_u[after]) - b}

    def summarise(self, per_run):
        return {"jump": {
            "window_s": [self.start_s, self.end_s],
            "rms_arcmin": {k: {ax: float(np.sqrt(ms[:, i].mean()) / units.ARCMIN) for i, ax in enumerate("ENU")}
                           for k, ms in per_run["window_ms"].items()},
            "peak_arcmin": {ax: float(per_run["peak"][:, i].max() / units.ARCMIN) for i, ax in enumerate("ENU")},
            "reconverge_s": metrics.stats(per_run["reconverge"]),
        }}

    def markdown(self, out):
        rows = [(n, r["jump"]) for n, r in out.metrics["methods"].items() if "jump" in r]
        if not rows:
            return ""
        lines = [f"## Noise jump ({self.start_s:g} s to {self.end_s:g} s)", "",
                 "Misalignment RMS over runs and time in each part of the record, peak |error| from the jump on, and "
                 "the time after the jump ends until phiU stays within the settling band of its final value "
                 "(arcmin, s):", "",
                 "| method | before E/N/U | during E/N/U | after E/N/U | peak E/N/U | re-converge (mean, max) |",
                 "|---|---|---|---|---|---|"]
        fmt = lambda d: " / ".join(f"{d[ax]:.2f}" for ax in "ENU") if d else "-"  # noqa: E731
        for n, j in rows:
            r = j["rms_arcmin"]
            lines.append(f"| {n} | {fmt(r.get('before'))} | {fmt(r.get('during'))} | {fmt(r.get('after'))} "
                         f"| {fmt(j['peak_arcmin'])} | {j['reconverge_s']['mean']:.0f}, "
                         f"{j['reconverge_s']['max_abs']:.0f} |")
        return "\n".join(lines) + "\n"

    def events(self):
        from fusionbench.reports.figure_events import Event

        return [Event(self.start_s, self.end_s, "noise-jump window")]
