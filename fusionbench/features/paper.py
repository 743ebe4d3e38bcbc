"""The source paper beside the run (``[paper]``: ``reference``, ``note``, ``settling_time_s = {method = s}``): the
paper's printed azimuth settling times beside ours, and the reproduction note."""

from __future__ import annotations

from dataclasses import dataclass, field

from fusionbench.bench.feature import FeatureBase
from fusionbench.simulation import fields


@dataclass(frozen=True)
class PaperClaims(FeatureBase):
    """The ``[paper]`` table: the reference, the reproduction note and the paper's settling times per method
    (s; a variant is matched through its base method)."""

    reference: str = "source paper"
    note: str = ""
    settling_time_s: dict = field(default_factory=dict)

    name = "paper"
    order = 90
    table = "paper"
    keys = frozenset({"reference", "note", "settling_time_s"})

    @classmethod
    def parse(cls, table, src, duration_s, methods):
        for key in ("reference", "note"):
            if not isinstance(table.get(key, ""), str):
                raise fields.FieldError(f"{fields.where(src, 'paper.' + key)}: expected a string, found {table[key]!r}")
        claims = table.get("settling_time_s", {})
        if not isinstance(claims, dict):
            raise fields.FieldError(f"{fields.where(src, 'paper.settling_time_s')}: expected a table of method = "
                                    f"seconds, found {claims!r}")
        for method in claims:
            fields.number(claims, method, src, lo=0.0, label=f"paper.settling_time_s.{method}")
        return cls(table.get("reference", "source paper"), table.get("note", ""), dict(claims))

    def markdown(self, out):
        lines = [f"## Beside the paper ({self.reference})", ""]
        if self.settling_time_s:
            band = out.scenario.settling_band_arcmin
            lines += [f"| method | paper: azimuth settles in (s) | here: mean (max) settling in a {band:g} arcmin band "
                      "(s) | final phiU rms (arcmin) |", "|---|---|---|---|"]
            for name, r in out.metrics["methods"].items():
                st = r["settling_time_s"]["U"]
                base = out.scenario.variants.get(name, {}).get("method", name)
                lines.append(f"| {name} | {self.settling_time_s.get(base, '-')} | {st['mean']:.0f} ({st['max_abs']:.0f}) "
                             f"| {r['final_error_arcmin']['U']['rms']:.2f} |")
            lines.append("")
        if self.note:
            lines += [self.note.strip(), ""]
        return "\n".join(lines)
