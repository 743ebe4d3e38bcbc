"""Least-squares fit of the IEEE-952 noise terms to an Allan variance curve, and the Gauss-Markov bias that stands
for the fitted bias instability in the simulator's error model.

The model (IEEE Std 952-1997, annex C) of the Allan variance of a rate (rad/s or m/s^2) averaged over tau (s)::

    sigma^2(tau) = 3 Q^2 / tau^2 + N^2 / tau + (2 ln2 / pi) B^2 + K^2 tau / 3 + R^2 tau^2 / 2

with Q the quantisation noise (rad or m/s), N the angle or velocity random walk (rad/sqrt(s), m/s/sqrt(s)),
B the bias instability (rad/s, m/s^2; flicker noise of two-sided PSD B^2 / (2 pi f)), K the rate or acceleration
random walk (rad/s/sqrt(s), m/s^2/sqrt(s)) and R the rate ramp (rad/s^2, m/s^3). In a log-log plot of the
deviation each term is a straight line of slope -1, -1/2, 0, +1/2, +1 (:data:`SLOPES`).

The fit is linear in the squared coefficients ``c = (Q^2, N^2, B^2, K^2, R^2)``, which must not be negative
(an exact non-negative least squares over the subsets of the terms), and is a generalised least squares with the
covariance of the Allan variance estimates: each is chi-square distributed with ``edf`` equivalent degrees of
freedom (Greenhall's), so its standard deviation is ``sigma^2 sqrt(2 / edf)`` and long taus, resting on few
independent differences, weigh little; and estimates at neighbouring octaves share data, so they are correlated
(:func:`correlation`, from the model's spectrum: about 0.5 for white noise, 0.9 for a random walk). The standard
deviations use the *model's* variance, not the estimate's (which would favour the points that came out low), and
the degrees of freedom the noise type of the term that dominates the model at each tau; variances, noise types
and correlations are iterated to a fixed point.

Which terms are present: the subset of the five terms that minimises the deviance plus ``SIGNIFICANCE^2`` per
term (:func:`fit`), so that a term is kept only when it improves the likelihood as a 3-sigma likelihood-ratio test
asks; an absent term is reported as 0. The deviance is taken in log space (:func:`_log_deviance`), where a
chi-square estimate with few degrees of freedom is nearly Gaussian: in linear space its long upper tail makes a
chance rise of the last points look like a random walk or a ramp.

Uncertainty: the 1-sigma uncertainty of each present coefficient is from the generalised least-squares
covariance ``(A^T C^-1 A)^-1`` of the present terms, multiplied by the reduced chi-square when that exceeds one
(a model that does not fit the curve within its confidence intervals gets wider uncertainties); a coefficient's
uncertainty is that of its square halved relatively (``sd(X) = sd(X^2) / (2 X)``). On simulated records the
errors divided by these uncertainties have a standard deviation of about 0.85 to 1.2.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import digamma, polygamma

from fusionbench.recording.allan import AllanCurve, edf, with_noise_types

__all__ = ["TERMS", "SLOPES", "ALPHA", "FLICKER", "SIGNIFICANCE", "basis", "AllanFit", "fit", "rate_psd",
           "correlation", "gm_avar", "gm_peak", "gauss_markov"]

#: The noise terms, in the order of the model's columns.
TERMS = ("Q", "N", "B", "K", "R")
#: Log-log slope of each term's Allan deviation.
SLOPES = {"Q": -1.0, "N": -0.5, "B": 0.0, "K": 0.5, "R": 1.0}
#: Power-law noise type (rate PSD ~ f^alpha) of each term, for the degrees of freedom; a ramp is not a power-law
#: noise and counts as a random walk (the steepest type Greenhall's degrees of freedom cover).
ALPHA = {"Q": 2, "N": 0, "B": -1, "K": -2, "R": -2}
#: The flicker floor: Allan variance of bias instability B is FLICKER * B^2 (deviation 0.664 B).
FLICKER = 2.0 * math.log(2.0) / math.pi
#: A term is present when its squared coefficient is at least this many standard deviations above zero.
SIGNIFICANCE = 3.0
_ITERATIONS = 30
_TINY = np.finfo(float).tiny
#: Points per octave of the frequency grid of :func:`correlation`.
_PER_OCTAVE = 48


def basis(tau):
    """The model's columns at ``tau`` (M,) s: (M, 5) array, Allan variance per unit squared coefficient."""
    tau = np.asarray(tau, dtype=float)
    return np.column_stack([3.0 / tau ** 2, 1.0 / tau, np.full(tau.shape, FLICKER), tau / 3.0, tau ** 2 / 2.0])


