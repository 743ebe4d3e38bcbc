"""Performance of the gyrocompass aligners: batched over the Monte Carlo axis against looped run by run.

Run from the repository root::

    python benchmarks/perf_gyrocompass.py             # full: 100 runs x 600 s x 100 Hz, looped over 10 runs
    python benchmarks/perf_gyrocompass.py --quick     # smoke test: 10 runs x 120 s, looped over 3 runs
    python benchmarks/perf_gyrocompass.py --profile   # also: cProfile of one batched and one one-run call
    python benchmarks/perf_gyrocompass.py --threads 1 # strapdown kernel on one numba thread
    python benchmarks/perf_gyrocompass.py --numpy-oracles --profile   # the NumPy loops the kernels replaced

The gyrocompass aligners, :class:`adrc.gyrocompass.ADRCGyrocompass` (``adrc``, control period 0.1 s, 10 Hz),
its printed-parameter variant :class:`adrc.gyrocompass.ADRCPaper` (``adrc-paper``, 0.02 s, 50 Hz) and
:class:`baselines.gyrocompass.PIDGyrocompass` (``pid``, 0.1 s, 10 Hz), on seed 000's (Zhou 2011, ADRC gyrocompass) data
(see ``benchmarks/README.md``, section *Gyrocompass benchmark*):

* **batched**: one ``align`` call with all R runs;
* **looped**: the same work one run at a time, ``align(imu.select_runs([k]), site, vref[k:k+1],
  init[k:k+1])``, over the first L runs (L < R to bound the time; rates are per run, so they compare).

Figures: control steps/s = runs x control steps / elapsed and IMU samples/s = runs x IMU samples /
elapsed, batched and looped, and their ratio. The looped runs' final attitudes are compared with the
batched ones for the same runs (they must agree to ~1e-12). Numba compile (or cache load) is excluded:
each aligner is warmed up on a short slice first.

A readable table goes to stdout, then, as the last line, one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import json
import os
import pstats
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _oracle import numpy_oracles  # noqa: E402 (the benchmarks' folder on the path)

DT = 0.01  # 100 Hz
SEED = 0
LAT_DEG, LON_DEG, H_M = 34.0, 108.0, 0.0
INIT_DEG = (3.0, 3.0, 180.0)  # Euler platform error angles [ax, ay, az] of the initial guess
VREF_SIGMA = 0.05  # m/s, white, each axis
WARMUP_S = 90.0  # longer than either aligner's minimum duration (ADRC 50 s, PID 80 s)
TARGET_RATIO = 20.0
ARCMIN = np.pi / 180 / 60


# ----------------------------------------------------------------------------------- workload
def sway_trajectory(duration):
    """Seed-000 sway at 34 N: pitch/roll/yaw 5/7/9 deg at 0.5/0.3/0.2 Hz, static translation."""
    from fusionbench.simulation import trajectory as T

    d = np.radians
    sway = T.EulerSway(mean=(0.0, 0.0, 0.0), amplitude=tuple(d([5.0, 7.0, 9.0])),
                       frequency=(0.5, 0.3, 0.2), phase=(0.0, 0.0, 0.0))
    return T.Trajectory(d(LAT_DEG), d(LON_DEG), H_M, attitude=sway, duration=duration)


def workload(runs, duration):
    """IMU data (R runs), velocity reference (R, N, 3), initial guesses (R, 3, 3), site, trajectory."""
    from fusionbench.methods.aligner import Site
    from fusionbench.simulation import attitude, imu

    tr = sway_trajectory(duration)
    data = imu.simulate(tr, imu.PRESETS["seed000"], DT, runs=runs, seed=SEED)
    vref = imu.simulate_vref(tr, imu.VelocityReferenceSpec((VREF_SIGMA,) * 3), data.t, runs=runs, seed=SEED)
    C_true0 = tr.truth([0.0]).C_bn[0]  # the initial state of increment data belongs to t[0] - dt = 0
    init = np.broadcast_to(attitude.euler_platform_to_dcm(np.radians(INIT_DEG)) @ C_true0, (runs, 3, 3)).copy()
    site = Site(np.radians(LAT_DEG), np.radians(LON_DEG), H_M)
    return tr, data, vref, init, site


def aligners():
    from adrc.gyrocompass import ADRCGyrocompass, ADRCPaper
    from baselines.gyrocompass import PIDGyrocompass

    return {"adrc": ADRCGyrocompass(), "adrc-paper": ADRCPaper(), "pid": PIDGyrocompass()}


def control_period(aligner):
    return aligner.step_s


def head(data, vref, init, runs, samples):
    """The first ``runs`` runs and ``samples`` samples of the workload (for warm-up and profiling)."""
    from fusionbench.simulation.imudata import IMUData

    return (IMUData(data.t[:samples], data.gyro[:runs, :samples], data.accel[:runs, :samples], data.kind),
            vref[:runs, :samples], init[:runs])


# ---------------------------------------------------------------------------------- benchmark
def bench_method(aligner, tr, data, vref, init, site, looped_runs, repeat=1):
    """Batched (one call, all runs) against looped (``looped_runs`` calls of one run)."""
    from fusionbench.simulation import attitude

    R, n = data.runs, data.samples
    m = max(1, int(round(control_period(aligner) / data.dt)))
    steps = n // m

    # warm-up: strapdown kernel (numba cache load or compile), imports, first LAPACK calls
    w = int(round(WARMUP_S / DT))
    t0 = time.perf_counter()
    for r in (2, 1):
        d, v, c = head(data, vref, init, r, w)
        aligner.align(d, site, vref=v, init=c)
    warm_s = time.perf_counter() - t0

    # batched: best of ``repeat`` (the first touch of the fresh history arrays is slow on a VM)
    times = []
    for _ in range(repeat):
        res_b = None  # free the previous result first
        c0, t0 = time.process_time(), time.perf_counter()
        res_b = aligner.align(data, site, vref=vref, init=init)
        times.append((time.perf_counter() - t0, time.process_time() - c0))
    t_b, cpu_b = min(times)
    assert res_b.t[-1] == data.t[-1], (res_b.t[-1], data.t[-1])  # the time rule: ends at the last sample

    L = min(looped_runs, R)
    t_l = cpu_l = 0.0
    diff_final = diff_hist = 0.0
    for k in range(L):
        one = data.select_runs([k])
        c0, t0 = time.process_time(), time.perf_counter()
        res = aligner.align(one, site, vref=vref[k:k + 1], init=init[k:k + 1])
        t_l += time.perf_counter() - t0
        cpu_l += time.process_time() - c0
        diff_final = max(diff_final, float(np.max(np.abs(res.C_bn_final[0] - res_b.C_bn_final[k]))))
        diff_hist = max(diff_hist, float(np.max(np.abs(res.C_bn[0] - res_b.C_bn[k]))))
        del res

    # sanity: final attitude error of the batch against the truth (arcmin), [E, N, U]
    phi = attitude.misalignment(res_b.C_bn_final, tr.truth([res_b.t_end]).C_bn[0])
    del res_b
    return {
        "runs": R,
        "looped_runs": L,
        "samples": n,
        "samples_per_step": m,
        "period_s": m * data.dt,
        "steps": steps,
        "warmup_s": warm_s,
        "batched_s": t_b,
        "batched_cpu_s": cpu_b,
        "batched_first_s": times[0][0],
        "repeat": repeat,
        "looped_s": t_l,
        "looped_cpu_s": cpu_l,
        "looped_s_per_run": t_l / L,
        "batched_steps_per_s": R * steps / t_b,
        "looped_steps_per_s": L * steps / t_l,
        "batched_samples_per_s": R * n / t_b,
        "looped_samples_per_s": L * n / t_l,
        "batched_us_per_step": t_b / steps * 1e6,
        "looped_us_per_step": t_l / (L * steps) * 1e6,
        "max_diff_final": diff_final,
        "max_diff_history": diff_hist,
        "final_err_mean_arcmin": (phi.mean(axis=0) / ARCMIN).tolist(),
        "final_err_rms_arcmin": (np.sqrt((phi ** 2).mean(axis=0)) / ARCMIN).tolist(),
    }


# ------------------------------------------------------------------------------------ profile
# The parts of a control step, as (label, file, function); "update" is told apart by its class.
# A part's time is its inclusive cProfile time (NumPy ufuncs run inside the calling function, so
# they count where they are written) minus that of the other parts it calls.
_PARTS = [
    ("fhan (TD and NLSEF)", "primitives.py", "fhan"),
    ("ESO update (incl. fal)", "primitives.py", "update@ExtendedStateObserver"),
    ("ESO update (incl. fal)", "primitives.py", "fal"),
    ("TD update (excl. fhan)", "primitives.py", "update@TrackingDifferentiator"),
    ("NLSEF (excl. fhan)", "primitives.py", "nlsef"),
    ("strapdown kernel (_integrate_numba)", "strapdown_compiled.py", "_integrate_numba"),
    ("Strapdown.run wrapper (checks, copies)", "strapdown.py", "run"),
    ("CommandLoop step (slicing, vref mean)", "compass.py", "__iter__"),
    ("AzimuthFit.add", "compass.py", "add"),
    ("AzimuthFit.azimuth (6x6 solve, 10 Hz)", "compass.py", "azimuth"),
    ("correct_azimuth", "compass.py", "correct_azimuth"),
    ("PID gain formulas (every step)", "gyrocompass.py", "level_gains"),
    ("PID gain formulas (every step)", "gyrocompass.py", "compass_gains"),
    ("PID gain formulas (every step)", "gyrocompass.py", "sigma_of"),
    ("align itself: setup and the attitude from the histories", "gyrocompass.py", "align"),
    ("the NumPy loop body (np.stack, history)", "adrc_gyrocompass.py", "run_numpy"),
    ("the NumPy loop body (np.stack, history)", "pid_gyrocompass.py", "run_numpy"),
    ("PID loop step (the oracle's PIDLoops.step)", "pid_gyrocompass.py", "step"),
]


def profile_call(fn, steps):
    """Run ``fn`` under cProfile; time per control step (us) of each part of :data:`_PARTS`.

    cProfile adds a fixed cost to every Python-level call, so parts made of many small calls
    (the ADRC primitives) look heavier than they are; the total is printed next to the unprofiled
    figure of the benchmark.
    """
    import inspect

    from adrc import primitives

    update_class = {inspect.getsourcelines(c.update)[1]: c.__name__
                    for c in (primitives.TrackingDifferentiator, primitives.ExtendedStateObserver)}

    def part(key):
        file, line, func = key
        base = os.path.basename(file)
        if func == "update" and base == "primitives.py":
            func = f"update@{update_class.get(line, '?')}"
        for label, f, name in _PARTS:
            if base == f and func == name:
                return label
        return None

    t0 = time.perf_counter()
    fn()
    plain = time.perf_counter() - t0
    pr = cProfile.Profile()
    t0 = time.perf_counter()
    pr.runcall(fn)
    wall = time.perf_counter() - t0
    stats = pstats.Stats(pr).stats
    total = sum(v[2] for v in stats.values())
    parts = {}
    for key, (cc, nc, tt, ct, callers) in stats.items():
        lab = part(key)
        if lab is None:
            continue
        parts[lab] = parts.get(lab, 0.0) + ct
        for caller, edge in callers.items():  # take this part's time out of the part calling it
            lab_c = part(caller)
            if lab_c is not None:
                parts[lab_c] = parts.get(lab_c, 0.0) - edge[3]
    rows = sorted(((lab, v / steps * 1e6) for lab, v in parts.items()), key=lambda x: -x[1])
    return {"wall_s": wall, "plain_s": plain, "plain_us_per_step": plain / steps * 1e6, "profiled_total_s": total,
            "us_per_step": total / steps * 1e6, "groups": rows}


def run_profiles(meths, data, vref, init, site, seconds, runs):
    n = int(round(seconds / DT))
    out = {}
    for name, al in meths.items():
        m = max(1, int(round(control_period(al) / DT)))
        steps = n // m
        d_b = head(data, vref, init, runs, n)
        d_1 = head(data, vref, init, 1, n)
        out[name] = {
            "seconds": seconds,
            "batched_runs": runs,
            "batched": profile_call(lambda: al.align(d_b[0], site, vref=d_b[1], init=d_b[2]), steps),
            "looped": profile_call(lambda: al.align(d_1[0], site, vref=d_1[1], init=d_1[2]), steps),
        }
    return out


# ------------------------------------------------------------------------------------- report
def _fmt(x):
    return f"{x:,.0f}" if x >= 100 else f"{x:.3g}"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="10 runs x 120 s, looped over 3 runs (smoke test)")
    p.add_argument("--looped-runs", type=int, default=None, help="runs aligned one by one (default 10; quick 3)")
    p.add_argument("--profile", action="store_true",
                   help="also profile (cProfile) one batched and one one-run call per method and print where "
                        "the time of a control step goes")
    p.add_argument("--repeat", type=int, default=3, help="repetitions of the batched call (best kept; default 3)")
    p.add_argument("--numpy-oracles", action="store_true",
                   help="run the control loops' NumPy oracles (tests/oracles/, the loops the compiled kernels "
                        "replaced; the profile's breakdown describes them) instead of the kernels")
    p.add_argument("--threads", type=int, default=None,
                   help="numba threads for the strapdown kernel (numba.set_num_threads; default: numba's, the core count)")
    args = p.parse_args(argv)
    import numba

    if args.threads is not None:
        numba.set_num_threads(args.threads)

    runs, duration, looped = (10, 120.0, 3) if args.quick else (100, 600.0, 10)
    if args.looped_runs is not None:
        looped = max(1, args.looped_runs)
    t_all = time.perf_counter()
    load0 = os.getloadavg()[0]

    t0 = time.perf_counter()
    tr, data, vref, init, site = workload(runs, duration)
    t_data = time.perf_counter() - t0
    meths = aligners()
    with numpy_oracles("adrc_gyrocompass", "pid_gyrocompass") if args.numpy_oracles else contextlib.nullcontext():
        res = {name: bench_method(al, tr, data, vref, init, site, looped, max(1, args.repeat))
               for name, al in meths.items()}
        prof = None
        if args.profile:
            prof = run_profiles(meths, data, vref, init, site, 90.0 if args.quick else 120.0, runs)
    total = time.perf_counter() - t_all
    load1 = os.getloadavg()[0]
    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel region has run
        layer = "?"

    nproc = os.cpu_count()
    print(f"gyrocompass aligners, batched vs looped  ({'quick' if args.quick else 'full'}; {nproc} CPUs; "
          f"numpy {np.__version__}; numba {numba.__version__} ({numba.get_num_threads()} threads, {layer} layer); "
          f"python {sys.version.split()[0]}{'; NumPy oracles of the loops' if args.numpy_oracles else ''}; load average {load0:.2f} at start, {load1:.2f} at end)")
    print(f"workload: seed-000 sway at {LAT_DEG:g} N (pitch/roll/yaw 5/7/9 deg at 0.5/0.3/0.2 Hz), preset seed000, "
          f"{1 / DT:g} Hz, {runs} runs x {duration:g} s ({data.samples:,} samples); vref white {VREF_SIGMA} m/s; "
          f"init Euler platform angles {list(INIT_DEG)} deg; IMU + vref generation {t_data:.1f} s (not timed below)")
    print(f"batched: one align call with all runs, best of {max(1, args.repeat)} (first attempt in brackets); looped: "
          f"align(imu.select_runs([k]), ...) one run at a time over the first {looped} runs, one pass (rates are per run)")
    print()
    hdr = f"   {'mode':<34}{'time, s':>9}{'CPU, s':>9}{'ctrl steps/s':>15}{'IMU samples/s':>16}{'us/step':>10}"
    for name, r in res.items():
        print(f"{name}: control period {r['period_s']:g} s ({r['samples_per_step']} samples), "
              f"{r['steps']:,} control steps per run; warm-up {r['warmup_s']:.1f} s (excluded)")
        print(hdr)
        print(f"   {'batched (1 call x %d runs)' % r['runs']:<34}{r['batched_s']:>9.2f}{r['batched_cpu_s']:>9.2f}"
              f"{_fmt(r['batched_steps_per_s']):>15}{_fmt(r['batched_samples_per_s']):>16}"
              f"{r['batched_us_per_step']:>10.1f}   [first {r['batched_first_s']:.2f} s]")
        print(f"   {'looped (%d calls x 1 run)' % r['looped_runs']:<34}{r['looped_s']:>9.2f}{r['looped_cpu_s']:>9.2f}"
              f"{_fmt(r['looped_steps_per_s']):>15}{_fmt(r['looped_samples_per_s']):>16}"
              f"{r['looped_us_per_step']:>10.1f}")
        ratio = r["batched_steps_per_s"] / r["looped_steps_per_s"]
        bound = f"; a batch of {r['runs']} runs cannot reach it" if r["runs"] < TARGET_RATIO else ""
        print(f"   batched / looped: {ratio:.1f}x (target >= {TARGET_RATIO:g}x: {'met' if ratio >= TARGET_RATIO else 'NOT met'}"
              f"{bound}); "
              f"looped {r['looped_s_per_run']:.2f} s per run, i.e. {r['runs']} runs would take "
              f"{r['looped_s_per_run'] * r['runs']:.0f} s")
        print(f"   batched vs looped, same runs: max |C_bn| difference, final {r['max_diff_final']:.1e}, whole history "
              f"{r['max_diff_history']:.1e} ({'agree' if r['max_diff_final'] < 1e-10 else 'DIFFER'})")
        e, s = r["final_err_mean_arcmin"], r["final_err_rms_arcmin"]
        print(f"   final attitude error vs truth (sanity), arcmin: mean E {e[0]:.3g}, N {e[1]:.3g}, U {e[2]:.3g}; "
              f"rms E {s[0]:.3g}, N {s[1]:.3g}, U {s[2]:.3g}")
        print()
    if prof:
        for name, pr in prof.items():
            print(f"profile {name} ({pr['seconds']:g} s of data; cProfile, so small functions are inflated): "
                  f"time per control step, us")
            b, l = pr["batched"], pr["looped"]
            print(f"   {'part':<55}{'batched (%d runs)' % pr['batched_runs']:>20}{'one run':>12}")
            labels = [lab for lab, _ in l["groups"]] + [lab for lab, _ in b["groups"] if lab not in dict(l["groups"])]
            db, dl = dict(b["groups"]), dict(l["groups"])
            for lab in labels:  # parts called once (the PID's correct_azimuth) are left out
                if max(db.get(lab, 0.0), dl.get(lab, 0.0)) >= 0.05:
                    print(f"   {lab:<55}{db.get(lab, 0.0):>20.1f}{dl.get(lab, 0.0):>12.1f}")
            print(f"   {'total under cProfile':<55}{b['us_per_step']:>20.1f}{l['us_per_step']:>12.1f}")
            print(f"   {'same call without cProfile (wall)':<55}{b['plain_us_per_step']:>20.1f}"
                  f"{l['plain_us_per_step']:>12.1f}")
            print()
    print(f"total benchmark time: {total:.0f} s")

    result = {
        "quick": bool(args.quick),
        "cpus": nproc,
        "runs": runs,
        "duration_s": duration,
        "looped_runs": looped,
        "repeat": max(1, args.repeat),
        "loadavg_start": load0,
        "loadavg_end": load1,
        "numba_threads": numba.get_num_threads(),
        "numba_threading_layer": layer,
        "target_ratio": TARGET_RATIO,
    }
    for name, r in res.items():
        ratio = r["batched_steps_per_s"] / r["looped_steps_per_s"]
        result.update({
            f"{name}_ratio": ratio,
            f"{name}_target_met": bool(ratio >= TARGET_RATIO),
            f"{name}_batched_steps_per_s": r["batched_steps_per_s"],
            f"{name}_looped_steps_per_s": r["looped_steps_per_s"],
            f"{name}_batched_samples_per_s": r["batched_samples_per_s"],
            f"{name}_looped_samples_per_s": r["looped_samples_per_s"],
            f"{name}_batched_s": r["batched_s"],
            f"{name}_batched_first_s": r["batched_first_s"],
            f"{name}_looped_s": r["looped_s"],
            f"{name}_control_steps_per_run": r["steps"],
            f"{name}_max_diff_final": r["max_diff_final"],
            f"{name}_max_diff_history": r["max_diff_history"],
        })
    if prof:
        for name, pr in prof.items():
            result[f"{name}_profile_us_per_step_batched"] = pr["batched"]["us_per_step"]
            result[f"{name}_profile_us_per_step_looped"] = pr["looped"]["us_per_step"]
            result[f"{name}_profile_parts_us_per_step_batched"] = dict(pr["batched"]["groups"])
            result[f"{name}_profile_parts_us_per_step_looped"] = dict(pr["looped"]["groups"])
    result["total_s"] = total
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
