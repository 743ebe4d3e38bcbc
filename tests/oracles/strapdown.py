"""The NumPy reference of the compiled strapdown loop
(:func:`fusionbench.simulation.strapdown_compiled._integrate_numba`).

A Python loop over samples with arrays over runs that makes the kernel's operations in its order; the tests hold the
kernel to it (``tests/test_strapdown.py``) and ``benchmarks/perf_core.py`` times the two side by side. ``PATCH`` names
the library's function it stands in for, for ``monkeypatch.setattr``.
"""

from __future__ import annotations

import numpy as np

from fusionbench.simulation import earth
from fusionbench.simulation.strapdown import _cross, body_increments, rodrigues


def integrate_numpy(C0, v0, lat0, lon0, h0, v_prev0, th_prev, dv_prev, dtheta, dvel, cmd, dt,
                    position_fixed, height_fixed, record_every, out_C, out_v, out_p):
    """The arguments and effects of the compiled kernel: loop over samples, NumPy over runs; updates the state arrays
    in place."""
    n = dtheta.shape[1]
    C_b, dv_b = body_increments(dtheta, dvel, th_prev, dv_prev)
    C, v, lat, lon, h, v_prev = C0.copy(), v0.copy(), lat0.copy(), lon0.copy(), h0.copy(), v_prev0.copy()
    for k in range(n):
        v_mid = 1.5 * v - 0.5 * v_prev
        rm, rn = earth.radii(lat)
        rmh, rnh = rm + h, rn + h
        g_n = earth.gravity_n(lat, h)
        w_ie = earth.earth_rate_n(lat)
        w_en = earth.transport_rate_n(v_mid, lat, h) * (not position_fixed)
        w_in = w_ie + w_en
        if cmd.shape[1]:
            w_in = w_in + cmd[:, k]
        zeta = w_in * dt
        dv_n = (C @ dv_b[:, k, :, None])[..., 0]
        dv_n = dv_n - 0.5 * _cross(zeta, dv_n)
        v_new = v + dv_n + (g_n - _cross(2.0 * w_ie + w_en, v_mid)) * dt
        if height_fixed:
            v_new[:, 2] = 0.0
        C = np.swapaxes(rodrigues(zeta), -1, -2) @ C @ C_b[:, k]
        if not position_fixed:
            vm = 0.5 * (v + v_new)
            h = h if height_fixed else h + vm[:, 2] * dt
            lat = lat + vm[:, 1] / rmh * dt
            lon = lon + vm[:, 0] / (rnh * np.cos(lat)) * dt
        v_prev, v = v, v_new
        if (k + 1) % record_every == 0:
            j = (k + 1) // record_every - 1
            out_C[:, j] = C
            out_v[:, j] = v
            out_p[:, j] = np.stack([lat, lon, h], -1)
    C0[:] = 1.5 * C - 0.5 * C @ np.swapaxes(C, -1, -2) @ C  # first-order re-orthonormalisation
    v0[:], lat0[:], lon0[:], h0[:], v_prev0[:] = v, lat, lon, h, v_prev
    th_prev[:] = dtheta[:, -1]
    dv_prev[:] = dvel[:, -1]


#: (module, attribute, oracle): the library function this oracle replaces.
PATCH = ("fusionbench.simulation.strapdown", "_integrate_numba", integrate_numpy)
