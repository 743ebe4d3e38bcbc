"""Performance of the fusionbench core: IMU simulation, strapdown integration, long-run memory.

Run from the repository root::

    python benchmarks/perf_core.py           # full: 100 runs x 600 s x 100 Hz, 20-hour long run
    python benchmarks/perf_core.py --quick   # smoke test: 10 runs x 60 s, 2-hour long run

Three measurements, all in one invocation (see ``benchmarks/README.md``):

1. IMU generation (:func:`fusionbench.imu.simulate`), one batched call with ``runs=R`` against
   ``R`` calls with ``runs=1, first_run=k``; both must give identical arrays.
2. Strapdown (:class:`fusionbench.strapdown.Strapdown`) over the same increments: numba engine
   batched (one integrator, R runs, chunks of 6000 samples) against looped (R one-run
   integrators), and the NumPy reference engine on a short slice (batched and looped).
3. Peak RSS of one long 100 Hz free-inertial run processed chunk by chunk
   (:func:`fusionbench.imu.simulate_chunks` -> ``Strapdown.run``), in a child process started
   before the parent allocates anything, so its ``ru_maxrss`` is its own.

A readable table goes to stdout, then, as the last line, one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

DT = 0.01  # 100 Hz
SEED = 0
STRAPDOWN_CHUNK = 6000  # samples per Strapdown.run call
NUMPY_SLICE = 3000  # samples integrated by the NumPy reference engine (batched)
NUMPY_LOOPED_RUNS = 10  # runs integrated one by one by the NumPy engine
NUMPY_LOOPED_SLICE = 300  # samples per run for the NumPy looped measurement
ARCSEC = np.pi / 180 / 3600


# ----------------------------------------------------------------------------------- scenarios
def sway_trajectory(duration):
    """Seed-000 sway at 34 N: pitch/roll/yaw 5/7/9 deg at 0.5/0.3/0.2 Hz, static translation."""
    from fusionbench import trajectory as T

    d = np.radians
    sway = T.EulerSway(mean=(0.0, 0.0, 0.0), amplitude=tuple(d([5.0, 7.0, 9.0])),
                       frequency=(0.5, 0.3, 0.2), phase=(0.0, 0.0, 0.0))
    return T.Trajectory(d(34.0), d(108.0), 0.0, attitude=sway, duration=duration)


def ship_trajectory(duration):
    """Ship-like sway (pitch 1.2 deg at 1/7 Hz, roll 1.2 deg at 1/8 Hz, yaw 0.8 deg at 1/11 Hz),
    static for 60 % of ``duration`` (12 h of 20 h), then east at 0.05 m/s^2 up to 20 m/s."""
    from fusionbench import trajectory as T

    d = np.radians
    sway = T.EulerSway(mean=(0.0, 0.0, 0.0), amplitude=tuple(d([1.2, 1.2, 0.8])),
                       frequency=(1 / 7, 1 / 8, 1 / 11), phase=(0.0, 0.0, 0.0))
    move = T.Translation(segments=(T.accelerate_to(20.0, 0.05, (1.0, 0.0, 0.0)),), start=0.6 * duration)
    return T.Trajectory(d(34.0), d(108.0), 0.0, attitude=sway, translation=move, duration=duration)


def initial_state(tr, runs):
    from fusionbench.strapdown import NavState

    tru = tr.truth([0.0])  # increments: the initial state belongs to t[0] - dt = 0
    return NavState.broadcast(runs, tru.C_bn[0], tru.v_n[0], tru.lat[0], tru.lon[0], tru.h[0])


# ------------------------------------------------------------------------------ long-run child
def _vm_hwm_mb():
    """Peak RSS of the current address space (VmHWM), MB; None where /proc is unavailable."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def long_child(hours, free_vertical=False):
    """Body of the child process: one run of ``hours`` h at 100 Hz, chunk by chunk."""
    t_start = time.perf_counter()
    from fusionbench import attitude, imu
    from fusionbench.strapdown import Strapdown

    duration = hours * 3600.0
    tr = ship_trajectory(duration)
    spec = imu.PRESETS["seed004"]
    state = initial_state(tr, 1)
    # warm-up (JIT compile or cache load) so that the wall time is the processing alone
    Strapdown(state, DT).run(np.zeros((1, 10, 3)), np.zeros((1, 10, 3)), record_every=5)
    rss_ready = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    setup_s = time.perf_counter() - t_start

    # The free vertical channel diverges (time constant sqrt(R / 2g), ~9.5 min): over hours the
    # height runs away and drags velocity and attitude with it, so a ship at sea level holds its
    # height where the library offers it (``height_fixed``); horizontal channels stay free.
    hold = "height_fixed" in inspect.signature(Strapdown).parameters and not free_vertical
    sd = Strapdown(state, DT, position_fixed=False, **({"height_fixed": True} if hold else {}))
    hist = {"C_bn": [], "v_n": [], "lat": [], "lon": [], "h": []}
    t_imu = t_sd = 0.0
    samples = 0
    t0 = time.perf_counter()
    gen = imu.simulate_chunks(tr, spec, DT, runs=1, seed=SEED, chunk_s=600.0)
    while True:
        a = time.perf_counter()
        chunk = next(gen, None)
        b = time.perf_counter()
        t_imu += b - a
        if chunk is None:
            break
        out = sd.run(chunk.gyro, chunk.accel, record_every=10000)
        t_sd += time.perf_counter() - b
        samples += chunk.samples
        for k in hist:
            hist[k].append(out[k])
        t_end = float(chunk.t[-1])
    wall = time.perf_counter() - t0
    hist = {k: np.concatenate(v, axis=1) for k, v in hist.items()}

    truth = tr.truth([t_end])
    phi = attitude.misalignment(sd.state.C_bn[0], truth.C_bn[0])
    rm_h = 6371e3
    pos_err = np.hypot((sd.state.lat[0] - truth.lat[0]) * rm_h,
                       (sd.state.lon[0] - truth.lon[0]) * rm_h * np.cos(truth.lat[0]))
    return {
        "hours": hours,
        "height_fixed": hold,
        "samples": samples,
        "records": int(hist["C_bn"].shape[1]),
        "wall_s": wall,
        "imu_s": t_imu,
        "strapdown_s": t_sd,
        "setup_s": setup_s,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "rss_after_setup_mb": rss_ready,
        "vm_hwm_mb": _vm_hwm_mb(),
        "att_err_arcsec": (phi / ARCSEC).tolist(),
        "att_err_norm_arcsec": float(np.linalg.norm(phi) / ARCSEC),
        "vel_err_mps": (sd.state.v_n[0] - truth.v_n[0]).tolist(),
        "h_err_m": float(sd.state.h[0] - truth.h[0]),
        "horiz_pos_err_m": float(pos_err),
        "finite": bool(np.all(np.isfinite(sd.state.C_bn)) and np.all(np.isfinite(sd.state.v_n))),
    }


