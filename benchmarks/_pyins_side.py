"""pyins (PyPI ``python-ins``) side by side with fusionbench in ``perf_core.py``: the same trajectory, one run.

pyins works in NED with FRD body axes and roll-pitch-heading angles, fusionbench in ENU with RFU body axes; as in
``tests/independent.py``, ``P = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]`` maps both ways: ``C_bn = P C_nb_pyins P``,
``v_RFU = P v_FRD``, ``v_ENU = P v_NED``; pyins roll and pitch are fusionbench's, its heading is ``-yaw``
(``tests/test_layouts.py::_c_bn_from_pyins``).

* generation: ``pyins.sim.generate_imu(time, lla, rph, velocity_n, sensor_type="increment")`` through the angle
  series of the benchmark's sway at the sample times (built beforehand, not timed: pyins cannot generate an
  Euler sway itself), then ``pyins.inertial_sensor.apply_imu_parameters`` with the seed000 preset's errors
  (bias, white noise, scale factor: the errors ``fusionbench.simulation.imu.simulate`` adds), one run;
* strapdown: ``pyins.strapdown.compute_increments_from_imu(imu, "increment")`` (coning and sculling) and
  ``pyins.strapdown.Integrator(pva).integrate`` over fusionbench's own increments of run 0, a zero "before"
  sample prepended (fusionbench's first step also has no previous sample);
* agreement: the final attitude of both integrators over those increments (height held in both: pyins
  ``with_altitude=False``, fusionbench ``height_fixed=True``; and free, both vertical channels diverging with
  their own gravity models), and pyins's perfect increments through pyins's strapdown against fusionbench's truth.

pyins's numba kernel is compiled at its first call (``cache`` is off in pyins): timed apart as a warm-up.
"""

from __future__ import annotations

import time

import numpy as np

P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
ARCSEC = np.pi / 180 / 3600
G_COLS, A_COLS = ["gyro_x", "gyro_y", "gyro_z"], ["accel_x", "accel_y", "accel_z"]


def version():
    """pyins's version, or None when it is not installed."""
    from importlib import metadata

    try:
        import pyins  # noqa: F401
    except ImportError:
        return None
    try:
        return metadata.version("python-ins")
    except metadata.PackageNotFoundError:  # importable, but not installed as a distribution
        return "unknown"


