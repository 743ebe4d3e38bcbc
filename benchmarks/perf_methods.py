"""Monte Carlo throughput of every registered alignment method beside the bare cost of its data, in one process.

Run from the repository root::

    python benchmarks/perf_methods.py           # full: 20 runs x 600 s at 100 Hz (7.5 min on 2 idle cores)
    python benchmarks/perf_methods.py --quick   # 5 runs x 120 s (about 30 s)
    python benchmarks/perf_methods.py --numpy-oracles --methods adrc pid   # the compiled loops' NumPy oracles

Workload: seed 000's (Zhou 2011, ADRC gyrocompass) Table-1 sway at 34 N (pitch/roll/yaw 5/7/9 deg at 0.5/0.3/0.2 Hz
about a -30 deg yaw, as ``perf_kalman.py``), navigation-grade IMU (preset ``navigation``), 100 Hz, ``simulate(...,
seed=0)``. A method whose ``supports(cls).bases`` do not include "sway" (``coarse``, the ``gtsam`` family) gets the same
trajectory with a zero sway amplitude ("static"); a paper variant that claims no base (``bases=()``) runs on the sway it
was published for. Navigators that need an initial attitude (``supports(cls).needs_init``: ``damped-nav``) are
skipped.

Figures (wall times in s, measured with ``time.perf_counter``):

* floor: ``imu.simulate`` of the runs plus one batched ``Strapdown`` (numba, ``position_fixed=True``, from the
  true initial attitude) over them: generating and integrating the data, the cost no aligner can beat;
  given for each base (sway, static); each of the two timings is the best of ``--repeat`` (3), while a
  method's is one call, so "x floor" errs against the method (if anything, too high).
* per method: ``align(data, site)`` on the whole batch after a warm-up call on a short one-run slice (imports,
  numba compile or cache load not counted); throughput = runs x duration / wall, in run-seconds of data
  aligned per wall second; x floor = the method's wall / the floor's wall for its base (1 would mean the
  method costs as much as producing its input; the issue's target is <= 10 for every aligner but gtsam);
  looped/batched = the wall of ``align(data.select_runs([k]))`` for k = 0..R-1, one after the other, over
  the batched wall (how much the batching saves). The looped pass is done for every method at ``--quick``
  and, at full size, only where the batched call took under ``--loop-limit`` s (20 by default).

``--numpy-oracles`` runs the methods whose loop is compiled (``coarse-i0``, ``adrc``, ``adrc-paper``, ``pid``,
``eso-td``, ``eso-td-paper``, and the graphs' rotation loop in ``gtsam``, ``gtsam-robust``, ``gtsam-adaptive``) with
the NumPy oracle of that loop (``tests/oracles/``: the operation-for-operation
reference the tests hold the kernel to) in its place, so two invocations compare the compiled loop with the NumPy
loop it replaced; the others run as registered (``oracle`` is recorded per method: null where none was used).

A table goes to stdout, then, as the last line, one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time

import numpy as np

from fusionbench.methods import aligner, claims
from fusionbench.methods.aligner import Site
from fusionbench.simulation import trajectory
from fusionbench.simulation.imu import PRESETS, simulate
from fusionbench.simulation.strapdown import NavState, Strapdown

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _oracle import numpy_oracles, oracle_users  # noqa: E402 (the benchmarks' folder on the path)

LAT, LON, H = np.radians(34.0), np.radians(108.0), 450.0
DT = 0.01
TARGET = 10.0  # the target: throughput within 10x of the floor


def make_trajectory(base, duration):
    """Seed 000's Table-1 sway (``base="sway"``) or the same attitude held still (``"static"``)."""
    d = np.radians
    amp = d([5.0, 7.0, 9.0]) if base == "sway" else np.zeros(3)
    return trajectory.Trajectory(LAT, LON, H, trajectory.EulerSway(d([0.0, 0.0, -30.0]), amp, (0.5, 0.3, 0.2)),
                                 duration=duration)


