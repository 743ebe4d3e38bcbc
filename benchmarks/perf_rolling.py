"""Seed 002's (Ding, rolling-platform self-calibration) rolling self-calibration: wall time of the platform simulation
and the 45-state EKF.

Workload: the paper's torquing scheme (``baselines.rolling.scheme.PAPER_SCHEME``: 0.1 deg/s about south
1800 s, east 900 s, south 1800 s, east 900 s; 5400 s, 2.7 M integration samples at 2 ms, an output
every 0.2 s = 27 000 filter steps) at latitude 34 deg, sea level; paper noise (the ``simulate``
defaults: 0.05 deg/h gyro white drift per 2-ms sample, 1 ug accelerometer noise per output). The true
coefficients of run r are row r of ``default_rng(2).normal(0, 0.3, (runs, 42)) * prior_sigma()[:42]``
(zero mean, 0.3 x the EKF's prior standard deviation of each coefficient); the true initial angles
are phi, theta, psi = 2, 3, 5 deg for every run. The simulator's noise seed is 0 (run r draws the r-th
child stream of ``SeedSequence(0)``, whatever the batch size). The EKF is
``baselines.rolling.ekf.RollingEKF()`` with its defaults (zero coefficients, attitude levelled from the
first second of outputs, azimuth 0; two passes), with the update engine of ``--engine`` (default
``numpy``, the filter's own default; ``filterpy``, the reference).

Measured, side by side in one invocation:

1. simulating ONE full run (``simulate(..., runs=1)``, the serial numba kernel);
2. the EKF on that run (one ``calibrate`` call: two passes of 27 000 predict + update steps of the
   45-state filter), and its causal first pass alone (``passes=1``);
3. simulating N runs batched in one call (the numba kernel threads over runs) against N calls of one
   run each (looped; call k uses noise seed k, so only its run 0 matches the batch: it is checked);
4. the Monte Carlo over all cores: the EKF on the N batched runs serially (one process) against
   joblib ``Parallel(n_jobs=-1)``, one run per task (loky worker processes); the two must give the
   same estimate and sigma histories (checked bit for bit; the largest difference is printed too).

Both numba kernels are warmed up (compiled or loaded from the cache) on a short scheme before any
timing. The estimation error of run 0 (from 2) is printed per coefficient group in customary units
(largest |final - true| in the group, next to the largest filter sigma at the end), then the three
angle errors at the end in arcsec. The target reported against (not asserted): one run, simulation +
EKF, under 60 s on a 2-core machine.

``--quick``: the paper's segments scaled to 1/6 of their durations, rounded to whole 1-s command
periods (300, 150, 300, 150 s: 900 s, 4 500 filter steps), and N = 2. ``--runs N`` overrides N.

The last line printed is one JSON object with the figures (seconds; ``peak_rss_mb`` is this process's
``ru_maxrss``, not the joblib workers').
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time

import numpy as np
from joblib import Parallel, delayed

from baselines.rolling import angles, model
from baselines.rolling.ekf import ENGINES, RollingEKF
from baselines.rolling.priors import prior_sigma
from baselines.rolling.scheme import PAPER_SCHEME, Scheme, Segment
from baselines.rolling.simulator import simulate
from fusionbench.simulation import units

LAT = np.radians(34.0)
ANGLES0 = np.radians([2.0, 3.0, 5.0])
COEFF_SEED = 2  # true coefficients
NOISE_SEED = 0  # simulator noise
TARGET_S = 60.0
GROUPS = ("D0", "D1", "D2", "GYRO_MOUNT", "K0", "K1", "K2", "ACCEL_MOUNT", "KT")


def quick_scheme(base=PAPER_SCHEME, factor=6):
    """``base`` with every segment 1/factor as long, rounded to whole command periods (at least one)."""
    T = base.command_period_s
    segs = tuple(Segment(s.axis, s.rate, max(1, round(s.duration / factor / T)) * T) for s in base.segments)
    return Scheme(segs, command_period_s=T, sample_s=base.sample_s, filter_s=base.filter_s)


def true_coeffs(runs):
    rng = np.random.default_rng(COEFF_SEED)
    return rng.normal(0.0, 0.3, (runs, model.N_COEFFS)) * prior_sigma()[:model.N_COEFFS]


def ekf_run(t, y, w_cmd, engine="numpy"):
    """The EKF on one run; returns (x history, sigma history, wall s)."""
    t0 = time.perf_counter()
    res = RollingEKF(engine=engine).calibrate(t, y, w_cmd, LAT)
    return res.x, res.sigma, time.perf_counter() - t0


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--runs", type=int, default=None, help="N of benchmarks 3 and 4 (default 4, --quick 2)")
    ap.add_argument("--engine", choices=ENGINES, default="numpy", help="the EKF's update engine (default numpy)")
    args = ap.parse_args()
    scheme = quick_scheme() if args.quick else PAPER_SCHEME
    runs = args.runs or (2 if args.quick else 4)
    if runs < 1:
        ap.error("--runs: expected a positive integer")
    cores = os.cpu_count() or 1
    coeffs = true_coeffs(runs)
    C0 = angles.angles_to_dcm(ANGLES0)
    print(f"seed-002 rolling self-calibration at 34 N: {scheme.duration:g} s scheme "
          f"({', '.join(f'{s.duration:g}' for s in scheme.segments)} s segments), {scheme.n_samples:,} samples "
          f"at {scheme.sample_s * 1e3:g} ms, {scheme.n_outputs:,} filter steps; N = {runs} runs, {cores} cores; "
          f"EKF engine {args.engine}")

    # warm-up: both numba kernels (serial for runs=1, parallel for runs>1) compiled or loaded from cache
    t0 = time.perf_counter()
    warm = Scheme(((Segment((0.0, -1.0, 0.0), 0.1 * units.DEG, 2.0)),))
    simulate(warm, coeffs[0], C0, LAT, seed=NOISE_SEED, runs=1)
    simulate(warm, coeffs[:2] if runs > 1 else np.stack([coeffs[0]] * 2), C0, LAT, seed=NOISE_SEED, runs=2)
    RollingEKF(engine=args.engine).calibrate(np.arange(1, 11) * scheme.filter_s, np.tile([0.0, 9.8, 0.0], (10, 1)),
                                             np.zeros((10, 3)), LAT)
    warm_s = time.perf_counter() - t0

    # 1. one run simulated
    t0 = time.perf_counter()
    one = simulate(scheme, coeffs[0], C0, LAT, seed=NOISE_SEED, runs=1)
    sim_one = time.perf_counter() - t0

    # 2. the EKF on that run (two passes, the default), and its causal first pass alone
    x0, s0, ekf_one = ekf_run(one.t, one.y[0], one.w_cmd[0], args.engine)
    per_step_ms = 1e3 * ekf_one / one.t.size / 2
    t0 = time.perf_counter()
    RollingEKF(passes=1, engine=args.engine).calibrate(one.t, one.y[0], one.w_cmd[0], LAT)
    ekf_first = time.perf_counter() - t0

    # 3. N runs simulated: batched in one call against looped one by one
    t0 = time.perf_counter()
    batch = simulate(scheme, coeffs, C0, LAT, seed=NOISE_SEED, runs=runs)
    sim_batched = time.perf_counter() - t0
    t0 = time.perf_counter()
    looped_y0 = None
    for k in range(runs):
        r = simulate(scheme, coeffs[k], C0, LAT, seed=NOISE_SEED + k, runs=1)
        if k == 0:
            looped_y0 = r.y[0]
        del r
    sim_looped = time.perf_counter() - t0
    sim_same = bool(np.array_equal(batch.y[0], one.y[0]) and np.array_equal(looped_y0, one.y[0]))

    # 4. the EKF on the N runs: serial against joblib over all cores, one run per task
    t0 = time.perf_counter()
    serial = [ekf_run(batch.t, batch.y[k], batch.w_cmd[k], args.engine) for k in range(runs)]
    ekf_serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    par = Parallel(n_jobs=-1)(delayed(ekf_run)(batch.t, batch.y[k], batch.w_cmd[k], args.engine) for k in range(runs))
    ekf_parallel = time.perf_counter() - t0
    ekf_same = all(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) for a, b in zip(serial, par))
    ekf_maxdiff = max(float(np.max(np.abs(a[0] - b[0]) / b[1])) for a, b in zip(serial, par))  # in sigmas
    ekf_same_as_one = bool(np.array_equal(serial[0][0], x0))

    total = sim_one + ekf_one
    print(f"warm-up (numba kernels from cache or compiled, filterpy import): {warm_s:.1f} s")
    print(f"{'benchmark':<44} {'wall s':>8}  notes")
    print(f"{'1 simulate one run':<44} {sim_one:8.2f}  compiled loop {one.wall_s:.2f} s, "
          f"{scheme.n_samples / sim_one / 1e6:.2f} M samples/s")
    print(f"{'2 EKF on that run (2 passes)':<44} {ekf_one:8.2f}  2 x {one.t.size:,} steps, {per_step_ms:.3f} ms/step")
    print(f"{'  EKF first (causal) pass alone':<44} {ekf_first:8.2f}  passes=1")
    print(f"{'  one run total (1 + 2)':<44} {total:8.2f}  target < {TARGET_S:g} s: "
          f"{'met' if total < TARGET_S else 'NOT met'}")
    print(f"{f'3 simulate {runs} runs batched (one call)':<44} {sim_batched:8.2f}  compiled loop {batch.wall_s:.2f} s")
    print(f"{f'  simulate {runs} runs looped ({runs} calls)':<44} {sim_looped:8.2f}  looped / batched "
          f"{sim_looped / sim_batched:.2f}; run 0 identical in all three: {sim_same}")
    print(f"{f'4 EKF on {runs} runs, serial':<44} {ekf_serial:8.2f}  "
          f"per run {', '.join(f'{s[2]:.1f}' for s in serial)} s; run 0 same as benchmark 2: {ekf_same_as_one}")
    print(f"{f'  EKF on {runs} runs, joblib n_jobs=-1':<44} {ekf_parallel:8.2f}  serial / parallel "
          f"{ekf_serial / ekf_parallel:.2f}; per run {', '.join(f'{p[2]:.1f}' for p in par)} s; "
          f"identical: {ekf_same} (max diff {ekf_maxdiff:.2g} sigma)")

    # estimation error of run 0 (benchmark 2's filter), customary units
    sel = one.t >= one.t[-1] - 100.0  # CalibrationResult.final(): coefficients averaged over the last 100 s
    res_final = x0[sel].mean(axis=0)
    res_final[model.ANGLES] = x0[-1, model.ANGLES]
    err = model.to_customary(res_final[:model.N_COEFFS] - one.coeffs[0])
    sig = model.to_customary(s0[-1, :model.N_COEFFS])
    tru = model.to_customary(one.coeffs[0])
    print(f"run 0 estimation error after {scheme.duration:g} s (coefficients: mean of the last 100 s)")
    print(f"{'group':<12} {'unit':<10} {'max |err|':>10} {'max sigma':>10} {'max |true|':>10} {'max |err|/sigma':>16}")
    groups = {}
    for name in GROUPS:
        sl = getattr(model, name)
        e, s = np.abs(err[sl]), sig[sl]
        groups[name] = {"max_abs_err": float(e.max()), "max_sigma": float(s.max())}
        print(f"{name:<12} {model.COEFF_CUSTOMARY_UNITS[sl.start]:<10} {e.max():10.4g} {s.max():10.4g} "
              f"{np.abs(tru[sl]).max():10.4g} {np.max(e / s):16.2f}")
    a_err = wrap(res_final[model.ANGLES] - one.states[0, -1, model.ANGLES]) / units.ARCSEC
    a_sig = s0[-1, model.ANGLES] / units.ARCSEC
    print("angles at the end, arcsec: " + ", ".join(f"{n} {e:+.2f} (sigma {s:.2f})"
                                                   for n, e, s in zip(("phi", "theta", "psi"), a_err, a_sig)))

    out = {
        "quick": args.quick, "engine": args.engine, "runs": runs, "cores": cores, "scheme_s": scheme.duration,
        "filter_steps": int(scheme.n_outputs), "warmup_s": round(warm_s, 2),
        "sim_one_run_s": round(sim_one, 3), "ekf_one_run_s": round(ekf_one, 3), "one_run_total_s": round(total, 3),
        "ekf_ms_per_step": round(per_step_ms, 4), "ekf_first_pass_s": round(ekf_first, 3), "target_one_run_s": TARGET_S, "target_met": bool(total < TARGET_S),
        "sim_batched_s": round(sim_batched, 3), "sim_looped_s": round(sim_looped, 3),
        "sim_looped_over_batched": round(sim_looped / sim_batched, 2), "sim_run0_identical": sim_same,
        "ekf_serial_s": round(ekf_serial, 3), "ekf_parallel_s": round(ekf_parallel, 3),
        "ekf_serial_over_parallel": round(ekf_serial / ekf_parallel, 2), "ekf_identical": ekf_same,
        "ekf_max_diff_sigma": ekf_maxdiff, "run0_errors_customary": groups,
        "run0_angle_err_arcsec": [round(float(v), 3) for v in a_err],
        "run0_angle_sigma_arcsec": [round(float(v), 3) for v in a_sig],
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
