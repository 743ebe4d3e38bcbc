"""Observability of a rolling torquing scheme: PWCS information matrix, rank, output sensitivity curves.

Seed 002 (Ding, rolling-platform self-calibration) (continuous rolling self-calibration of a floated inertial platform)
argues that its scheme (:data:`baselines.rolling.scheme.PAPER_SCHEME`) makes all 45 states of its EKF observable: the
information matrix of the piecewise-constant system along the scheme has rank 45, and the "output sensitivity
curves" (its Figs. 4-7) show how strongly each error coefficient drives the accelerometer outputs as
the platform rolls. This module computes both for any :class:`~baselines.rolling.scheme.Scheme`, so a user
can check a scheme of their own before running the filter.

Model
-----
The filter's linearised error-state model (:func:`baselines.rolling.jacobians.error_jacobians`)::

    e = [c_true - c_est (42, SI), eta (3, rad)],   C_true = (I - [eta x]) C_est   (eta: rotation in ENU)
    de/dt = F_e(x(t), w_cmd(t)) e,   dy = H_e(x(t)) e + v,   v ~ N(0, R),  R = accel_noise^2 I_3

linearised along the *commanded* path: the nominal state ``x(t) = [coeffs, angles(C_path(t))]`` with
``C_path`` from :func:`baselines.rolling.scheme.commanded_path` (the drift the coefficients would add to the
path is second order in the error and left out).

Piecewise-constant system (PWCS; Goshen-Meskin and Bar-Itzhack, "Observability analysis of
piece-wise constant systems", IEEE Trans. AES 28(4), 1992). Time is cut into steps of ``step_s``
(``t_k = k step_s``); over step k, ``[t_k, t_{k+1})``, the system matrix is held at
``F_k = F_e(x(t_k), w_cmd)`` with the torque command of the command period that holds the step, so::

    Phi_k = expm(F_k step_s)                      (scipy.linalg.expm)
    Phi(t_k, 0) = Phi_{k-1} ... Phi_1 Phi_0,       Phi(t_0, 0) = I
    H_k = H_e(x(t_k))

One output every ``step_s`` at ``t_k``, k = 1 .. N (``N = duration / step_s``; the first one step after
the start, as the filter's), gives the information matrix (SI, the inverse of the error covariance a
prior-free least-squares fit of ``e(0)`` would reach)::

    M = sum_k Phi(t_k, 0)^T H_k^T R^-1 H_k Phi(t_k, 0)                               (45 x 45)

It is the observability Gramian of the discretised system, weighted by the noise. The scheme makes
the initial error ``e(0)`` observable from the outputs exactly when M has full rank 45; seed 002
reports rank 45 for its scheme.

Scaling. The SI states span 1e-12 rad/s/(m/s^2)^2 (quadratic drift terms) to 0.1 rad (attitude), so
the SI M has entries from 1e-3 to 1e+30 and its singular values say nothing about rank. In the
prior-scaled coordinates of the filter, ``e = D z`` with ``D = diag(prior_sigma())``
(:func:`baselines.rolling.priors.prior_sigma`: one unit of z is one prior standard deviation)::

    M_z = D M D

A singular value of ``M_z`` compares the information of the data in that direction with the prior's
(which is 1 in every direction): much larger than 1 means the scheme determines that combination far
better than the prior, and 0 means not at all. ``scaled=True`` (default) returns ``M_z``.

Rank and tolerance. :func:`information_rank` counts singular values above ``rtol`` times the largest,
``rtol = 1e-12`` (:data:`RTOL`). Measured at latitude 40 deg, 1-s steps, zero coefficients, 1-ug noise
(singular values of ``M_z`` relative to the largest, 4.4e13):

* paper scheme: smallest 8.5e-10 (K2_X + K2_Y), all 45 above the tolerance: rank 45 (same at
  latitudes 0, 20, 60 deg; 4.6e-10 at 80 deg);
* rolling about south only for 5400 s: 21st 1.8e-8, 22nd 3.5e-17: rank 21 (about east only: the same);
* static platform (rate 0, 600 s): 6th 1.4e-8, 7th 2.6e-17: rank 6.

The null singular values of the deficient schemes sit at the float64 rounding floor of a 45 x 45 SVD
(``45 eps ~ 1e-14`` relative, below it here); 1e-12 lies two decades above that floor and almost three
below the paper scheme's weakest direction. (At the paper's noise and step, 1e-12 of the largest is an
information of 44 prior units: a direction the data would pin down to no better than 1/7 of its prior
sigma.) Parts of a scheme do not always show such a gap: the paper scheme's first 2700 s (south, east)
has singular values 1.5e-11, 1.1e-12, 5.7e-13, 9.7e-18 relative, so its rank (34 at 1e-12) depends on
the tolerance; look at :func:`singular_values` before trusting one number.

Output sensitivity (seed 002's Figs. 4-7)::

    S(t_k) = H_k Phi(t_k, 0) D          (3 x 45 at each t_k; m/s^2 of output per one prior sigma)

column j is the change of the three accelerometer outputs at ``t_k`` caused by an initial error of one
prior standard deviation in state j (the information matrix is ``M_z = sum_k S_k^T R^-1 S_k``).

Every function validates its input and raises one ``ValueError`` line naming the field.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from fusionbench.simulation import earth

from . import angles, model
from .jacobians import error_jacobians
from .priors import prior_sigma
from .scheme import Scheme, commanded_path, commands

#: Default relative tolerance of :func:`information_rank` (on the singular values of the scaled M).
RTOL = 1e-12
#: Names of the 45 error states: the coefficients, then the rotation error eta (ENU components).
ERROR_STATE_NAMES = list(model.COEFF_NAMES) + ["eta_E", "eta_N", "eta_U"]


def _check_inputs(scheme, lat, h, C0, coeffs, step_s):
    if not isinstance(scheme, Scheme):
        raise ValueError(f"scheme: expected a baselines.rolling.scheme.Scheme, found {type(scheme).__name__}")
    earth.check_latitude(lat, "lat")
    h = float(h)
    if not np.isfinite(h):
        raise ValueError(f"h: expected a finite height in m, found {h}")
    if C0 is None:
        C0 = angles.angles_to_dcm(np.zeros(3))
    C0 = np.asarray(C0, dtype=float)
    if C0.shape != (3, 3):
        raise ValueError(f"C0: expected shape (3, 3), found {C0.shape}")
    if coeffs is None:
        coeffs = np.zeros(model.N_COEFFS)
    coeffs = np.asarray(coeffs, dtype=float)
    if coeffs.shape != (model.N_COEFFS,) or not np.all(np.isfinite(coeffs)):
        raise ValueError(f"coeffs: expected {model.N_COEFFS} finite SI values, found shape {coeffs.shape}")
    try:
        step_s = float(step_s)
    except (TypeError, ValueError):
        raise ValueError(f"step_s: expected a positive number of seconds, found {step_s!r}") from None
    per = scheme.command_period_s
    k = round(per / step_s) if np.isfinite(step_s) and step_s > 0 else 0
    if k < 1 or abs(per - k * step_s) > 1e-9 * per:
        raise ValueError(f"step_s: expected a whole fraction of the command period {per} s, found {step_s}")
    return float(lat), h, C0, coeffs, step_s


def _output_sensitivity(scheme, lat, h, C0, coeffs, step_s):
    """Times t_k (k = 1 .. N, s) and ``H_k Phi(t_k, 0)`` (N, 3, 45), SI (unscaled)."""
    n = int(round(scheme.duration / step_s))
    t = np.arange(n + 1) * step_s
    path_angles = angles.dcm_to_angles(commanded_path(scheme, C0, t))
    cmd = commands(scheme, C0, lat)
    # the command period that holds step k, [t_k, t_k + step_s)
    ci = np.minimum(((t + 0.5 * step_s) // scheme.command_period_s).astype(int), cmd.shape[0] - 1)
    nc = model.N_COEFFS
    # F_k's eta rows (n, 3, 45); the whole F_k (n, 45, 45: 87 MB over seed 002's 5400 s) only if its coefficient rows
    # are not zero, which the filter's model (constant coefficients) never has
    F_eta = np.empty((n, 3, model.N_STATES))
    F = None
    H = np.empty((n + 1, 3, model.N_STATES))
    x = np.concatenate([coeffs, np.zeros(3)])
    for k in range(n + 1):
        x[model.ANGLES] = path_angles[k]
        Fk, H[k] = error_jacobians(x, cmd[ci[k]], lat, h)
        if k < n:
            F_eta[k] = Fk[nc:]
            if F is None and np.any(Fk[:nc] != 0.0):  # the rows before k were zero
                F = np.zeros((n, model.N_STATES, model.N_STATES))
                F[:k, nc:] = F_eta[:k]
            if F is not None:
                F[k] = Fk
    if F is not None:  # not the filter's model: the plain way
        Phi = expm(F * step_s)
        out = np.empty((n, 3, model.N_STATES))
        P = np.eye(model.N_STATES)
        for k in range(n):
            P = Phi[k] @ P  # Phi(t_{k+1}, 0)
            out[k] = H[k + 1] @ P
        return t[1:], out
    # Only the 3 eta rows of F_k are non-zero, F_k = [[0, 0], [A_k, B_k]], so
    # expm(F_k T) = [[I, 0], [G_k A_k, expm(B_k T)]] with G_k = int_0^T expm(B_k s) ds, both from one 6 x 6
    # exponential (Van Loan): expm([[B_k, I], [0, 0]] T) = [[expm(B_k T), G_k], [0, I]]
    aug = np.zeros((n, 6, 6))
    aug[:, :3, :3] = F_eta[:, :, nc:] * step_s
    aug[:, :3, 3:] = np.eye(3) * step_s
    # with constant nominal coefficients B_k = -[w_ie x] + (drift terms, zero for zero coefficients):
    # exponentiate each distinct matrix once
    uniq, inv = np.unique(aug.reshape(n, 36), axis=0, return_inverse=True)
    X = expm(uniq.reshape(-1, 6, 6))[inv.ravel()]
    E, GA = X[:, :3, :3], X[:, :3, 3:] @ F_eta[:, :, :nc]
    # Q_k = eta rows of Phi(t_k, 0): Q_0 = [0, I], Q_{k+1} = E_k Q_k + [G_k A_k, 0]
    Q = np.empty((n, 3, model.N_STATES))
    q = np.zeros((3, model.N_STATES))
    q[:, nc:] = np.eye(3)
    for k in range(n):
        q = E[k] @ q
        q[:, :nc] += GA[k]
        Q[k] = q
    # H_k Phi(t_k, 0) = [H_c + H_eta Q_c, H_eta Q_eta]
    out = H[1:].copy()
    out[:, :, nc:] = 0.0
    out += H[1:, :, nc:] @ Q
    return t[1:], out


def information_matrix(scheme, lat, h=0.0, C0=None, coeffs=None, step_s=1.0, accel_noise=model.PAPER_ACCEL_NOISE,
                       scaled=True):
    """PWCS information matrix of a torquing scheme (module notes).

    Parameters
    ----------
    scheme : baselines.rolling.scheme.Scheme
        Torquing scheme.
    lat : float
        Latitude, rad.
    h : float, optional
        Height, m.
    C0 : array_like, shape (3, 3), optional
        Initial attitude ``C_pn`` (p to ENU); default the zero attitude (platform axes on
        North-Up-East, ``angles.angles_to_dcm(zeros(3))``).
    coeffs : array_like, shape (42,), optional
        Nominal error coefficients (SI) to linearise at; default zeros.
    step_s : float, optional
        PWCS step and output interval, s; a whole fraction of the scheme's command period.
    accel_noise : float, optional
        Accelerometer noise, m/s^2 (standard deviation of each output): ``R = accel_noise^2 I``.
    scaled : bool, optional
        If True, ``M_z = D M D`` in prior-scaled coordinates (dimensionless); else M in SI
        (entry ij in 1 / (unit_i unit_j)).

    Returns
    -------
    ndarray, shape (45, 45)
        Symmetric positive semi-definite information matrix of the initial error ``e(0)``.
    """
    lat, h, C0, coeffs, step_s = _check_inputs(scheme, lat, h, C0, coeffs, step_s)
    accel_noise = float(accel_noise)
    if not np.isfinite(accel_noise) or accel_noise <= 0:
        raise ValueError(f"accel_noise: expected a positive standard deviation in m/s^2, found {accel_noise}")
    _, S = _output_sensitivity(scheme, lat, h, C0, coeffs, step_s)
    if scaled:
        S = S * prior_sigma()
    Z = S.reshape(-1, model.N_STATES) / accel_noise
    M = Z.T @ Z
    return 0.5 * (M + M.T)


def _check_square(M):
    M = np.asarray(M, dtype=float)
    if M.ndim != 2 or M.shape[0] != M.shape[1] or M.shape[0] == 0:
        raise ValueError(f"M: expected a square matrix, found shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError("M: expected finite values, found NaN or inf")
    return M


def _check_rtol(rtol):
    rtol = float(rtol)
    if not np.isfinite(rtol) or not 0 < rtol < 1:
        raise ValueError(f"rtol: expected a relative tolerance in (0, 1), found {rtol}")
    return rtol


def singular_values(M):
    """Singular values of an information matrix, largest first (its units; dimensionless when scaled)."""
    return np.linalg.svd(_check_square(M), compute_uv=False)


def information_rank(M, rtol=RTOL, return_singular_values=False):
    """Numerical rank of an information matrix: singular values above ``rtol`` times the largest.

    Parameters
    ----------
    M : array_like, shape (n, n)
        Information matrix, best the prior-scaled one (``information_matrix(..., scaled=True)``).
    rtol : float, optional
        Relative tolerance, default :data:`RTOL` = 1e-12 (justified from measured spectra in the
        module notes).
    return_singular_values : bool, optional
        Also return the singular values (largest first).

    Returns
    -------
    int, or (int, ndarray of shape (n,))
    """
    rtol = _check_rtol(rtol)
    s = singular_values(M)
    rank = int(np.sum(s > rtol * s[0])) if s[0] > 0 else 0
    return (rank, s) if return_singular_values else rank


@dataclass
class Directions:
    """Weakest (unobservable) directions of an information matrix (:func:`unobservable_directions`).

    Attributes
    ----------
    singular_values : ndarray, shape (k,)
        The k smallest singular values of M, smallest first (units of M).
    vectors : ndarray, shape (n, k)
        Unit vectors spanning the same subspace as their right singular vectors (coordinates of M:
        prior-scaled when M is), in a readable basis: each column has one "pivot" state and no component
        on the other columns' pivots, so a single state the scheme cannot see appears alone.
    terms : list of list of (str, float)
        Per column, the states with ``abs(component) >= min_component``, largest first.
    weights : ndarray, shape (n,)
        Squared norm of each state's projection on the subspace (basis independent): 1 means the state
        lies in it entirely (not separated at all), 0 that it is orthogonal to it.
    names : list of str
        State names.
    """

    singular_values: np.ndarray
    vectors: np.ndarray
    terms: list
    weights: np.ndarray
    names: list

    def __str__(self):
        lines = []
        for i, tt in enumerate(self.terms):
            lines.append(" + ".join(f"{c:+.2f} {n}" for n, c in tt) or "(none)")
        return "\n".join(lines)


def informed_directions(M, threshold=1.0):
    """Directions of a prior-scaled information matrix in which the data outweigh the prior: eigenvalues
    above ``threshold`` (1: the posterior variance ``(I + M)^-1`` is below half the prior's). Unlike the
    rank (:func:`information_rank`, a structural property) this depends on the noise and the priors: how
    many directions a run actually calibrates."""
    ev = np.linalg.eigvalsh(0.5 * (np.asarray(M) + np.asarray(M).T))
    return int(np.sum(ev > threshold))


def unobservable_directions(M, rtol=RTOL, count=None, names=None, min_component=0.05):
    """Combinations of states a scheme cannot separate: the right singular vectors of the smallest
    singular values, named.

    Parameters
    ----------
    M : array_like, shape (n, n)
        Information matrix (prior-scaled recommended).
    rtol : float, optional
        Singular values below ``rtol`` times the largest count as zero (:data:`RTOL`); used when
        ``count`` is None.
    count : int, optional
        Take this many smallest singular values instead (e.g. to see the weakest directions of a full
        rank scheme).
    names : list of str, optional
        State names; default :data:`ERROR_STATE_NAMES` (n = 45).
    min_component : float, optional
        Smallest abs(component) listed in ``terms``.

    Returns
    -------
    Directions
    """
    M = _check_square(M)
    n = M.shape[0]
    names = list(ERROR_STATE_NAMES if names is None else names)
    if len(names) != n:
        raise ValueError(f"names: expected {n} names, found {len(names)}")
    _, s, Vt = np.linalg.svd(M)
    if count is None:
        k = n - (int(np.sum(s > _check_rtol(rtol) * s[0])) if s[0] > 0 else 0)
    else:
        if not isinstance(count, (int, np.integer)) or not 0 <= count <= n:
            raise ValueError(f"count: expected an integer in [0, {n}], found {count!r}")
        k = int(count)
    V = Vt[n - k:][::-1].T  # (n, k), smallest singular value first
    weights = np.sum(V * V, axis=1)
    if k > 1:
        # readable basis of the same span: pivots = states most inside the subspace (pivoted QR of V^T),
        # then B^T = R1^-1 V^T is the identity on the pivots (reduced echelon form)
        from scipy.linalg import qr

        _, R, piv = qr(V.T, pivoting=True)
        B = np.linalg.solve(R[:, :k], R)  # columns in pivoted order
        Bt = np.empty_like(B)
        Bt[:, piv] = B
        V = Bt.T / np.linalg.norm(Bt, axis=1)
    terms = []
    for j in range(k):
        v = V[:, j]
        order = np.argsort(-np.abs(v))
        terms.append([(names[i], float(v[i])) for i in order if abs(v[i]) >= min_component])
    return Directions(singular_values=s[n - k:][::-1].copy(), vectors=V, terms=terms, weights=weights, names=names)


def sensitivity_curves(scheme, lat, h=0.0, C0=None, coeffs=None, step_s=1.0):
    """Output sensitivity curves of a scheme (seed 002's Figs. 4-7).

    ``S(t_k) = H_k Phi(t_k, 0) D``: the change of the three accelerometer outputs at ``t_k`` caused by
    an initial error of one prior standard deviation (:func:`baselines.rolling.priors.prior_sigma`) in each
    of the 45 error states (module notes).

    Parameters
    ----------
    scheme, lat, h, C0, coeffs, step_s :
        As in :func:`information_matrix`.

    Returns
    -------
    times : ndarray, shape (T,)
        ``t_k = k step_s``, k = 1 .. T, s.
    S : ndarray, shape (T, 3, 45)
        Sensitivity of outputs (X, Y, Z accelerometer) to each state, m/s^2 per prior sigma.
    """
    lat, h, C0, coeffs, step_s = _check_inputs(scheme, lat, h, C0, coeffs, step_s)
    t, S = _output_sensitivity(scheme, lat, h, C0, coeffs, step_s)
    return t, S * prior_sigma()