def floor(tr, runs, repeat=1):
    """(IMUData, simulate wall s, strapdown wall s): the data and the cost of generating and integrating it, each
    time the best of ``repeat`` (the same seed: the same data every time)."""
    t_sim, t_sd = [], []
    tru = tr.truth([0.0])  # increments: the initial state is at t[0] - dt = 0
    for _ in range(repeat):
        data = None
        t0 = time.perf_counter()
        data = simulate(tr, PRESETS["navigation"], DT, runs=runs, seed=0)
        t_sim.append(time.perf_counter() - t0)
        state = NavState.broadcast(runs, tru.C_bn[0], tru.v_n[0], tru.lat[0], tru.lon[0], tru.h[0])
        t0 = time.perf_counter()
        Strapdown(state, DT, position_fixed=True).run(data.gyro, data.accel, record_every=100)
        t_sd.append(time.perf_counter() - t0)
    return data, min(t_sim), min(t_sd)


def base_for(sup):
    """The base a method is measured on: sway if it claims it (or claims nothing: a paper's variant), else static."""
    if not sup.bases or "sway" in sup.bases:
        return "sway"
    return "static" if "static" in sup.bases else None


#: The oracles of the methods' compiled loops (``tests/oracles/<name>.py``); the strapdown's is perf_core.py's.
METHOD_ORACLES = ("coarse", "adrc_gyrocompass", "pid_gyrocompass", "eso_td", "graph_rotations")


def oracle_for(cls):
    """The name of the NumPy oracle that stands in for ``cls``'s compiled loop (its module, or one it derives from, runs
    the kernel the oracle replaces), else None."""
    modules = {c.__module__ for c in cls.__mro__}
    return next((n for n in METHOD_ORACLES if modules & set(oracle_users(n))), None)