@dataclass(frozen=True)
class AllanFit:
    """The fitted terms of one axis.

    Attributes
    ----------
    curve : AllanCurve
        The measured deviation, its confidence intervals for the noise types of the fitted model.
    coef : ndarray, shape (5,)
        Squared coefficients ``Q^2, N^2, B^2, K^2, R^2`` (SI squared), 0 for an absent term.
    cov : ndarray, shape (5, 5)
        Their covariance (zero rows and columns for absent terms).
    present : ndarray of bool, shape (5,)
        Which terms are significant.
    chi2 : float
        Generalised residual sum of squares of the Allan variance.
    dof : int
        Degrees of freedom of the fit (points less present terms).
    """

    curve: AllanCurve
    coef: np.ndarray
    cov: np.ndarray
    present: np.ndarray
    chi2: float
    dof: int

    def value(self, term):
        """Coefficient of ``term`` (one of :data:`TERMS`), SI; 0 when absent."""
        return float(np.sqrt(self.coef[TERMS.index(term)]))

    def sigma(self, term):
        """1-sigma uncertainty of :meth:`value`, SI; 0 when absent."""
        i = TERMS.index(term)
        return float(np.sqrt(self.cov[i, i]) / (2.0 * np.sqrt(self.coef[i]))) if self.present[i] else 0.0

    def is_present(self, term):
        """Whether ``term`` is significant."""
        return bool(self.present[TERMS.index(term)])

    def avar(self, tau):
        """The fitted Allan variance at ``tau`` (s), SI squared."""
        return basis(tau) @ self.coef

    def term_adev(self, term, tau):
        """The Allan deviation of ``term`` alone at ``tau`` (s), SI."""
        return np.sqrt(basis(tau)[:, TERMS.index(term)] * self.coef[TERMS.index(term)])

    @property
    def tau_floor(self):
        """Averaging time of the fitted deviation's minimum within the measured taus, s."""
        grid = np.geomspace(self.curve.tau[0], self.curve.tau[-1], 512)
        return float(grid[np.argmin(self.avar(grid))])


def rate_psd(f, coef, dt):
    """Two-sided PSD of the rate (SI^2/Hz) of the model with squared coefficients ``coef`` at ``f`` (Hz), for samples
    of interval ``dt``: ``4 Q^2 sin^2(pi f dt) / dt`` (white phase: a rounding error of variance Q^2 on each
    cumulative sample), ``N^2``, ``B^2 / (2 pi f)``, ``K^2 / (2 pi f)^2`` and ``R^2 / (2 pi f)^3`` (IEEE 952,
    annex C)."""
    f = np.asarray(f, dtype=float)
    w = 2.0 * np.pi * f
    return (coef[0] * 4.0 * np.sin(np.pi * f * dt) ** 2 / dt + coef[1] + coef[2] / w + coef[3] / w ** 2
            + coef[4] / w ** 3)


def _filter_gain(f, m, dt):
    """``|H(f)|^2`` of the Allan second difference at factor ``m`` applied to rate samples of interval ``dt``:
    ``4 dt^2 sin^4(pi f m dt) / sin^2(pi f dt)`` (the Allan variance is the integral over all f of the two-sided
    PSD times this gain, over ``2 tau^2``)."""
    return 4.0 * dt ** 2 * np.sin(np.pi * f * m * dt) ** 4 / np.sin(np.pi * f * dt) ** 2


class _Grid:
    """Frequencies, integration weights and filter gains of :func:`correlation` for one record."""

    def __init__(self, m, dt, n_phase):
        n = max(n_phase - 1, 4)
        lf = np.linspace(np.log(1.0 / (n * dt)), np.log(0.5 / dt), int(_PER_OCTAVE * np.log2(n / 2.0)) + 2)
        w = np.full(lf.size, lf[1] - lf[0])
        w[[0, -1]] *= 0.5  # trapezoid rule in log f
        self.f, self.dt = np.exp(lf), dt
        self.gw = np.array([_filter_gain(self.f, k, dt) for k in m]) * np.sqrt(w * self.f)

    def correlation(self, coef):
        g = self.gw * rate_psd(self.f, coef, self.dt)
        G = g @ g.T
        d = np.sqrt(np.diag(G))
        return G / np.outer(d, d)


