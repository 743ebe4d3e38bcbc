"""Seed 004's (Gu 2017, adaptive Schuler damping) design figures from the network itself: damping ratio against q (Fig.
4), peak attitude error against acceleration (Fig. 5), and the acceleration -> q data and its RBF map (Figs. 6 and 8).

Written with matplotlib (Agg) into a report folder; every curve is computed here from
:mod:`damping.network` and :mod:`damping.qmap`, none is read from the paper. Units on the axes.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fusionbench.reports.figures import save_png  # noqa: E402

from . import network, qmap  # noqa: E402


def damping_ratio_figure(path):
    """Fig. 4: xi(q) from the resonant peak, from the dominant poles, and the paper's fit 0.09 (q - 1)."""
    q = np.linspace(1.0, 8.0, 57)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(q, [network.damping_from_peak(v) for v in q], label="resonant peak Mr = 1/(2 xi sqrt(1 - xi^2))")
    ax.plot(q, [network.damping_from_poles(v) for v in q], label="least-damped closed-loop poles")
    ax.plot(q, network.paper_fit(q), "k--", label="paper's fit xi = 0.09 (q - 1), eq. 6")
    ax.set_xlabel("network coefficient q (dimensionless)")
    ax.set_ylabel("damping ratio xi (dimensionless)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Damping ratio of the north level loop against q (Fig. 4)", fontsize=10)
    fig.tight_layout()
    save_png(fig, path)


def accel_error_figure(path, max_error_deg=0.03):
    """Fig. 5: peak attitude error (deg) against acceleration for several q: eq. 10 with the pole damping
    ratio (dashed) and lsim of eq. 2 with the actual H(s) (solid)."""
    a = np.linspace(0.0, 0.1, 51)
    fig, ax = plt.subplots(figsize=(6, 4))
    for q in (2.0, 3.0, 5.0, 6.56):
        e1 = network.simulated_peak_error(1.0, q)  # linear in the acceleration
        xi = network.damping_from_poles(q)
        (line,) = ax.plot(a, np.degrees(a * e1), label=f"q = {q:g} (pole damping xi = {xi:.2f})")
        ax.plot(a, np.degrees(network.peak_attitude_error(a, xi)), "--", color=line.get_color())
    ax.plot([], [], "k-", lw=1, label="solid: lsim of eq. 2 with the actual H(s)")
    ax.plot([], [], "k--", lw=1, label="dashed: eq. 10 with that xi")
    ax.axhline(max_error_deg, color="k", lw=1.5, ls=":", label=f"{max_error_deg:g} deg, the map's target")
    ax.set_xlabel("acceleration step (m/s^2)")
    ax.set_ylabel("peak attitude error (deg)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("Peak attitude error from an acceleration step (Fig. 5)", fontsize=10)
    fig.tight_layout()
    save_png(fig, path)


def qmap_figure(path, qm, max_error_deg=0.03):
    """Figs. 6 and 8: the largest q keeping the peak error at ``max_error_deg`` (training data) and the
    fitted RBF map, clipped to [1, 7]."""
    a, q = qmap.training_data(qmap.default_accels(), max_error=np.radians(max_error_deg))
    fine = np.logspace(np.log10(a[0]), np.log10(a[-1]), 400)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.semilogx(a, q, ".", ms=3, label="training data: simulated eq. 2 (Fig. 6)")
    ax.semilogx(fine, qm(fine), label=f"RBF map, clipped to [1, 7] (Fig. 8); held-out MSE {qm.mse_:.2g}")
    ax.set_xlabel("acceleration (m/s^2)")
    ax.set_ylabel("network coefficient q (dimensionless)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(f"Acceleration -> q keeping the peak error at {max_error_deg:g} deg", fontsize=10)
    fig.tight_layout()
    save_png(fig, path)


def theory_figures(folder, qm=None, max_error_deg=0.03):
    """Write the figures into ``folder``; the map figure only when a map ``qm`` is given.

    Returns
    -------
    list of (str, str)
        File names and captions.
    """
    folder = Path(folder)
    out = [("damping_ratio.png", "damping ratio against q (seed 004 Fig. 4)"),
           ("accel_error.png", "peak attitude error against acceleration (seed 004 Fig. 5)")]
    damping_ratio_figure(folder / out[0][0])
    accel_error_figure(folder / out[1][0], max_error_deg)
    if qm is not None:
        out.append(("qmap.png", "acceleration -> q: training data and RBF map (seed 004 Figs. 6 and 8)"))
        qmap_figure(folder / out[2][0], qm, max_error_deg)
    return out