def timed_align(method, data, site):
    t0 = time.perf_counter()
    method.align(data, site)
    return time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="5 runs x 120 s (smoke test)")
    ap.add_argument("--loop-limit", type=float, default=20.0,
                    help="at full size, run the looped pass only for methods whose batched call took under this, s")
    ap.add_argument("--repeat", type=int, default=3, help="repetitions of the floor's two timings (best kept)")
    ap.add_argument("--methods", nargs="*", help="only these registered methods (default: all)")
    ap.add_argument("--numpy-oracles", action="store_true",
                    help="run the methods whose loop is compiled with its NumPy oracle (tests/oracles/) instead")
    args = ap.parse_args(argv)
    runs, duration = (5, 120.0) if args.quick else (20, 600.0)
    run_s = runs * duration
    load0 = os.getloadavg()[0]
    t_all = time.perf_counter()
    site = Site(LAT, LON, H)

    # warm-up of the simulator and of the threaded and serial strapdown kernels, then the floors
    warm = make_trajectory("sway", 2.0)
    floor(warm, 1), floor(warm, runs)
    Strapdown(NavState.broadcast(runs, np.eye(3), lat=LAT, h=H), DT, position_fixed=True).run(
        np.zeros((runs, 20000 // runs + 1, 3)), np.zeros((runs, 20000 // runs + 1, 3)), record_every=100)
    # 2 runs x 200 s (a coarse stage plus min_duration_s; >= 20 000 samples: the threaded strapdown) per base
    warmups = {b: simulate(make_trajectory(b, 200.0), PRESETS["navigation"], DT, runs=2, seed=1)
               for b in ("sway", "static")}
    datas, floors = {}, {}
    for base in ("sway", "static"):
        data, t_sim, t_sd = floor(make_trajectory(base, duration), runs, args.repeat)
        datas[base] = data
        floors[base] = {"simulate_s": t_sim, "strapdown_s": t_sd, "floor_s": t_sim + t_sd,
                        "run_s_per_s": run_s / (t_sim + t_sd)}

    out = {"quick": bool(args.quick), "runs": runs, "duration_s": duration, "rate_hz": 1 / DT, "cpus": os.cpu_count(),
           "loop_limit_s": None if args.quick else args.loop_limit,
           "floor_repeat": args.repeat, "target_x_floor": TARGET, "floor": floors, "numpy_oracles": args.numpy_oracles,
           "methods": {}, "skipped": {}}
    names = args.methods or sorted(aligner.available_methods())
    for name in names:
        cls = aligner.entry_class(aligner.METHODS_GROUP, name)
        sup = claims.supports(cls)
        base = base_for(sup)
        if sup.needs_init or base is None:
            out["skipped"][name] = "needs an initial attitude (navigator)" if sup.needs_init else "claims no base here"
            continue
        data = datas[base]
        oracle = oracle_for(cls) if args.numpy_oracles else None
        with numpy_oracles(oracle) if oracle else contextlib.nullcontext():
            warm = warmups[base]  # imports, numba compile or cache load: batched (2 runs, threaded) and one run
            aligner.load_method(name, imu="navigation").align(warm, site)
            aligner.load_method(name, imu="navigation").align(warm.select_runs([0]), site)
            try:
                t_b = timed_align(aligner.load_method(name, imu="navigation"), data, site)
            except ValueError as exc:  # a method's refusal (e.g. too short a record at --quick): said, not fatal
                out["skipped"][name] = f"refused: {exc}"
                continue
            rec = {"base": base, "bases_claimed": list(sup.bases), "oracle": oracle, "batched_s": t_b,
                   "run_s_per_s": run_s / t_b,
                   "x_floor": t_b / floors[base]["floor_s"], "looped_s": None, "looped_over_batched": None}
            if args.quick or t_b < args.loop_limit:
                t_l = sum(timed_align(aligner.load_method(name, imu="navigation"), data.select_runs([k]), site)
                          for k in range(runs))
                rec.update(looped_s=t_l, looped_over_batched=t_l / t_b)
        rec["within_target"] = rec["x_floor"] <= TARGET
        out["methods"][name] = rec
        print(f"  {name}: {t_b:.2f} s", file=sys.stderr, flush=True)
    out["total_s"] = time.perf_counter() - t_all
    out["loadavg_start"], out["loadavg_end"] = load0, os.getloadavg()[0]

    print(f"Method throughput, {runs} runs x {duration:g} s at 100 Hz, navigation IMU, 34 N "
          f"({os.cpu_count()} CPUs; load average {load0:.2f} at start, {out['loadavg_end']:.2f} at end)"
          + ("; NumPy oracles in place of the compiled loops" if args.numpy_oracles else ""))
    print(f"{'floor':<15} {'base':<6} {'simulate s':>10} {'strapdown s':>11} {'floor s':>8} {'run-s per s':>12}")
    for base, f in floors.items():
        print(f"{'':<15} {base:<6} {f['simulate_s']:10.2f} {f['strapdown_s']:11.2f} {f['floor_s']:8.2f} "
              f"{f['run_s_per_s']:12.0f}")
    print(f"{'method':<15} {'base':<6} {'batched s':>10} {'run-s per s':>11} {'x floor':>8} {'looped s':>10} "
          f"{'looped/batched':>14}")
    for name, r in out["methods"].items():
        loop = (f"{r['looped_s']:10.2f} {r['looped_over_batched']:14.2f}" if r["looped_s"] is not None
                else f"{'-':>10} {'-':>14}")
        flag = "" if r["within_target"] else f"  > {TARGET:g}x floor"
        print(f"{name:<15} {r['base']:<6} {r['batched_s']:10.2f} {r['run_s_per_s']:11.0f} {r['x_floor']:8.2f} "
              f"{loop}{flag}")
    for name, why in out["skipped"].items():
        print(f"{name:<15} skipped: {why}")
    looped = ", ".join(n for n, r in out["methods"].items() if r["looped_s"] is not None) or "none"
    print("looped pass: every method" if args.quick else
          f"looped pass only where the batched call took under {args.loop_limit:g} s: {looped}")
    beyond = {n: round(r["x_floor"], 2) for n, r in out["methods"].items() if not r["within_target"]}
    out["beyond_target"] = beyond
    print(f"beyond {TARGET:g}x the floor: {beyond or 'none'}; total {out['total_s']:.0f} s")
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