def correlation(m, dt, n_phase, coef):
    """Correlation matrix (M, M) of the overlapping Allan variance estimates at factors ``m`` of one record of
    ``n_phase`` phase points and sample interval ``dt`` (s), for the model ``coef``.

    Two estimates are sums of squares of the same Gaussian data through two filters; for a record much longer
    than the filters their covariance is proportional to ``integral S(f)^2 |H_m(f)|^2 |H_m'(f)|^2 df`` (S the rate
    PSD, :func:`rate_psd`; H the two filters), integrated here on a geometric grid from the record's lowest
    frequency to Nyquist. Octave neighbours correlate by about 0.5 for white noise, 0.7 for flicker and 0.9 for a
    random walk.
    """
    return _Grid(m, dt, n_phase).correlation(coef)


def _dominant_alpha(A, coef):
    return np.array([ALPHA[TERMS[j]] for j in np.argmax(A * coef, axis=1)], dtype=int)


def _cholesky(a, model, edf, corr):
    """Lower Cholesky factor of the covariance of the Allan variance estimates ``a``: standard deviations
    ``model sqrt(2 / edf)``, correlations ``corr``."""
    sd = np.maximum(model, 1e-12 * a.max()) * np.sqrt(2.0 / edf)
    C = corr * np.outer(sd, sd)
    return np.linalg.cholesky(C + np.diag(1e-9 * np.diag(C)))


def _gls_nnls(A, a, L):
    """Non-negative generalised least squares of ``A x = a`` with covariance ``L L^T``, exactly: the best of the
    unconstrained solutions on every subset of the columns that comes out positive (at most 2^5 small solves;
    the optimum's non-zero entries are the unconstrained solution on its support)."""
    Aw = np.linalg.solve(L, A)
    aw = np.linalg.solve(L, a)
    norm = np.linalg.norm(Aw, axis=0)
    norm[norm == 0] = 1.0
    Aw = Aw / norm
    x, *_ = np.linalg.lstsq(Aw, aw, rcond=None)
    if np.all(x > 0):  # the unconstrained optimum is feasible: it is the answer
        return x / norm
    best, best_cost = np.zeros(A.shape[1]), float(aw @ aw)
    for k in range(1, A.shape[1]):
        for cols in itertools.combinations(range(A.shape[1]), k):
            x, *_ = np.linalg.lstsq(Aw[:, cols], aw, rcond=None)
            if np.all(x > 0):
                r = aw - Aw[:, cols] @ x
                if r @ r < best_cost:
                    best, best_cost = np.zeros(A.shape[1]), float(r @ r)
                    best[list(cols)] = x
    return best / norm


def _log_deviance(a, model, nu, corr):
    """``-2 log`` likelihood (up to a constant) of the Allan variance estimates ``a`` under the model ``model``, in
    log space: ``log(a / model)`` is the log of a chi-square over its ``nu`` degrees of freedom, mean
    ``psi(nu/2) - log(nu/2)`` and variance ``psi'(nu/2)`` whatever the model (psi the digamma function), and
    nearly Gaussian where the chi-square itself has a long upper tail (few degrees of freedom, long taus);
    correlated as the estimates are."""
    r = np.log(np.maximum(a, _TINY) / np.maximum(model, _TINY)) - (digamma(nu / 2.0) - np.log(nu / 2.0))
    sd = np.sqrt(polygamma(1, nu / 2.0))
    L = np.linalg.cholesky(corr * np.outer(sd, sd) + np.diag(1e-9 * sd ** 2))
    z = np.linalg.solve(L, r)
    return float(z @ z + 2.0 * np.sum(np.log(np.diag(L))))


def _fit_terms(curve, grid, A, active):
    """Fit the terms ``active`` (bool (5,)), iterating the covariance of the Allan variance estimates (model
    variances, noise types, correlations) to a fixed point: ``(deviance, coef, alpha, L)`` with ``L L^T`` that
    covariance and the deviance of :func:`_log_deviance`."""
    a = curve.avar
    model, corr, alpha, dof = a.copy(), np.eye(a.size), curve.alpha, curve.edf
    coef = np.zeros(len(TERMS))
    for _ in range(_ITERATIONS):
        new = np.zeros(len(TERMS))
        new[active] = _gls_nnls(A[:, active], a, _cholesky(a, model, dof, corr))
        done = np.allclose(new, coef, rtol=1e-5, atol=0)
        coef, model = new, A @ new
        if not np.any(coef > 0):
            break
        new_alpha = _dominant_alpha(A, coef)
        if not np.array_equal(new_alpha, alpha):
            alpha, dof, done = new_alpha, edf(curve.m, curve.n_phase, new_alpha), False
        corr = grid.correlation(coef)
        if done:
            break
    return _log_deviance(a, model, dof, corr), coef, alpha, _cholesky(a, model, dof, corr)