def _best(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        out = None
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def _pyins_params(errors, rng):
    """pyins ``Parameters`` of one fusionbench ``SensorErrors`` (bias, white, scale; FRD axes)."""
    from pyins import inertial_sensor

    scale = P @ np.diag(1.0 + np.asarray(errors.scale)) @ P
    return inertial_sensor.Parameters(transform=scale, bias=P @ np.asarray(errors.bias),
                                      noise=P @ np.asarray(errors.white), rng=rng)


def _imu_frame(dtheta, dvel, dt):
    """pyins increment-IMU DataFrame of RFU increments (n, 3), with a zero "before" row at t = 0."""
    import pandas as pd

    n = len(dtheta)
    body = np.vstack([np.zeros((1, 6)), np.hstack([dtheta @ P, dvel @ P])])
    return pd.DataFrame(body, index=pd.Index(np.arange(n + 1) * dt, name="time"), columns=G_COLS + A_COLS)


def _pyins_strapdown(imu, pva, with_altitude=True):
    """pyins's strapdown over an increment IMU DataFrame; its final C_bn in fusionbench's frames."""
    from pyins import strapdown

    inc = strapdown.compute_increments_from_imu(imu, "increment")
    integ = strapdown.Integrator(pva, with_altitude=with_altitude)
    integ.integrate(inc)
    return P @ integ.mat_nb[len(inc)] @ P


def bench_pyins(tr, data, spec, dt, repeat, seed=0):
    """pyins's generation and strapdown on trajectory ``tr`` (one run), beside fusionbench's run 0 of ``data``."""
    import pandas as pd
    from pyins import inertial_sensor, sim, strapdown, transform

    from fusionbench.simulation import attitude
    from fusionbench.simulation.strapdown import NavState, Strapdown

    t_start = time.perf_counter()
    n = data.samples
    t = np.arange(n + 1) * dt  # pyins: n + 1 points, increments over (t[k-1], t[k]]; row 0 repeats row 1
    tru = tr.truth(t)
    e, _ = tr.attitude.euler(t)  # [pitch, roll, yaw], rad
    rph = np.degrees(np.column_stack([e[:, 1], e[:, 0], -e[:, 2]]))
    rph_check = float(np.abs(P @ transform.mat_from_rph(rph) @ P - tru.C_bn).max())
    lla = np.column_stack([np.degrees(tru.lat), np.degrees(tru.lon), tru.h])
    vel = tru.v_n @ P
    pva = pd.Series(np.hstack([lla[0], vel[0], rph[0]]),
                    index=["lat", "lon", "alt", "VN", "VE", "VD", "roll", "pitch", "heading"])

    # warm-up: pyins's numba kernel compiles at its first call (not cached), pandas/scipy paths
    w = 201
    t0 = time.perf_counter()
    _, warm = sim.generate_imu(t[:w], lla[:w], rph[:w], vel[:w], sensor_type="increment")
    _pyins_strapdown(warm, pva)
    t_warm = time.perf_counter() - t0

    def generate():
        _, perfect = sim.generate_imu(t, lla, rph, vel, sensor_type="increment")
        rng = np.random.RandomState(seed)
        noisy = inertial_sensor.apply_imu_parameters(perfect, "increment", _pyins_params(spec.gyro, rng),
                                                     _pyins_params(spec.accel, rng))
        return perfect, noisy

    t_gen, (perfect, _) = _best(generate, repeat)
    t_perfect, _ = _best(lambda: sim.generate_imu(t, lla, rph, vel, sensor_type="increment"), repeat)

    imu0 = _imu_frame(data.gyro[0], data.accel[0], dt)  # fusionbench's run 0, in pyins's frames
    t_sd, C_py_free = _best(lambda: _pyins_strapdown(imu0, pva), repeat)
    t_inc, _ = _best(lambda: strapdown.compute_increments_from_imu(imu0, "increment"), repeat)
    C_py_held = _pyins_strapdown(imu0, pva, with_altitude=False)

    def fb_final(height_fixed):
        st = NavState.broadcast(1, tru.C_bn[0], tru.v_n[0], tru.lat[0], tru.lon[0], tru.h[0])
        sd = Strapdown(st, dt, height_fixed=height_fixed)
        sd.run(data.gyro[:1], data.accel[:1], record_every=n)
        return sd.state.C_bn[0]

    def arcsec(C1, C2):
        return float(np.linalg.norm(attitude.misalignment(C1, C2)) / ARCSEC)

    # pyins's own perfect increments: how close its spline generation is to fusionbench's exact increments,
    # and where pyins's strapdown takes them against fusionbench's truth
    _, dth_exact, dv_exact = tr.increments(0.0, dt, n)
    dth_py, dv_py = perfect[G_COLS].to_numpy()[1:] @ P, perfect[A_COLS].to_numpy()[1:] @ P
    C_py_own = _pyins_strapdown(_imu_frame(dth_py, dv_py, dt), pva, with_altitude=False)
    return {
        "version": version(),
        "samples": n,
        "warmup_s": t_warm,
        "gen_s": t_gen,
        "gen_per_s": n / t_gen,
        "gen_perfect_s": t_perfect,
        "gen_perfect_per_s": n / t_perfect,
        "strapdown_s": t_sd,
        "strapdown_per_s": n / t_sd,
        "increments_s": t_inc,
        "rph_check": rph_check,
        "diff_held_arcsec": arcsec(C_py_held, fb_final(True)),
        "diff_free_arcsec": arcsec(C_py_free, fb_final(False)),
        "gen_max_dtheta_diff_rad": float(np.abs(dth_py - dth_exact).max()),
        "gen_max_dvel_diff_mps": float(np.abs(dv_py - dv_exact).max()),
        "own_vs_truth_arcsec": arcsec(C_py_own, tru.C_bn[-1]),
        "total_s": time.perf_counter() - t_start,
    }


def report(py, im, sd, runs):
    """Print the side-by-side section (4.) of ``perf_core.py``; ``im``, ``sd``: its benchmarks 1 and 2."""
    if py is None:
        print("4. pyins side by side: pyins not installed (pip install python-ins)")
        return
    n = py["samples"]
    print(f"4. pyins {py['version']} side by side, same sway, one run x {n:,} samples (best of repeats); "
          f"pyins warm-up (numba compile) {py['warmup_s']:.2f} s, this section {py['total_s']:.1f} s")
    print(f"   {'IMU generation':<46}{'samples/s':>14}{'fusionbench / pyins':>22}")
    rows = [("pyins generate_imu + apply_imu_parameters", py["gen_per_s"], None),
            ("pyins generate_imu alone (perfect IMU)", py["gen_perfect_per_s"], None),
            ("fusionbench simulate, one run per call", im["looped_per_s"], py["gen_per_s"]),
            (f"fusionbench simulate, batched ({runs} runs)", im["batched_per_s"], py["gen_per_s"])]
    for name, r, ref in rows:
        print(f"   {name:<46}{r:>14,.0f}" + (f"{r / ref:>21.1f}x" if ref else ""))
    print(f"   {'strapdown':<46}{'steps/s':>14}{'fusionbench / pyins':>22}")
    rows = [("pyins compute_increments + Integrator", py["strapdown_per_s"], None),
            ("fusionbench numba, one run per integrator", sd["looped_per_s"], py["strapdown_per_s"]),
            (f"fusionbench numba, batched ({runs} runs)", sd["batched_per_s"], py["strapdown_per_s"])]
    for name, r, ref in rows:
        print(f"   {name:<46}{r:>14,.0f}" + (f"{r / ref:>21.1f}x" if ref else ""))
    print(f"   (pyins strapdown: compute_increments_from_imu {py['increments_s']:.3f} s of {py['strapdown_s']:.3f} s; "
          f"Integrator keeps every sample and its roll/pitch/heading, fusionbench every 100th)")
    print(f"   final attitude, same increments (run 0): pyins vs fusionbench {py['diff_held_arcsec']:.2e} arcsec "
          f"(height held in both), {py['diff_free_arcsec']:.2e} arcsec (free vertical channels)")
    print(f"   pyins's own perfect increments vs fusionbench's exact ones: max "
          f"{py['gen_max_dtheta_diff_rad']:.1e} rad, {py['gen_max_dvel_diff_mps']:.1e} m/s; through pyins's "
          f"strapdown, final attitude vs fusionbench truth {py['own_vs_truth_arcsec']:.2e} arcsec "
          f"(angle series check {py['rph_check']:.0e})")


def json_fields(py, im, sd):
    """The pyins figures for ``perf_core.py``'s JSON line (None where pyins is not installed)."""
    keys = ["pyins_version", "pyins_gen_samples_per_s", "pyins_gen_perfect_samples_per_s",
            "pyins_strapdown_steps_per_s", "imu_looped_over_pyins", "imu_batched_over_pyins",
            "strapdown_looped_over_pyins", "strapdown_batched_over_pyins", "pyins_att_diff_held_arcsec",
            "pyins_att_diff_free_arcsec", "pyins_own_vs_truth_arcsec", "pyins_warmup_s", "pyins_total_s"]
    if py is None:
        return dict.fromkeys(keys)
    vals = [py["version"], py["gen_per_s"], py["gen_perfect_per_s"], py["strapdown_per_s"],
            im["looped_per_s"] / py["gen_per_s"], im["batched_per_s"] / py["gen_per_s"],
            sd["looped_per_s"] / py["strapdown_per_s"], sd["batched_per_s"] / py["strapdown_per_s"],
            py["diff_held_arcsec"], py["diff_free_arcsec"], py["own_vs_truth_arcsec"], py["warmup_s"], py["total_s"]]
    return dict(zip(keys, vals))
