"""Kalman fine alignment, batched against run by run: the filters of all runs on arrays (``engine="numpy"``)
beside one filterpy ``KalmanFilter`` per run (``engine="filterpy"``, the reference), in one process.

Workload: 20 runs x 600 s of seed 000's Table-1 sway at 34 N, navigation-grade IMU at 100 Hz, each method from
its own start (60 s of inertial-frame coarse alignment, then the 10-Hz filter). ``--quick``: 5 runs x 120 s.
Both engines must give the same attitudes (to 1e-9 rad); the figure is run-seconds of data aligned per wall
second and the ratio of the two engines. The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from baselines.kalman import AdaptiveKalmanAligner, KalmanAligner
from fusionbench import attitude, trajectory
from fusionbench.aligner import Site
from fusionbench.imu import PRESETS, simulate

LAT = np.radians(34.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    runs, duration = (5, 120.0) if args.quick else (20, 600.0)
    d = np.radians
    tr = trajectory.Trajectory(LAT, d(108.0), 450.0, trajectory.EulerSway(d([0.0, 0.0, -30.0]), d([5.0, 7.0, 9.0]),
                                                                           (0.5, 0.3, 0.2)), duration=duration)
    data = simulate(tr, PRESETS["navigation"], 0.01, runs=runs, seed=0)
    site = Site(LAT, d(108.0), 450.0)
    out = {"quick": args.quick, "runs": runs, "duration_s": duration}
    print(f"Kalman alignment, {runs} runs x {duration:g} s at 100 Hz: batched (numpy) vs run by run (filterpy)")
    print(f"{'method':<5} {'batched s':>10} {'filterpy s':>11} {'ratio':>6} {'run-s per s':>12} {'same':>6}")
    for cls in (KalmanAligner, AdaptiveKalmanAligner):
        cls(imu="navigation").align(data.select_runs([0]), site)  # warm-up: imports, numba
        t0 = time.perf_counter()
        a = cls(imu="navigation").align(data, site)
        t_batch = time.perf_counter() - t0
        t0 = time.perf_counter()
        b = cls(imu="navigation", engine="filterpy").align(data, site)
        t_loop = time.perf_counter() - t0
        same = bool(np.abs(attitude.misalignment(a.C_bn, b.C_bn)).max() < 1e-9)
        rate = runs * duration / t_batch
        print(f"{cls.name:<5} {t_batch:10.2f} {t_loop:11.2f} {t_loop / t_batch:6.2f} {rate:12.0f} {str(same):>6}")
        out.update({f"{cls.name}_batched_s": t_batch, f"{cls.name}_filterpy_s": t_loop,
                    f"{cls.name}_ratio": t_loop / t_batch, f"{cls.name}_run_s_per_s": rate, f"{cls.name}_same": same})
    print(json.dumps(out))


if __name__ == "__main__":
    main()
