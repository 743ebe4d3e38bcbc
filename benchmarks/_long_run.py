"""The long free-inertial run of ``perf_core.py`` (its measurement 3), in a process of its own: one run of a ship's
sway at 100 Hz for hours, IMU generated and integrated chunk by chunk
(:func:`fusionbench.simulation.imu.simulate_chunks` -> ``Strapdown.run``), its wall time, peak RSS and final errors.
``perf_core.py`` starts it (:func:`run_long_child`) before it allocates anything, so that the child's ``ru_maxrss`` is
its own::

    python benchmarks/_long_run.py HOURS [--free-vertical] [--perfect-imu]   # prints one JSON line
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
ARCSEC = np.pi / 180 / 3600


def ship_trajectory(duration):
    """Ship-like sway (pitch 1.2 deg at 1/7 Hz, roll 1.2 deg at 1/8 Hz, yaw 0.8 deg at 1/11 Hz),
    static for 60 % of ``duration`` (12 h of 20 h), then east at 0.05 m/s^2 up to 20 m/s."""
    from fusionbench.simulation import trajectory as T
    from fusionbench.simulation.translation import Translation, accelerate_to

    d = np.radians
    sway = T.EulerSway(mean=(0.0, 0.0, 0.0), amplitude=tuple(d([1.2, 1.2, 0.8])),
                       frequency=(1 / 7, 1 / 8, 1 / 11), phase=(0.0, 0.0, 0.0))
    move = Translation(segments=(accelerate_to(20.0, 0.05, (1.0, 0.0, 0.0)),), start=0.6 * duration)
    return T.Trajectory(d(34.0), d(108.0), 0.0, attitude=sway, translation=move, duration=duration)


def initial_state(tr, runs):
    from fusionbench.simulation.strapdown import NavState

    tru = tr.truth([0.0])  # increments: the initial state belongs to t[0] - dt = 0
    return NavState.broadcast(runs, tru.C_bn[0], tru.v_n[0], tru.lat[0], tru.lon[0], tru.h[0])


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


def long_child(hours, free_vertical=False, perfect=False):
    """Body of the child process: one run of ``hours`` h at 100 Hz, chunk by chunk."""
    t_start = time.perf_counter()
    from fusionbench.simulation import attitude, imu
    from fusionbench.simulation.strapdown import Strapdown

    duration = hours * 3600.0
    tr = ship_trajectory(duration)
    spec = imu.PRESETS["seed004"].perfect() if perfect else imu.PRESETS["seed004"]
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
    finite = bool(np.all(np.isfinite(sd.state.C_bn)) and np.all(np.isfinite(sd.state.v_n)))
    # a free vertical channel can overflow over many hours: report NaN rather than fail
    phi = attitude.misalignment(sd.state.C_bn[0], truth.C_bn[0]) if finite else np.full(3, np.nan)
    rm_h = 6371e3
    pos_err = np.hypot((sd.state.lat[0] - truth.lat[0]) * rm_h,
                       (sd.state.lon[0] - truth.lon[0]) * rm_h * np.cos(truth.lat[0]))
    return {
        "hours": hours,
        "height_fixed": hold,
        "imu": spec.name,
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
        "finite": finite,
    }


def run_long_child(hours, free_vertical=False, perfect=False):
    """Start this script as a child for the long run and return its JSON result (:func:`long_child`)."""
    cmd = [sys.executable, os.path.abspath(__file__), repr(hours)]
    if free_vertical:
        cmd.append("--free-vertical")
    if perfect:
        cmd.append("--perfect-imu")
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"long-run child failed ({proc.returncode}):\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("hours", type=float, help="duration of the run, h")
    p.add_argument("--free-vertical", action="store_true", help="leave the (divergent) vertical channel free")
    p.add_argument("--perfect-imu", action="store_true", help="an error-free IMU (the attitude error must be ~0)")
    args = p.parse_args(argv)
    print(json.dumps(long_child(args.hours, args.free_vertical, args.perfect_imu)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
