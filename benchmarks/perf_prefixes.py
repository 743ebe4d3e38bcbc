"""A smoother's settling on record prefixes: the factor graphs' prefix aligner beside cold prefix solves, in one process.

Run from the repository root::

    python benchmarks/perf_prefixes.py           # 5 runs x 600 s at 100 Hz (a few minutes on 2 idle cores)
    python benchmarks/perf_prefixes.py --quick   # 2 runs x 300 s

Workload: seed 000's (Zhou 2011, ADRC gyrocompass) Table-1 sway at 34 N (pitch/roll/yaw 5/7/9 deg at 0.5/0.3/0.2 Hz
about a -30 deg yaw), navigation-grade IMU (preset ``navigation``), ``simulate(..., seed=0)``: the data of
``perf_methods.py``. For each graph (``gtsam``, ``gtsam-robust``, ``gtsam-adaptive``) the runner's settling on prefixes
every 25 s (:func:`fusionbench.bench.runner._prefix_settling`, a 4-arcmin band about the truth: prefixes from the
end back to where every run has left it) is timed twice: ``cold``, each prefix solved from its own coarse alignment (the
runner before the prefix aligner: ``estimate_only``), and ``warm``, through ``prefix_aligner`` (the whole record solved
once, each prefix started from that solution, its shared intervals' preintegration reused), and ``kept``, the runner's
path since issue 26: the copy ``keeping_solutions()`` aligns the whole record first (the runner's own align, not timed
here) and its prefix aligner starts from that solution without solving the record again (a graph without a keeper,
``gtsam-adaptive``: not run). Reported: wall s of each, the speed-ups over cold, the largest azimuth difference between
the settling times (they must agree), s.

A table goes to stdout, then, as the last line, one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from fusionbench.bench import runner
from fusionbench.methods import aligner
from fusionbench.methods.aligner import Site
from fusionbench.simulation.imu import PRESETS, simulate

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from perf_methods import DT, H, LAT, LON, make_trajectory  # noqa: E402 (the benchmarks' folder on the path)

METHODS = ("gtsam", "gtsam-robust", "gtsam-adaptive")


class Cold:
    """The runner's view of a graph before the prefix aligner: its ``estimate_only`` copy, each prefix cold."""

    def __init__(self, method):
        self.inner = method.estimate_only()
        self.min_duration_s = method.min_duration_s

    def align(self, *args, **kwargs):
        return self.inner.align(*args, **kwargs)


class Scenario:
    """What ``_prefix_settling`` reads of a scenario: the band and the site (the limit is the truth's zero)."""

    settling_band_arcmin = 4.0
    site = Site(LAT, LON, H)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 runs x 300 s")
    ap.add_argument("--methods", nargs="*", default=METHODS, help="only these graphs (default: the three)")
    args = ap.parse_args(argv)
    runs, duration = (2, 300.0) if args.quick else (5, 600.0)
    tr = make_trajectory("sway", duration)
    data = simulate(tr, PRESETS["navigation"], DT, runs=runs, seed=0)
    runner.scenario_limits = lambda scn, traj, t, C: np.zeros((len(t), 3))  # against the truth itself
    phi_end = np.zeros(runs)  # every run inside the band on the whole record: prefixes tried until each left it
    out = {"runs": runs, "duration_s": duration, "methods": {}}
    print(f"{runs} runs x {duration:g} s at {1 / DT:g} Hz, prefixes every {runner.PREFIX_STEP_S:g} s")
    print("| method | cold s | warm s | kept s | speed-up (warm, kept) | settling (warm) s | largest difference s |")
    print("|---|---:|---:|---:|---:|---|---:|")
    for name in args.methods:
        method = aligner.load_method(name, imu="navigation")
        method.estimate_only().align(data.select_runs([0]), Scenario.site)  # warm-up (imports)
        t0 = time.perf_counter()
        cold, _ = runner._prefix_settling(Cold(method), data, None, None, tr, Scenario, phi_end, 0.0)
        t_cold = time.perf_counter() - t0
        t0 = time.perf_counter()  # gtsam-adaptive has no prefix aligner: the runner solves its prefixes cold
        warm, _ = runner._prefix_settling(method, data, None, None, tr, Scenario, phi_end, 0.0)
        t_warm = time.perf_counter() - t0
        diff = float(np.nanmax(np.abs(warm - cold)))
        t_kept, kept = None, None
        if callable(getattr(method, "keeping_solutions", None)):
            keeper = method.keeping_solutions()
            keeper.align(data, Scenario.site)  # the runner's align of the record (its marginals too)
            t0 = time.perf_counter()
            kept, _ = runner._prefix_settling(keeper, data, None, None, tr, Scenario, phi_end, 0.0)
            t_kept = time.perf_counter() - t0
            diff = max(diff, float(np.nanmax(np.abs(kept - cold))))
        out["methods"][name] = {"cold_s": t_cold, "warm_s": t_warm, "kept_s": t_kept, "speedup": t_cold / t_warm,
                                "speedup_kept": None if t_kept is None else t_cold / t_kept,
                                "settle_warm_s": warm.tolist(), "settle_cold_s": cold.tolist(),
                                "settle_kept_s": None if kept is None else kept.tolist(), "max_diff_s": diff}
        kept_s, kept_x = ("-", "-") if t_kept is None else (f"{t_kept:.1f}", f"{t_cold / t_kept:.2f}")
        print(f"| `{name}` | {t_cold:.1f} | {t_warm:.1f} | {kept_s} | {t_cold / t_warm:.2f}, {kept_x} | "
              f"{', '.join(f'{s:g}' for s in warm)} | {diff:g} |")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