def run_long_child(hours, free_vertical=False):
    """Start this script as a child for the long run and return its JSON result."""
    cmd = [sys.executable, os.path.abspath(__file__), "--_long-child", repr(hours)]
    if free_vertical:
        cmd.append("--free-vertical")
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"long-run child failed ({proc.returncode}):\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- IMU benchmark
def bench_imu(runs, duration):
    from fusionbench import imu

    tr = sway_trajectory(duration)
    spec = imu.PRESETS["seed000"]
    imu.simulate(sway_trajectory(1.0), spec, DT, runs=2, seed=SEED)  # warm caches/imports

    t0 = time.perf_counter()
    batched = imu.simulate(tr, spec, DT, runs=runs, seed=SEED)
    t_batched = time.perf_counter() - t0

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
    # where a batched call spends its time: the shared exact increments vs the per-run errors
    t0 = time.perf_counter()
    tr.increments(0.0, DT, min(n, 60000))
    t_inc = (time.perf_counter() - t0) * n / min(n, 60000)
    return batched, {
        "runs": runs,
        "samples": n,
        "batched_s": t_batched,
        "looped_s": t_looped,
        "batched_per_s": runs * n / t_batched,
        "looped_per_s": runs * n / t_looped,
        "identical": identical,
        "increments_s": t_inc,
    }


# ----------------------------------------------------------------------- strapdown benchmark
def _feed(sd, g, a, chunk, record_every):
    outs = []
    for k0 in range(0, g.shape[1], chunk):
        outs.append(sd.run(g[:, k0:k0 + chunk], a[:, k0:k0 + chunk], record_every=record_every))
    return {k: np.concatenate([o[k] for o in outs], axis=1) for k in outs[0]}


