"""A process's memory from one scenario to the next, with glibc's mmap threshold as glibc moves it and fixed by the
runner (:func:`fusionbench.bench.memory.pin_mmap_threshold`), side by side (issue 26, item 3).

A worker of ``fusionbench run all`` runs every scenario in turn. Each measurement here is one fresh child process that
runs a sequence of scenarios with ``--jobs 1`` semantics (``run_scenario(..., n_jobs=1)``, 13 runs a batch as the
default batches of static-q-jump): static-q-jump alone, or after paper004-accel-0.005 (20-h records at 5 Hz, which
free large blocks). ``glibc`` leaves the threshold to glibc (the runner's call made a no-op), ``pinned`` is the
runner as it is. Reported per child: its peak resident set (``ru_maxrss``, the whole sequence: static-q-jump's peak
is the larger), each step's wall time and the resident set after it (heap trimmed). The two modes' metrics must be
equal.

    python benchmarks/perf_heap.py            # 13 runs of static-q-jump at default size (about 10 min)
    python benchmarks/perf_heap.py --quick    # 4 runs

The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

CHILD = """
import gc, json, resource, sys, time
from fusionbench.bench import runner, scenarios
from fusionbench.bench.experiment import run_scenario
from fusionbench.bench.memory import release_freed_heap
mode, runs, steps = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
if mode == "glibc":
    runner.pin_mmap_threshold = lambda: False
def resident_mb():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() / 2**20
out = {"steps": [], "metrics": {}}
for name in steps:
    t0 = time.perf_counter()
    res = run_scenario(scenarios.get(name), runs=runs if name == "static-q-jump" else None, n_jobs=1,
                       progress=False, batch_size=13)
    wall = time.perf_counter() - t0
    out["metrics"][name] = {k: v for k, v in res.metrics.items() if k != "provenance"}
    del res
    gc.collect()
    release_freed_heap()
    out["steps"].append({"scenario": name, "wall_s": wall, "after_mb": resident_mb()})
out["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(out))
"""

SEQUENCES = {"alone": ["static-q-jump"], "after paper004": ["paper004-accel-0.005", "static-q-jump"]}


def _strip_walls(m):
    """The metrics without wall times (they differ between any two runs)."""
    if isinstance(m, dict):
        return {k: _strip_walls(v) for k, v in m.items() if "wall" not in k}
    if isinstance(m, list):
        return [_strip_walls(v) for v in m]
    return m


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 runs of static-q-jump, not 13")
    args = ap.parse_args(argv)
    if not sys.platform.startswith("linux"):
        print("the mmap threshold is glibc's: Linux only")
        return 0
    runs = 4 if args.quick else 13
    rows, metrics = [], {}
    for seq, steps in SEQUENCES.items():
        for mode in ("glibc", "pinned"):
            t0 = time.perf_counter()
            done = subprocess.run([sys.executable, "-c", CHILD, mode, str(runs), *steps], capture_output=True,
                                  text=True, check=True)
            res = json.loads(done.stdout.strip().splitlines()[-1])
            metrics[(seq, mode)] = _strip_walls(res.pop("metrics"))
            rows.append({"sequence": seq, "mode": mode, "peak_mb": res["peak_mb"], "steps": res["steps"],
                         "child_s": time.perf_counter() - t0})
            last = res["steps"][-1]
            print(f"{seq:16s} {mode:7s} peak {res['peak_mb']:6.0f} MB   static-q-jump {last['wall_s']:6.1f} s, "
                  f"{last['after_mb']:5.0f} MB after", flush=True)
    same = all(metrics[(seq, "glibc")] == metrics[(seq, "pinned")] for seq in SEQUENCES)
    print(f"metrics equal in both modes: {same}")
    print(json.dumps({"quick": args.quick, "runs": runs, "rows": rows, "metrics_equal": same}))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
