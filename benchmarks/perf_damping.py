"""Seed 004's (Gu 2017, adaptive Schuler damping) 20-hour damped navigation: wall time and peak memory of the three
scenarios x three schemes.

Workload: the built-in scenarios ``paper004-accel-{0.005,0.02,0.05}`` (ship at sea, 5 Hz, seed-004 IMU,
20 h), each navigated with the ``undamped``, ``fixed`` and ``adaptive`` schemes of ``damped-nav``. The IMU
data stream through the navigator in 10-minute chunks (``fusionbench.simulation.imu.simulate_chunks``), so memory
does not grow with the duration: only the once-per-second attitude history is kept. Each scheme
regenerates its chunks (the same numbers every time: one seed). The level RMSE over the scenario's
window (one Schuler period after the manoeuvre) is printed beside the times, against truth.

``--runs N`` navigates N Monte Carlo runs together (default 1, the paper's single simulation);
``--quick`` shortens the record to 14 h (still past the manoeuvre and its window for 0.02 and 0.05).
Then, side by side, ``--batch`` runs (default 4) of the 0.05 m/s^2 adaptive navigation batched in one
call against looped one at a time. The last line printed is one JSON object with ``wall_s`` (all
nine navigations, including the IMU simulation and the acceleration map's fit; not the comparison),
``peak_rss_mb`` (the whole process) and the comparison's times.
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import numpy as np

from damping.navigator import DampedNavigator, default_map
from fusionbench.bench import scenarios
from fusionbench.scoring import metrics
from fusionbench.simulation import imu, units

SCENARIOS = ("paper004-accel-0.005", "paper004-accel-0.02", "paper004-accel-0.05")
SCHEMES = ("undamped", "fixed", "adaptive")
CHUNK_S = 600.0


def _stream(scn, traj, runs, seed, duration):
    """(IMUData, vref) chunks of the scenario: IMU increments and the reference velocity at their times."""
    for ch in imu.simulate_chunks(traj, scn.imu_spec, scn.dt, runs=runs, seed=seed, chunk_s=CHUNK_S, duration=duration):
        yield ch, imu.simulate_vref(traj, scn.vref_spec, ch.t, runs=runs, seed=seed)


def navigate(scn, scheme, runs, seed, duration):
    """One scheme over the scenario; returns (wall s, level RMSE in the window, arcmin)."""
    traj = scn.trajectory(duration)
    opts = dict(scn.variants[scheme])
    opts.pop("method")
    nav = DampedNavigator(**opts)
    init = scn.initial_guess(traj.truth([0.0]).C_bn[0])
    t0 = time.perf_counter()
    res = nav.navigate_chunks(_stream(scn, traj, runs, seed, duration), scn.site, init, dt=scn.dt, runs=runs)
    wall = time.perf_counter() - t0
    a, b = scn.feature("windows").rmse_window_s
    sel = (res.t >= a) & (res.t <= b)
    phi = metrics.misalignment_history(res.C_bn[:, sel], traj.truth(res.t[sel]).C_bn)
    return wall, float(np.sqrt(np.mean(np.sum(phi[..., :2] ** 2, axis=-1))) / units.ARCMIN)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--batch", type=int, default=4, help="runs of the batched-vs-looped comparison (0: skip)")
    args = ap.parse_args()
    duration = 14 * 3600.0 if args.quick else 20 * 3600.0
    t_all = time.perf_counter()
    t0 = time.perf_counter()
    default_map()  # fitted once (cross-validated RBF map), counted in the total
    fit_s = time.perf_counter() - t0
    print(f"seed-004 damped navigation, {duration / 3600:g} h at 5 Hz, {args.runs} run(s) per navigation, "
          f"streamed in {CHUNK_S:g} s chunks; acceleration map fitted in {fit_s:.1f} s")
    print(f"{'scenario':<22} {'scheme':<9} {'wall s':>7} {'window level RMSE arcmin':>25}")
    out = {"runs": args.runs, "duration_s": duration, "map_fit_s": round(fit_s, 2), "navigations": {}}
    for name in SCENARIOS:
        scn = scenarios.get(name)
        if scn.feature("windows").rmse_window_s[1] > duration:
            print(f"{name:<22} skipped: its window ends after {duration / 3600:g} h")
            continue
        for scheme in SCHEMES:
            wall, rmse = navigate(scn, scheme, args.runs, 0, duration)
            print(f"{name:<22} {scheme:<9} {wall:7.2f} {rmse:25.3f}")
            out["navigations"][f"{name}/{scheme}"] = {"wall_s": round(wall, 2), "window_rmse_arcmin": round(rmse, 3)}
    out["wall_s"] = round(time.perf_counter() - t_all, 2)
    out["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)
    print(f"total {out['wall_s']:.1f} s, peak RSS {out['peak_rss_mb']:.0f} MB")
    if args.batch > 1:  # side by side: the same runs batched in one navigation and looped one by one
        scn = scenarios.get(SCENARIOS[-1])
        batched, _ = navigate(scn, "adaptive", args.batch, 0, duration)
        looped = 0.0
        for k in range(args.batch):
            looped += navigate(scn, "adaptive", 1, k, duration)[0]
        print(f"{SCENARIOS[-1]} adaptive, {args.batch} runs: batched {batched:.1f} s, looped {looped:.1f} s, "
              f"ratio {looped / batched:.2f}")
        out["batch"] = {"runs": args.batch, "batched_s": round(batched, 2), "looped_s": round(looped, 2),
                        "ratio": round(looped / batched, 2)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
