"""The NumPy reference of ``coarse-i0``'s compiled pass over the samples
(:func:`fusionbench.methods.coarse_kernel.body_pass`).

A Python step per sample over all runs at once, the kernel's arithmetic; ``tests/test_coarse.py`` holds the method
to it. ``PATCH`` names the library's function it stands in for, for ``monkeypatch.setattr``.
"""

from __future__ import annotations

import numpy as np


def body_pass_numpy(C_b, dv_b, dt, ckeep, vkeep, C_out, V_out, P_out):
    """:func:`fusionbench.methods.coarse_kernel.body_pass` in NumPy (its arguments and effects)."""
    R, N = dv_b.shape[:2]
    C = np.broadcast_to(np.eye(3), (R, 3, 3)).copy()
    V = np.zeros((R, 3))
    P = np.zeros((R, 3))
    jc = jv = 0
    for k in range(N):
        dV = (C @ dv_b[:, k, :, None])[..., 0]
        P = P + (V + 0.5 * dV) * dt
        V = V + dV
        C = C @ C_b[:, k]
        if jc < ckeep.size and ckeep[jc] == k:
            C_out[:, jc] = C
            jc += 1
        if jv < vkeep.size and vkeep[jv] == k:
            V_out[:, jv] = V
            if P_out.shape[1]:
                P_out[:, jv] = P
            jv += 1


#: (module, attribute, oracle): the library function this oracle replaces.
PATCH = ("fusionbench.methods.coarse_i0", "body_pass", body_pass_numpy)
