"""Performance of the fusionbench core: IMU simulation, strapdown integration, long-run memory.

Run from the repository root::

    python benchmarks/perf_core.py           # full: 100 runs x 600 s x 100 Hz, 20-hour long run
    python benchmarks/perf_core.py --quick   # smoke test: 10 runs x 60 s, 2-hour long run

Three measurements, all in one invocation (see ``benchmarks/README.md``):

1. IMU generation (:func:`fusionbench.simulation.imu.simulate`), one batched call with ``runs=R`` against
   ``R`` calls with ``runs=1, first_run=k``; both must give identical arrays.
2. Strapdown (:class:`fusionbench.simulation.strapdown.Strapdown`) over the same increments: the compiled kernel
   batched (one integrator, R runs, chunks of 6000 samples) against looped (R one-run
   integrators), and its NumPy oracle (``tests/oracles/strapdown.py``) on a short slice (batched and looped).
3. Peak RSS of one long 100 Hz free-inertial run processed chunk by chunk
   (:func:`fusionbench.simulation.imu.simulate_chunks` -> ``Strapdown.run``), in a child process started
   before the parent allocates anything, so its ``ru_maxrss`` is its own.
4. pyins (``python-ins``, a test dependency) side by side, one run of the same sway: its IMU generation and
   strapdown beside fusionbench's, and the final attitudes of both strapdowns over the same increments
   (``benchmarks/_pyins_side.py``; skipped, with nulls in the JSON, when pyins is not installed).

A readable table goes to stdout, then, as the last line, one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _long_run import DT, SEED, initial_state, run_long_child  # noqa: E402 (the benchmarks' folder on the path)
from _oracle import numpy_oracles  # noqa: E402

STRAPDOWN_CHUNK = 6000  # samples per Strapdown.run call
NUMPY_SLICE = 3000  # samples integrated by the NumPy oracle (batched)
NUMPY_LOOPED_RUNS = 10  # runs integrated one by one by the NumPy oracle
NUMPY_LOOPED_SLICE = 300  # samples per run for the NumPy looped measurement


# ----------------------------------------------------------------------------------- scenarios
def sway_trajectory(duration):
    """Seed-000 (Zhou 2011, ADRC gyrocompass) sway at 34 N: pitch/roll/yaw 5/7/9 deg at 0.5/0.3/0.2 Hz, static
    translation."""
    from fusionbench.simulation import trajectory as T

    d = np.radians
    sway = T.EulerSway(mean=(0.0, 0.0, 0.0), amplitude=tuple(d([5.0, 7.0, 9.0])),
                       frequency=(0.5, 0.3, 0.2), phase=(0.0, 0.0, 0.0))
    return T.Trajectory(d(34.0), d(108.0), 0.0, attitude=sway, duration=duration)


# ----------------------------------------------------------------------------- IMU benchmark
def timed(fn, repeat=1):
    """Call ``fn`` ``repeat`` times; return (best wall time s, all times, last result).

    Best-of-n because the first touch of fresh memory can be several times slower on a virtual
    machine (the host backs guest pages lazily); the first time is reported next to the best.
    """
    times, out = [], None
    for _ in range(repeat):
        out = None  # free the previous result before the next repetition
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), times, out


def bench_imu(runs, duration, repeat):
    from fusionbench.simulation import imu

    tr = sway_trajectory(duration)
    spec = imu.PRESETS["seed000"]
    imu.simulate(sway_trajectory(1.0), spec, DT, runs=2, seed=SEED)  # warm caches/imports

    t_batched, t_all, batched = timed(lambda: imu.simulate(tr, spec, DT, runs=runs, seed=SEED), repeat)

    t_looped = 0.0
    identical = True
    for k in range(runs):
        t0 = time.perf_counter()
        one = imu.simulate(tr, spec, DT, runs=1, seed=SEED, first_run=k)
        t_looped += time.perf_counter() - t0
        identical &= bool(np.array_equal(one.gyro[0], batched.gyro[k])
                          and np.array_equal(one.accel[0], batched.accel[k])
                          and np.array_equal(one.t, batched.t))
    n = batched.samples
    # where a call spends its time: the exact increments (shared by all runs of a batch)
    t_inc, _, _ = timed(lambda: tr.increments(0.0, DT, n), repeat)
    return batched, {
        "runs": runs,
        "samples": n,
        "batched_s": t_batched,
        "batched_first_s": t_all[0],
        "looped_s": t_looped,
        "batched_per_s": runs * n / t_batched,
        "looped_per_s": runs * n / t_looped,
        "identical": identical,
        "increments_s": t_inc,
    }


# ----------------------------------------------------------------------- strapdown benchmark
def _split(g, a, chunk):
    """Contiguous (runs, chunk, 3) pieces, as :func:`fusionbench.simulation.imu.simulate_chunks` yields them
    (``Strapdown.run`` would otherwise copy each non-contiguous slice of a batch)."""
    return [(np.ascontiguousarray(g[:, k0:k0 + chunk]), np.ascontiguousarray(a[:, k0:k0 + chunk]))
            for k0 in range(0, g.shape[1], chunk)]


def _feed(sd, chunks, record_every):
    outs = [sd.run(dth, dv, record_every=record_every) for dth, dv in chunks]
    return {k: np.concatenate([o[k] for o in outs], axis=1) for k in outs[0]}


def bench_strapdown(data, duration, repeat):
    import numba

    from fusionbench.simulation import strapdown as S, strapdown_compiled as K

    tr = sway_trajectory(duration)
    g, a = data.gyro, data.accel
    runs, n, _ = g.shape
    st = initial_state(tr, runs)
    st1 = initial_state(tr, 1)
    chunk = min(STRAPDOWN_CHUNK, n)
    rec = 100
    # big enough for the threaded kernel (runs x samples >= K.PARALLEL_MIN_WORK), which the batch uses
    tiny = (np.zeros((runs, max(10, K.PARALLEL_MIN_WORK // runs + 1), 3)),) * 2
    tiny1 = (np.zeros((1, 10, 3)), np.zeros((1, 10, 3)))

    # compile time: a fresh, uncached copy of the threaded kernel (the library's own has cache=True),
    # swapped in for one call so that Strapdown.run passes it its usual arguments
    library_kernel = K._integrate_parallel
    K._integrate_parallel = numba.njit(cache=False, parallel=True)(K._integrate_kernel)
    try:
        t_compile, _, _ = timed(lambda: S.Strapdown(st, DT).run(*tiny, record_every=5))
    finally:
        K._integrate_parallel = library_kernel
    # warm-up of the library kernels (cache load if their on-disk cache is valid, else a compile):
    # the threaded one for the batch, the serial one for the one-run loop
    t_first, _, _ = timed(lambda: S.Strapdown(st, DT).run(*tiny, record_every=5))
    S.Strapdown(st1, DT).run(*tiny1, record_every=5)
    cache_hit = sum(K._integrate_parallel.stats.cache_hits.values()) > 0

    # numba batched: one integrator for all runs, fed chunk by chunk
    chunks = _split(g, a, chunk)
    t_b, tb_all, out_b = timed(lambda: _feed(S.Strapdown(st, DT), chunks, rec), repeat)
    del chunks
    # numba looped: one integrator per run, same chunks (slices of one run are contiguous already)
    t_l, tl_all, out_l = timed(lambda: [
        _feed(S.Strapdown(initial_state(tr, 1), DT), _split(g[r:r + 1], a[r:r + 1], chunk), rec)
        for r in range(runs)], repeat)
    diff_bl = max(float(np.max(np.abs(out_l[r]["C_bn"][0] - out_b["C_bn"][r]))) for r in range(runs))

    # the kernel's NumPy oracle (tests/oracles/strapdown.py), batched, on the first NUMPY_SLICE samples
    m = min(NUMPY_SLICE, n)
    head = _split(g[:, :m], a[:, :m], m)
    with numpy_oracles("strapdown"):
        t_np, _, out_np = timed(lambda: _feed(S.Strapdown(st, DT), head, rec))
    ref = _feed(S.Strapdown(st, DT), head, rec)
    diff_np = float(np.max(np.abs(out_np["C_bn"] - ref["C_bn"])))

    # the oracle looped (a few runs, a few samples: it is the slow path batching exists for)
    rl, ml = min(NUMPY_LOOPED_RUNS, runs), min(NUMPY_LOOPED_SLICE, n)
    with numpy_oracles("strapdown"):
        t_npl, _, _ = timed(lambda: [
            S.Strapdown(initial_state(tr, 1), DT).run(g[r:r + 1, :ml], a[r:r + 1, :ml], record_every=rec)
            for r in range(rl)])

    return {
        "runs": runs,
        "samples": n,
        "chunk": chunk,
        "compile_s": t_compile,
        "first_call_s": t_first,
        "cache_hit": cache_hit,
        "batched_s": t_b,
        "batched_first_s": tb_all[0],
        "looped_s": t_l,
        "looped_first_s": tl_all[0],
        "batched_per_s": runs * n / t_b,
        "looped_per_s": runs * n / t_l,
        "max_diff_batched_looped": diff_bl,
        "numpy_samples": m,
        "numpy_s": t_np,
        "numpy_per_s": runs * m / t_np,
        "max_diff_numpy_numba": diff_np,
        "numpy_looped_runs": rl,
        "numpy_looped_samples": ml,
        "numpy_looped_s": t_npl,
        "numpy_looped_per_s": rl * ml / t_npl,
    }


# ------------------------------------------------------------------------------------- report
def _fmt(x):
    return f"{x:,.0f}" if x >= 100 else f"{x:.3g}"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="10 runs x 60 s, 2-hour long run (smoke test)")
    p.add_argument("--free-vertical", action="store_true",
                   help="long run: leave the (divergent) vertical channel free instead of holding the height")
    p.add_argument("--perfect-imu", action="store_true",
                   help="long run: error-free IMU (the attitude error must then be ~0: checks the pipeline)")
    p.add_argument("--repeat", type=int, default=3, help="repetitions of the batched measurements (best kept)")
    args = p.parse_args(argv)

    runs, duration, hours = (10, 60.0, 2.0) if args.quick else (100, 600.0, 20.0)
    t_all = time.perf_counter()
    load0 = os.getloadavg()[0]
    # the long run first, while this process is still small: a child's ru_maxrss can include the
    # peak of the address space it was started from, so start it before allocating anything
    long = run_long_child(hours, args.free_vertical, args.perfect_imu)
    data, im = bench_imu(runs, duration, args.repeat)
    sd = bench_strapdown(data, duration, args.repeat)
    import _pyins_side as pys

    from fusionbench.simulation import imu

    py = None
    if pys.version():
        py = pys.bench_pyins(sway_trajectory(duration), data, imu.PRESETS["seed000"], DT, args.repeat)
    total = time.perf_counter() - t_all
    load1 = os.getloadavg()[0]

    nproc = os.cpu_count()
    print(f"fusionbench core performance  ({'quick' if args.quick else 'full'}; {nproc} CPUs; "
          f"numpy {np.__version__}; python {sys.version.split()[0]}; load average {load0:.2f} at start, "
          f"{load1:.2f} at end)")
    print(f"batched figures: best of {args.repeat} (first attempt in brackets); looped: one pass")
    print()
    print(f"1. IMU generation, seed-000 sway, preset seed000: {runs} runs x {duration:g} s x 100 Hz "
          f"= {runs * im['samples']:,} samples")
    print(f"   {'mode':<34}{'time, s':>10}{'samples/s':>16}")
    print(f"   {'batched (1 call, runs=' + str(runs) + ')':<34}{im['batched_s']:>10.2f}{_fmt(im['batched_per_s']):>16}"
          f"   [{im['batched_first_s']:.2f} s]")
    print(f"   {'looped (' + str(runs) + ' calls, runs=1)':<34}{im['looped_s']:>10.2f}{_fmt(im['looped_per_s']):>16}")
    print(f"   batched / looped: {im['batched_per_s'] / im['looped_per_s']:.1f}x;  "
          f"outputs identical (np.array_equal): {im['identical']}")
    print(f"   trajectory.increments alone for {im['samples']:,} samples: {im['increments_s']:.2f} s "
          f"(once per call, shared by the runs of a batch)")
    print()
    print(f"2. Strapdown, same increments ({runs} x {sd['samples']:,}), chunks of {sd['chunk']} samples, "
          f"record_every=100")
    print(f"   numba compile (fresh uncached copy of the kernel): {sd['compile_s']:.2f} s; library kernel "
          f"first call: {sd['first_call_s']:.2f} s ({'cache hit' if sd['cache_hit'] else 'compiled'})")
    print(f"   {'mode':<42}{'time, s':>10}{'steps/s':>16}")
    rows = [
        (f"numba batched (1 x {runs} runs)", sd["batched_s"], sd["batched_per_s"], sd["batched_first_s"]),
        (f"numba looped ({runs} x 1 run)", sd["looped_s"], sd["looped_per_s"], sd["looped_first_s"]),
        (f"numpy batched ({runs} runs x {sd['numpy_samples']} samples)", sd["numpy_s"], sd["numpy_per_s"]),
        (f"numpy looped ({sd['numpy_looped_runs']} x 1 run x {sd['numpy_looped_samples']})",
         sd["numpy_looped_s"], sd["numpy_looped_per_s"]),
    ]
    for name, t, r, *first in rows:
        print(f"   {name:<42}{t:>10.2f}{_fmt(r):>16}" + (f"   [{first[0]:.2f} s]" if first else ""))
    print(f"   numba batched / looped: {sd['batched_per_s'] / sd['looped_per_s']:.2f}x;  "
          f"numba / numpy (batched): {sd['batched_per_s'] / sd['numpy_per_s']:.1f}x;  "
          f"numpy batched / looped: {sd['numpy_per_s'] / sd['numpy_looped_per_s']:.1f}x")
    print(f"   max |C_bn| difference: batched vs looped {sd['max_diff_batched_looped']:.1e}, "
          f"numpy vs numba {sd['max_diff_numpy_numba']:.1e}")
    print()
    print(f"3. Long run in a separate process: {hours:g} h x 100 Hz = {long['samples']:,} samples, ship sway, "
          f"IMU {long['imu']}, free inertial (position_fixed=False, "
          f"{'height held: height_fixed=True' if long['height_fixed'] else 'free vertical channel'}), "
          f"record_every=10000 "
          f"({long['records']} records kept)")
    print(f"   peak RSS (ru_maxrss): {long['peak_rss_mb']:.0f} MB  (after imports and warm-up: "
          f"{long['rss_after_setup_mb']:.0f} MB; VmHWM {long['vm_hwm_mb'] or float('nan'):.0f} MB)")
    print(f"   wall time: {long['wall_s']:.1f} s  (IMU generation {long['imu_s']:.1f} s, strapdown "
          f"{long['strapdown_s']:.1f} s; imports and warm-up {long['setup_s']:.1f} s not included)")
    e = long["att_err_arcsec"]
    print(f"   final attitude error vs truth: E {e[0]:.4g}, N {e[1]:.4g}, U {e[2]:.4g} arcsec "
          f"(|phi| {long['att_err_norm_arcsec']:.4g}); velocity error "
          f"[{', '.join(f'{x:.3g}' for x in long['vel_err_mps'])}] m/s; height error {long['h_err_m']:.3g} m; "
          f"horizontal position error {long['horiz_pos_err_m'] / 1852:.3g} nmi")
    print()
    pys.report(py, im, sd, runs)
    print()
    print(f"total benchmark time: {total:.0f} s")

    result = {
        "quick": bool(args.quick),
        "cpus": nproc,
        "repeat": args.repeat,
        "loadavg_start": load0,
        "loadavg_end": load1,
        "imu_runs": runs,
        "imu_samples_per_run": im["samples"],
        "imu_batched_samples_per_s": im["batched_per_s"],
        "imu_looped_samples_per_s": im["looped_per_s"],
        "imu_batched_over_looped": im["batched_per_s"] / im["looped_per_s"],
        "imu_identical": im["identical"],
        "strapdown_batched_steps_per_s": sd["batched_per_s"],
        "strapdown_looped_steps_per_s": sd["looped_per_s"],
        "strapdown_numpy_steps_per_s": sd["numpy_per_s"],
        "strapdown_numpy_looped_steps_per_s": sd["numpy_looped_per_s"],
        "strapdown_batched_over_looped": sd["batched_per_s"] / sd["looped_per_s"],
        "numba_over_numpy": sd["batched_per_s"] / sd["numpy_per_s"],
        "numpy_batched_over_looped": sd["numpy_per_s"] / sd["numpy_looped_per_s"],
        "numba_compile_s": sd["compile_s"],
        "numba_first_call_s": sd["first_call_s"],
        "long_hours": hours,
        "peak_rss_20h_mb": long["peak_rss_mb"],
        "vm_hwm_20h_mb": long["vm_hwm_mb"],
        "wall_20h_s": long["wall_s"],
        "imu_20h_s": long["imu_s"],
        "strapdown_20h_s": long["strapdown_s"],
        "att_err_20h_arcsec": long["att_err_norm_arcsec"],
        "height_fixed_20h": long["height_fixed"],
        "imu_20h": long["imu"],
        **pys.json_fields(py, im, sd),
        "total_s": total,
    }
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