def bench_strapdown(data, duration):
    import numba

    from fusionbench import strapdown as S

    tr = sway_trajectory(duration)
    g, a = data.gyro, data.accel
    runs, n, _ = g.shape
    st = initial_state(tr, runs)
    st1 = initial_state(tr, 1)
    chunk = min(STRAPDOWN_CHUNK, n)
    rec = 100

    # compile time: a fresh, uncached copy of the kernel (the library's own has cache=True),
    # swapped in for one tiny call so that Strapdown.run passes it its usual arguments
    library_kernel = S._integrate_numba
    S._integrate_numba = numba.njit(cache=False)(library_kernel.py_func)
    try:
        t0 = time.perf_counter()
        S.Strapdown(st1, DT).run(np.zeros((1, 10, 3)), np.zeros((1, 10, 3)), record_every=5)
        t_compile = time.perf_counter() - t0
    finally:
        S._integrate_numba = library_kernel
    # warm-up of the library kernel (cache load if its on-disk cache is valid, else a compile)
    t0 = time.perf_counter()
    S.Strapdown(st1, DT).run(np.zeros((1, 10, 3)), np.zeros((1, 10, 3)), record_every=5)
    t_first = time.perf_counter() - t0
    stats = S._integrate_numba.stats
    cache_hit = sum(stats.cache_hits.values()) > 0

    # numba batched
    t0 = time.perf_counter()
    out_b = _feed(S.Strapdown(st, DT, engine="numba"), g, a, chunk, rec)
    t_b = time.perf_counter() - t0

    # numba looped: one integrator per run, same chunks
    t0 = time.perf_counter()
    out_l = [_feed(S.Strapdown(initial_state(tr, 1), DT, engine="numba"), g[r:r + 1], a[r:r + 1], chunk, rec)
             for r in range(runs)]
    t_l = time.perf_counter() - t0
    diff_bl = max(float(np.max(np.abs(out_l[r]["C_bn"][0] - out_b["C_bn"][r]))) for r in range(runs))

    # NumPy reference engine, batched, on the first NUMPY_SLICE samples
    m = min(NUMPY_SLICE, n)
    t0 = time.perf_counter()
    out_np = _feed(S.Strapdown(st, DT, engine="numpy"), g[:, :m], a[:, :m], m, rec)
    t_np = time.perf_counter() - t0
    ref = _feed(S.Strapdown(st, DT, engine="numba"), g[:, :m], a[:, :m], m, rec)
    diff_np = float(np.max(np.abs(out_np["C_bn"] - ref["C_bn"])))

    # NumPy engine looped (a few runs, a few samples: it is the slow path batching exists for)
    rl, ml = min(NUMPY_LOOPED_RUNS, runs), min(NUMPY_LOOPED_SLICE, n)
    t0 = time.perf_counter()
    for r in range(rl):
        S.Strapdown(initial_state(tr, 1), DT, engine="numpy").run(g[r:r + 1, :ml], a[r:r + 1, :ml], record_every=rec)
    t_npl = time.perf_counter() - t0

    return {
        "runs": runs,
        "samples": n,
        "chunk": chunk,
        "compile_s": t_compile,
        "first_call_s": t_first,
        "cache_hit": cache_hit,
        "batched_s": t_b,
        "looped_s": t_l,
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
    p.add_argument("--_long-child", dest="long_child", type=float, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)

    if args.long_child is not None:
        print(json.dumps(long_child(args.long_child, args.free_vertical)))
        return 0

    runs, duration, hours = (10, 60.0, 2.0) if args.quick else (100, 600.0, 20.0)
    t_all = time.perf_counter()
    # the long run first, while this process is still small: a child's ru_maxrss can include the
    # peak of the address space it was started from, so start it before allocating anything
    long = run_long_child(hours, args.free_vertical)
    data, im = bench_imu(runs, duration)
    sd = bench_strapdown(data, duration)
    total = time.perf_counter() - t_all

    nproc = os.cpu_count()
    print(f"fusionbench core performance  ({'quick' if args.quick else 'full'}; {nproc} CPUs; "
          f"numpy {np.__version__}; python {sys.version.split()[0]})")
    print()
    print(f"1. IMU generation, seed-000 sway, preset seed000: {runs} runs x {duration:g} s x 100 Hz "
          f"= {runs * im['samples']:,} samples")
    print(f"   {'mode':<34}{'time, s':>10}{'samples/s':>16}")
    print(f"   {'batched (1 call, runs=' + str(runs) + ')':<34}{im['batched_s']:>10.2f}{_fmt(im['batched_per_s']):>16}")
    print(f"   {'looped (' + str(runs) + ' calls, runs=1)':<34}{im['looped_s']:>10.2f}{_fmt(im['looped_per_s']):>16}")
    print(f"   batched / looped: {im['batched_per_s'] / im['looped_per_s']:.1f}x;  "
          f"outputs identical (np.array_equal): {im['identical']}")
    print(f"   trajectory.increments alone for {im['samples']:,} samples: {im['increments_s']:.2f} s "
          f"(computed once per chunk per call)")
    print()
    print(f"2. Strapdown, same increments ({runs} x {sd['samples']:,}), chunks of {sd['chunk']} samples, "
          f"record_every=100")
    print(f"   numba compile (fresh uncached copy of the kernel): {sd['compile_s']:.2f} s; library kernel "
          f"first call: {sd['first_call_s']:.2f} s ({'cache hit' if sd['cache_hit'] else 'compiled'})")
    print(f"   {'mode':<42}{'time, s':>10}{'steps/s':>16}")
    rows = [
        (f"numba batched (1 x {runs} runs)", sd["batched_s"], sd["batched_per_s"]),
        (f"numba looped ({runs} x 1 run)", sd["looped_s"], sd["looped_per_s"]),
        (f"numpy batched ({runs} runs x {sd['numpy_samples']} samples)", sd["numpy_s"], sd["numpy_per_s"]),
        (f"numpy looped ({sd['numpy_looped_runs']} x 1 run x {sd['numpy_looped_samples']})",
         sd["numpy_looped_s"], sd["numpy_looped_per_s"]),
    ]
    for name, t, r in rows:
        print(f"   {name:<42}{t:>10.2f}{_fmt(r):>16}")
    print(f"   numba batched / looped: {sd['batched_per_s'] / sd['looped_per_s']:.2f}x;  "
          f"numba / numpy (batched): {sd['batched_per_s'] / sd['numpy_per_s']:.1f}x;  "
          f"numpy batched / looped: {sd['numpy_per_s'] / sd['numpy_looped_per_s']:.1f}x")
    print(f"   max |C_bn| difference: batched vs looped {sd['max_diff_batched_looped']:.1e}, "
          f"numpy vs numba {sd['max_diff_numpy_numba']:.1e}")
    print()
    print(f"3. Long run in a separate process: {hours:g} h x 100 Hz = {long['samples']:,} samples, ship sway, "
          f"preset seed004, free inertial (position_fixed=False, "
          f"{'height held: height_fixed=True' if long['height_fixed'] else 'free vertical channel'}), "
          f"record_every=10000 "
          f"({long['records']} records kept)")
    print(f"   peak RSS (ru_maxrss): {long['peak_rss_mb']:.0f} MB  (after imports and warm-up: "
          f"{long['rss_after_setup_mb']:.0f} MB; VmHWM {long['vm_hwm_mb'] or float('nan'):.0f} MB)")
    print(f"   wall time: {long['wall_s']:.1f} s  (IMU generation {long['imu_s']:.1f} s, strapdown "
          f"{long['strapdown_s']:.1f} s; imports and warm-up {long['setup_s']:.1f} s not included)")
    e = long["att_err_arcsec"]
    print(f"   final attitude error vs truth: E {e[0]:.1f}, N {e[1]:.1f}, U {e[2]:.1f} arcsec "
          f"(|phi| {long['att_err_norm_arcsec']:.1f}); velocity error "
          f"{np.round(long['vel_err_mps'], 2).tolist()} m/s; height error {long['h_err_m']:.3g} m; "
          f"horizontal position error {long['horiz_pos_err_m'] / 1852:.3g} nmi")
    print()
    print(f"total benchmark time: {total:.0f} s")

    result = {
        "quick": bool(args.quick),
        "cpus": nproc,
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
        "total_s": total,
    }
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