def fit(curve: AllanCurve, dt):
    """Fit the IEEE-952 terms to ``curve`` of a record of sample interval ``dt`` (s); see the module's description.

    The terms are the subset of the five that minimises the deviance plus ``SIGNIFICANCE^2`` per term: between
    two nested subsets the larger wins only when its extra term lowers the deviance by ``SIGNIFICANCE^2``, a
    likelihood-ratio test of one parameter at ``SIGNIFICANCE`` sigma. The deviance, not a coefficient's z-score,
    decides, because the covariance depends on the model: a steep term predicts large variances at long taus and
    so looks insignificant in its own covariance, however badly the model fits without it.

    Returns
    -------
    AllanFit
        Every term's squared coefficient and covariance, which terms are present.
    """
    A = basis(curve.tau)
    n = len(TERMS)
    if not np.any(curve.avar > 0):  # a noiseless axis: nothing to fit
        return AllanFit(curve, np.zeros(n), np.zeros((n, n)), np.zeros(n, bool), 0.0, int(curve.tau.size))
    grid = _Grid(curve.m, dt, curve.n_phase)
    best, best_score = None, np.inf
    for k in range(1, len(TERMS) + 1):
        for cols in itertools.combinations(range(len(TERMS)), k):
            active = np.isin(np.arange(len(TERMS)), cols)
            trial = _fit_terms(curve, grid, A, active)
            if np.all(trial[1][active] > 0) and trial[0] + SIGNIFICANCE ** 2 * k < best_score:
                best, best_score = trial, trial[0] + SIGNIFICANCE ** 2 * k
    _, coef, alpha, L = best if best is not None else _fit_terms(curve, grid, A, np.zeros(len(TERMS), bool))
    a = curve.avar
    present = coef > 0
    Aw = np.linalg.solve(L, A[:, present])
    r = np.linalg.solve(L, a - A @ coef)
    chi2, dof = float(r @ r), int(a.size - present.sum())
    cov = np.zeros((len(TERMS), len(TERMS)))
    if present.any():
        norm = np.linalg.norm(Aw, axis=0)
        inv = np.linalg.pinv((Aw / norm).T @ (Aw / norm)) / np.outer(norm, norm)
        cov[np.ix_(present, present)] = inv * max(1.0, chi2 / dof if dof > 0 else 1.0)
    return AllanFit(with_noise_types(curve, alpha), coef, cov, present, chi2, dof)


def gm_avar(x):
    """Allan variance of a unit-variance first-order Gauss-Markov rate of correlation time T at tau = x T:
    ``2 / x - (3 - 4 exp(-x) + exp(-2 x)) / x^2`` (from its structure function ``D(u) = 2 (T u - T^2 (1 -
    exp(-u / T)))``, Allan variance ``(4 D(tau) - D(2 tau)) / (2 tau^2)``)."""
    x = np.asarray(x, dtype=float)
    return 2.0 / x - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / x ** 2


@lru_cache(maxsize=1)
def gm_peak():
    """``(x_peak, adev_peak)``: where a unit-variance Gauss-Markov's Allan deviation peaks, in units of its
    correlation time, and the peak deviation (maximised from :func:`gm_avar`; about 1.89 and 0.62)."""
    res = minimize_scalar(lambda x: -gm_avar(x), bounds=(0.1, 10.0), method="bounded", options={"xatol": 1e-10})
    return float(res.x), float(np.sqrt(-res.fun))


def gauss_markov(b, tau_floor):
    """The first-order Gauss-Markov bias ``(sigma, T)`` that stands for a bias instability ``b`` (rad/s or m/s^2)
    whose flicker floor ends at ``tau_floor`` (s): its Allan deviation peaks at ``tau_floor`` (``T = tau_floor /
    x_peak``) with the flicker floor's height ``sqrt(FLICKER) b = 0.664 b`` (``sigma = 0.664 b / adev_peak``)."""
    x_peak, adev_peak = gm_peak()
    return math.sqrt(FLICKER) * b / adev_peak, tau_floor / x_peak
