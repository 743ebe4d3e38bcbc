"""The error limits that constant sensor biases leave in the ESO/TD aligner on an eastward moving base (eqs. 7, 9,
12 as solved), shared by ``tests/test_moving_base.py`` and ``tests/test_eso_td_accuracy.py``."""

import numpy as np

from fusionbench.simulation import earth


def _specific_force_n(tr, t):
    _, f_b = tr.kinematics(t)
    return np.einsum("nij,nj->ni", tr.truth(t).C_bn, f_b)


def moving_base_limits(tr, t, eps_n, nab_n):
    """Error psi - psi_hat (rad, (R, M, 3)) that constant biases leave in eqs. 7, 9, 12 as solved.

    With p = psiN - n psiU - nabE / fU and q = psiE - s psiU + nabN / fU (eqs. 7, 9 without the psiU
    terms; s = fE / fU, n = fN / fU) and the strapdown's psi' (eq. 1 with -eps), the module's
    ``psiU_hat D = W sinL p - q' - s W cosL q`` (D = W cosL (1 + s^2) - W sinL n + s') gives, for an
    eastward base (L_dot = 0)::

        eU = psiU - psiU_hat = (-epsE + s epsU + W sinL nabE / fU + s W cosL nabN / fU + k) / D
        eE = -nabN / fU + s eU,    eN = nabE / fU + n eU

    with k = d(nabN / fU)/dt = -nabN fU' / fU^2. On a static base (s = n = k = 0, W = w_ie) this is
    the usual [-nabN / g, nabE / g, -epsE / (w_ie cos L) + tan L nabE / g]. The truth's specific force
    is taken half a step before each report (the trajectory's acceleration stops at exactly 400 s).
    """
    t = np.asarray(t, dtype=float) - 0.05
    f = _specific_force_n(tr, t)
    fdot = f - _specific_force_n(tr, t - 1.0)
    tru = tr.truth(t)
    L = tru.lat
    _, rn = earth.radii(L)
    W = earth.OMEGA_IE + tru.v_n[:, 0] / ((rn + tru.h) * np.cos(L))
    fE, fN, fU = f.T
    s, n = fE / fU, fN / fU
    ds = fdot[:, 0] / fU - fE * fdot[:, 2] / fU**2
    eps = np.asarray(eps_n, dtype=float).reshape(-1, 1, 3)
    nab = np.asarray(nab_n, dtype=float).reshape(-1, 1, 3)
    k = -nab[..., 1] * fdot[:, 2] / fU**2
    den = W * np.cos(L) * (1 + s * s) - W * np.sin(L) * n + ds
    eU = (-eps[..., 0] + s * eps[..., 2] + W * np.sin(L) * nab[..., 0] / fU + s * W * np.cos(L) * nab[..., 1] / fU
          + k) / den
    return np.stack([-nab[..., 1] / fU + s * eU, nab[..., 0] / fU + n * eU, eU], axis=-1)
