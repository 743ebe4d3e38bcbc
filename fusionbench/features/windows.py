"""Attitude over windows of the run (``[metrics] rmse_window_s = [start, end]`` and ``amplitude_windows_s =
{name = [start, end], ...}``, s): the level RMSE in one window and the half peak-to-peak of the misalignment in
named ones (seed 004's (Gu 2017, adaptive Schuler damping) free-inertial navigation: the Schuler oscillation with and
without damping)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fusionbench.bench.check import ABS_TOL_ARCMIN, REL_TOL
from fusionbench.bench.feature import FeatureBase
from fusionbench.simulation import fields, units


def window(table, key, src, duration_s, label):
    """``table[key]`` validated as ``[start, end]`` with 0 <= start < end <= duration_s (s)."""
    w = table[key]
    if (not isinstance(w, list) or len(w) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                          for x in w) or not 0 <= w[0] < w[1] <= duration_s):
        raise fields.FieldError(f"{fields.where(src, label)}: expected [start, end] with 0 <= start < end <= "
                                f"duration_s, found {w!r}")
    return (float(w[0]), float(w[1]))


@dataclass(frozen=True)
class AttitudeWindows(FeatureBase):
    """The RMSE window ``rmse_window_s`` (or None) and the named amplitude windows, s.

    Per method in metrics.json: ``window_rmse_arcmin`` (``window_s`` and the RMS over runs and the window's time
    of E, N, U and the level error sqrt(E^2 + N^2)) and ``amplitude_arcmin`` (per window, half the peak-to-peak of
    E, N, U, mean over runs). Windows without samples (a ``--quick`` record) are left out."""

    rmse_window_s: tuple | None = None
    amplitude_windows_s: dict = field(default_factory=dict)

    name = "windows"
    order = 20
    keys = frozenset({"rmse_window_s", "amplitude_windows_s"})

    @classmethod
    def parse(cls, table, src, duration_s, methods):
        win = window(table, "rmse_window_s", src, duration_s, "metrics.rmse_window_s") if "rmse_window_s" in table \
            else None
        amp = table.get("amplitude_windows_s", {})
        if not isinstance(amp, dict):
            raise fields.FieldError(f"{fields.where(src, 'metrics.amplitude_windows_s')}: expected a table of name = "
                                    f"[start, end], found {amp!r}")
        amp = {n: window(amp, n, src, duration_s, f"metrics.amplitude_windows_s.{n}") for n in amp}
        return cls(win, amp) if win is not None or amp else None  # an empty table asks for nothing

    def collect(self, t, phi, band, limit_u):
        out = {}
        if self.rmse_window_s is not None:
            a, b = self.rmse_window_s
            sel = (t >= a) & (t <= b)
            if sel.any():
                ms = np.mean(phi[:, sel] ** 2, axis=1)
                out["rmse_ms"] = np.concatenate([ms, ms[:, :2].sum(axis=1, keepdims=True)], axis=1)  # E, N, U, level
        amp = {}
        for n, (a, b) in self.amplitude_windows_s.items():
            sel = (t >= a) & (t <= b)
            if sel.any():
                amp[n] = 0.5 * (phi[:, sel].max(axis=1) - phi[:, sel].min(axis=1))
        if amp:
            out["amplitude"] = amp
        return out

    def summarise(self, per_run):
        entry = {}
        if "rmse_ms" in per_run:
            rms = np.sqrt(per_run["rmse_ms"].mean(axis=0)) / units.ARCMIN
            entry["window_rmse_arcmin"] = {"window_s": list(self.rmse_window_s),
                                           **{ax: float(rms[i]) for i, ax in enumerate(("E", "N", "U", "level"))}}
        if "amplitude" in per_run:
            entry["amplitude_arcmin"] = {w: {ax: float(np.mean(v[:, i]) / units.ARCMIN) for i, ax in enumerate("ENU")}
                                         for w, v in per_run["amplitude"].items()}
        return entry

    def markdown(self, out):
        rows = [(n, r) for n, r in out.metrics["methods"].items() if "window_rmse_arcmin" in r or "amplitude_arcmin" in r]
        if not rows:
            return ""
        win, amps = self.rmse_window_s, self.amplitude_windows_s
        head = "| method |"
        if win is not None:
            head += f" RMSE {win[0]:.0f}-{win[1]:.0f} s: E / N / level |"
        head += "".join(f" amplitude '{w}' {a:.0f}-{b:.0f} s: E / N |" for w, (a, b) in amps.items())
        lines = ["## Attitude over the run", "",
                 "Level misalignment, arcmin: RMS over runs and the window's time, and the half peak-to-peak "
                 "in each amplitude window (mean over runs):", "", head, "|---" * (head.count("|") - 1) + "|"]
        for n, r in rows:
            row = f"| {n} |"
            if win is not None:
                w = r.get("window_rmse_arcmin")
                row += f" {w['E']:.3f} / {w['N']:.3f} / {w['level']:.3f} |" if w else " - |"
            for a in amps:
                v = r.get("amplitude_arcmin", {}).get(a)
                row += f" {v['E']:.3f} / {v['N']:.3f} |" if v else " - |"
            lines.append(row)
        return "\n".join(lines) + "\n"

    def report_figures(self, out, folder):
        level_figure(out, folder / "level.png", self.rmse_window_s)
        return {"level.png": "level errors against time"}

    @staticmethod
    def check(new, ref):
        """The level RMSE in the window may not grow beyond 10 % of the reference plus 0.05 arcmin."""
        bad = []
        for name, r in ref.get("methods", {}).items():
            if "window_rmse_arcmin" in r and name in new.get("methods", {}):
                rv = r["window_rmse_arcmin"]["level"]
                nv = new["methods"][name].get("window_rmse_arcmin", {}).get("level", float("nan"))
                allowed = rv * (1 + REL_TOL) + ABS_TOL_ARCMIN
                if not nv <= allowed:
                    bad.append((name, "window level RMSE (arcmin)", rv, nv, allowed))
        return bad


def level_figure(out, path, win=None):
    """Level misalignment (phiE, phiN, arcmin) against time, median and 16-84 % band of every method, with the
    RMSE window ``win`` (s) shaded and the events marked (like seed 004's Figs. 9-11). Returns the Figure."""
    from fusionbench.reports import figures as fg
    from fusionbench.reports.report import run_context

    c = run_context(out)
    fig, axes = fg.small_multiples(c, [(i, f"phi{'EN'[i]} (arcmin)", 0.0, False, []) for i in range(2)],
                                   lambda n, i: out.outcomes[n].phi[..., i] / units.ARCMIN)
    if win is not None:
        for ax in axes.ravel():
            ax.axvspan(win[0] / c.scale, win[1] / c.scale, color="tab:blue", alpha=0.08, lw=0)
    fg.finish(fig, f"{c.title}: level errors, median over runs and 16-84 % band",
              fg.notes(c, "" if win is None else f"Blue: the RMSE window, {win[0] / c.scale:.4g} to "
                       f"{win[1] / c.scale:.4g} {c.unit}."))
    fg.save_png(fig, path)
    return fig
