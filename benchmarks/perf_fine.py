"""Fine-alignment Monte Carlo wall time: kf, gtsam and eso-td, serial against joblib over all cores.

Workload: 100 runs x 600 s of a stationary IMU at 34 N (seed-000 (Zhou 2011, ADRC gyrocompass) sensor, 100 Hz),
zero-velocity reference with 0.01 m/s noise, initial guess 20', 20', 40' off (seed 001's (Zhao 2007, ESO/TD alignment)).
Serial: one process aligns all runs (each method's own batching). Parallel: the runs split into one chunk per core,
aligned by joblib workers (loky processes); run k's numbers do not depend on the split, which the
script checks. ``--quick``: 10 runs x 120 s.

The last line printed is one JSON object with the wall times and ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from joblib import Parallel, delayed

from fusionbench.methods.aligner import Site, load_method
from fusionbench.simulation import attitude, trajectory, units
from fusionbench.simulation.imu import PRESETS, VelocityReferenceSpec, simulate, simulate_vref

METHODS = ("kf", "gtsam", "eso-td")
LAT = np.radians(34.0)
PSI0 = np.radians([20 / 60, 20 / 60, 40 / 60])


def workload(runs, duration):
    tr = trajectory.Trajectory(LAT, np.radians(108.0), 450.0, trajectory.EulerSway(mean=np.radians([1.0, -2.0, -123.0])),
                               duration=duration)
    data = simulate(tr, PRESETS["seed000"], 0.01, runs=runs, seed=0)
    vref = simulate_vref(tr, VelocityReferenceSpec((0.01,) * 3), data.t, runs=runs, seed=0)
    init = attitude.euler_platform_to_dcm(PSI0) @ tr.truth([0.0]).C_bn[0]
    return tr, data, vref, init


def align_chunk(name, data, vref, init):
    res = load_method(name).align(data, Site(LAT, np.radians(108.0), 450.0), vref=vref, init=init)
    return res.C_bn_final


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    runs, duration = (10, 120.0) if args.quick else (100, 600.0)
    jobs = os.cpu_count() or 1
    tr, data, vref, init = workload(runs, duration)
    C_true = tr.truth([duration]).C_bn[0]
    chunks = np.array_split(np.arange(runs), jobs)
    print(f"fine alignment, {runs} runs x {duration:g} s at 100 Hz, {jobs} cores; serial vs joblib ({jobs} workers)")
    print(f"{'method':<8} {'serial s':>9} {'parallel s':>11} {'ratio':>6} {'same numbers':>13} {'rms U arcmin':>13}")
    out = {"quick": args.quick, "runs": runs, "duration_s": duration, "cores": jobs}
    for name in METHODS:
        align_chunk(name, data.select_runs([0]), vref[:1], init)  # warm-up (compile, imports)
        t0 = time.perf_counter()
        serial = align_chunk(name, data, vref, init)
        t_serial = time.perf_counter() - t0
        t0 = time.perf_counter()
        parts = Parallel(n_jobs=jobs)(delayed(align_chunk)(name, data.select_runs(c), vref[c], init) for c in chunks)
        t_par = time.perf_counter() - t0
        par = np.concatenate(parts)
        same = bool(np.max(np.abs(par - serial)) < 1e-9)
        rms_u = float(np.sqrt(np.mean((attitude.misalignment(serial, C_true)[:, 2] / units.ARCMIN) ** 2)))
        print(f"{name:<8} {t_serial:9.2f} {t_par:11.2f} {t_serial / t_par:6.2f} {str(same):>13} {rms_u:13.2f}")
        out[f"{name}_serial_s"] = t_serial
        out[f"{name}_parallel_s"] = t_par
        out[f"{name}_ratio"] = t_serial / t_par
        out[f"{name}_same_numbers"] = same
    print(json.dumps(out))


if __name__ == "__main__":
    main()
