"""Peak memory of a long scenario against its number of runs, streamed and held whole (issue 16, item 3).

Each measurement is one ``fusionbench run SCENARIO --runs N --jobs 1`` in a fresh child process, so that its peak
resident set size (``ru_maxrss``) is its own; the child runs the command line's ``main`` with
``fusionbench.bench.streaming.STREAM_MIN_S`` left as it is (``streamed``: the runner feeds the chunks to the methods
that take them) or set to infinity (``whole``: every run's samples held, as before the streaming). The metrics of the
two are compared (all but wall times and provenance) and must be equal.

    python benchmarks/perf_memory.py                 # paper004-accel-0.02 (20 h at 5 Hz), 2, 8 and 16 runs
    python benchmarks/perf_memory.py --quick         # 2 and 4 runs
    python benchmarks/perf_memory.py --runs 8 --scenario paper004-accel-0.05

The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = """
import json, resource, sys
from fusionbench.bench import streaming
from fusionbench.cli import main
mode, out = sys.argv[1], sys.argv[2]
if mode == "whole":
    streaming.STREAM_MIN_S = float("inf")
rc = main(sys.argv[3:] + ["--out", out])
print(json.dumps({"rc": rc, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def measure(scenario, runs, mode, folder):
    """Peak RSS (MB) and wall time (s) of one run of the command line in a child, and its metrics."""
    out = Path(folder) / f"{mode}-{runs}"
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", CHILD, mode, str(out), "run", scenario, "--runs", str(runs),
                           "--jobs", "1"], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{mode} {runs} runs failed: {proc.stderr.strip().splitlines()[-1:]}")
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    return got["peak_mb"], wall, json.loads((out / "metrics.json").read_text())


def _strip(d):
    if isinstance(d, dict):
        return {k: _strip(v) for k, v in d.items() if k not in ("wall_s", "provenance")}
    return d


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="paper004-accel-0.02")
    ap.add_argument("--runs", type=int, nargs="*", default=None, help="numbers of runs (default 2 8 16)")
    ap.add_argument("--quick", action="store_true", help="2 and 4 runs")
    args = ap.parse_args(argv)
    counts = args.runs or ([2, 4] if args.quick else [2, 8, 16])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        # one run first, its result thrown away: numba's on-disk cache is filled (a first compile costs memory)
        measure(args.scenario, 1, "streamed", tmp)
        print(f"{args.scenario}: peak RSS of `fusionbench run --runs N --jobs 1`, one child process each")
        print(f"{'runs':>5} {'streamed MB':>12} {'wall s':>7} {'whole MB':>9} {'wall s':>7}  same metrics")
        for n in counts:
            s_mb, s_wall, s_met = measure(args.scenario, n, "streamed", tmp)
            w_mb, w_wall, w_met = measure(args.scenario, n, "whole", tmp)
            same = _strip(s_met) == _strip(w_met)
            rows.append({"runs": n, "streamed_peak_mb": round(s_mb, 1), "streamed_wall_s": round(s_wall, 2),
                         "whole_peak_mb": round(w_mb, 1), "whole_wall_s": round(w_wall, 2), "same_metrics": same})
            print(f"{n:>5} {s_mb:>12.0f} {s_wall:>7.1f} {w_mb:>9.0f} {w_wall:>7.1f}  {same}")
    growth = (rows[-1]["streamed_peak_mb"] - rows[0]["streamed_peak_mb"]) / max(1, rows[-1]["runs"] - rows[0]["runs"])
    print(f"streamed: {growth:.2f} MB more per run from {rows[0]['runs']} to {rows[-1]['runs']} runs")
    print(json.dumps({"scenario": args.scenario, "rows": rows, "streamed_mb_per_run": round(growth, 2)}))


if __name__ == "__main__":
    main()
