"""The documentation's front figure: aligners on one bench, scored against the truth, the limit and the bound.

Twenty recordings of 300 s of a navigation-grade IMU on a static bench at 34 N (heading 123 deg), each method from
its own start (no initial guess, as ``fusionbench align`` calls it; the causal methods, whose attitude at t uses the
samples up to t). The curve of a method is the RMS over the runs
of its azimuth error about the theoretical limit (the error every stationary alignment ends on, set by the fixed
biases), at every time of its history; the dashed line is the attainable bound, the standard deviation about the
limit that the IMU's noise leaves the best estimator. The compass loops hold their starting heading until their
compass stage begins (off the scale before). Run from the repository root::

    python docs/figures/front.py          # writes docs/_static/front.png (about 10 s on 2 cores)
"""

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import fusionbench as fb  # noqa: E402

METHODS = {"pid": "#1f77b4", "adrc": "#2ca02c", "eso-td": "#9467bd", "kf": "#d62728"}
OUT = Path(__file__).parents[1] / "_static" / "front.png"


def main():
    site = fb.Site.from_degrees(34.0, 108.0, 450.0)
    bench = fb.Trajectory(site.lat, site.lon, site.h, fb.EulerSway(mean=np.radians([1.0, -2.0, -123.0])),
                          duration=300.0)
    spec = fb.PRESETS["navigation"]
    imu = fb.simulate(bench, spec, dt=0.01, runs=20, seed=1)
    C_true = bench.truth([0.0]).C_bn[0]  # a static bench: one attitude
    limit = fb.metrics.theoretical_limits(spec.gyro.bias, spec.accel.bias, C_true, site.lat, site.h)
    t_bound, bound = fb.metrics.attainable_bound(spec, 300.0, trajectory=bench)

    fig, ax = plt.subplots(figsize=(8.0, 3.8), layout="constrained")
    for name, color in METHODS.items():
        res = fb.align(imu, site, method=name)
        phi = fb.metrics.misalignment_history(res.C_bn, bench.truth(res.t).C_bn)  # (runs, M, 3) rad
        rms = np.sqrt(np.mean((phi[..., 2] - limit[2]) ** 2, axis=0)) / fb.units.ARCMIN
        keep = res.t >= 5.0
        ax.semilogy(res.t[keep], rms[keep], color=color, lw=1.6, label=name)
        print(f"{name}: azimuth RMS about the limit at {res.t[-1]:.0f} s: {rms[-1]:.2f} arcmin")
    keep = t_bound >= 5.0
    ax.semilogy(t_bound[keep], bound[keep, 2] / fb.units.ARCMIN, "k--", lw=1.4, label="attainable bound")
    print(f"bound at 300 s: {bound[-1, 2] / fb.units.ARCMIN:.2f} arcmin")
    ax.set_xlabel("time from the start of the record (s)")
    ax.set_ylabel("azimuth error about the limit,\nRMS over 20 runs (arcmin)")
    ax.set_xlim(0.0, 300.0)
    ax.set_ylim(1.5, 100.0)  # pid and adrc report their starting heading (about 7000 arcmin off) before their compass
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(ncols=3, fontsize=9, loc="upper right")
    ax.set_title("Static bench at 34 N, navigation-grade IMU: every method from its own start", fontsize=10)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
