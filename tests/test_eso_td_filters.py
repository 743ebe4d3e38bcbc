"""The ESO/TD aligner's filters on their own: the printed ESO (eq. 6) and fst TD (eq. 15) against their derived
ramp lags and sinusoid bounds, the default's expanding-memory ESO and least-squares TD against the least-squares line.
"""

import numpy as np
import pytest

from adrc.eso_td_estimator import expanding_memory_gains
from adrc.ls_differentiator import LeastSquaresDifferentiator
from adrc.moving_base import ESOTDAligner
from adrc.primitives import FSTTrackingDifferentiator, SecondOrderESO, fst


def _eso_steady_ratio(h, b1, b2, w):
    """|z2 - x'| / |x'| in steady state for x' = sin(w t): s_k = A s_{k-1} + B y_k (eq. 6, alpha = 1)
    with y_k = x(k h) = Y e^{j w k h}, Y = 1 / (j w), gives S = (I - e^{-j w h} A)^-1 B Y."""
    A = np.array([[1 - h * b1, h], [-h * b2, 1.0]])
    B = np.array([h * b1, h * b2])
    S = np.linalg.solve(np.eye(2) - np.exp(-1j * w * h) * A, B) / (1j * w)
    return abs(S[1] - 1.0)


def test_eso_tracks_a_ramp_with_the_derived_lag_and_a_sinusoid_within_the_derived_bound():
    h, b1, b2 = 0.1, 0.6, 0.08
    # ramp disturbance x' = b + d t (y = x = b t + d t^2 / 2): steady state of eq. 6,
    # e1 = -d / beta2 and z2 after the update at t_k = x'(t_k) + d (3h/2 - beta1 / beta2)
    b, d = 0.05, 2e-4
    eso = SecondOrderESO((1,), h, b1, b2, alpha=1.0, delta=2 * h)
    t = np.arange(3000) * h
    eso.reset(0.0)
    for k in range(t.size):
        _, z2 = eso.update(b * t[k] + d * t[k] ** 2 / 2)
    assert z2[0] - (b + d * t[-1]) == pytest.approx(d * (1.5 * h - b1 / b2), rel=1e-6)
    # the same, referred to the next sample as SecondOrderESO.steady_lag (used by the feedback) states it
    e1, e2 = eso.steady_lag(d)
    assert z2[0] - (b + d * (t[-1] + h)) == pytest.approx(e2[()], rel=1e-6)
    t_next = t[-1] + h
    assert eso.z1[0] - (b * t_next + d * t_next**2 / 2) == pytest.approx(e1[()], rel=1e-6)
    # sinusoidal disturbance x' = A sin(w t), period 300 s: error amplitude ratio from the discrete
    # transfer function (continuous: |1 - G(jw)| ~ w beta1 / beta2 = 0.157)
    Amp, w = 0.05, 2 * np.pi / 300
    ratio = _eso_steady_ratio(h, b1, b2, w)
    assert ratio == pytest.approx(abs(1 - b2 / (-w * w + 1j * w * b1 + b2)), rel=0.02)
    eso = SecondOrderESO((1,), h, b1, b2, alpha=1.0, delta=2 * h)
    t = np.arange(12000) * h
    y = Amp * (1 - np.cos(w * t)) / w
    err = np.empty(t.size)
    for k in range(t.size):
        _, z2 = eso.update(y[k])
        err[k] = z2[0] - Amp * np.sin(w * t[k])
    late = np.abs(err[t > 600])  # the slowest mode (5 s) is long gone
    assert late.max() <= ratio * Amp * (1 + 1e-4)
    assert late.max() >= 0.99 * ratio * Amp


def _td_steady_ratio(h, h1, w):
    """|x2 - v'| / |v'| in steady state for v = sin(w t), TD eq. 15 in its linear zone:
    x_k = F x_{k-1} + G v_k, F = [[1, h], [-h / h1^2, 1 - 2h / h1]], G = [0, h / h1^2]."""
    F = np.array([[1.0, h], [-h / h1**2, 1 - 2 * h / h1]])
    G = np.array([0.0, h / h1**2])
    S = np.linalg.solve(np.eye(2) - np.exp(-1j * w * h) * F, G)
    return abs(S[1] / (1j * w) - 1.0)


@pytest.mark.parametrize("h1", [0.5, 20.0])
def test_fst_td_differentiates_a_ramp_exactly_and_a_sinusoid_within_the_derived_bound(h1):
    h, r = 0.1, 500.0
    # ramp v = a t: linear zone (|y| < h1^2 r), steady state of eq. 15: x2 = a and, after the update
    # at t_k, x1 = v(t_k) - (2 h1 - h) a
    a = 3e-4
    td = FSTTrackingDifferentiator((1,), h, r, h1)
    n = int(30 * h1 / h) + 200
    for k in range(n):
        x1, x2 = td.update(a * k * h)
    assert x2[0] == pytest.approx(a, rel=1e-9)
    assert x1[0] - a * (n - 1) * h == pytest.approx(-(2 * h1 - h) * a, rel=1e-6)
    # sinusoid: the linear filter 1 / (1 + h1 s)^2 on the derivative, discretised (the continuous
    # form is only close for h << h1)
    Amp, w = 0.01, 2 * np.pi / (60 * h1)
    ratio = _td_steady_ratio(h, h1, w)
    if h1 >= 20 * h:
        assert ratio == pytest.approx(abs(1 / (1 + 1j * w * h1) ** 2 - 1), rel=0.02)
    td = FSTTrackingDifferentiator((1,), h, r, h1)
    t = np.arange(int(200 * h1 / h)) * h
    err = np.empty(t.size)
    for k in range(t.size):
        _, x2 = td.update(Amp * np.sin(w * t[k]))
        err[k] = x2[0] - Amp * w * np.cos(w * t[k])
    late = np.abs(err[t > 40 * h1])
    assert late.max() <= ratio * Amp * w * (1 + 1e-3)
    assert late.max() >= 0.98 * ratio * Amp * w


@pytest.mark.parametrize("V", [1e3, 1e4])
def test_fst_td_crosses_a_large_step_with_bounded_acceleration_and_no_overshoot(V):
    h, r, h1 = 0.1, 500.0, 0.5  # the paper's TD; V beyond the linear zone h1^2 r = 125
    td = FSTTrackingDifferentiator((1,), h, r, h1)
    x1s, x2s = [], []
    for _ in range(300):
        assert abs(fst(td.x1, td.x2, V, r, h1)[0]) <= r * (1 + 1e-12)  # |x2'| <= r
        x1, x2 = td.update(V)
        x1s.append(x1[0])
        x2s.append(x2[0])
    x1s, x2s = np.array(x1s), np.array(x2s)
    assert x2s.max() <= np.sqrt(r * V)  # the bang-bang peak rate of a time-optimal crossing
    assert x1s.max() <= V * (1 + 1e-12)  # no overshoot
    # the time-optimal crossing 2 sqrt(V / r) plus the linear zone's tail of a few h1
    settled = np.nonzero(np.abs(x1s - V) > 1e-3 * V)[0][-1] * h + h
    assert settled <= 2 * np.sqrt(V / r) + 6 * h1


# ------------------------------------------------------------------------------ the default configuration
def test_an_eso_with_expanding_memory_gains_is_the_least_squares_line():
    # eq. 6 with beta1 = (g + g') / h, beta2 = g' / h^2 (Morrison's expanding memory) is the least-squares
    # line through every sample so far: z2 its slope, z1 its value one step ahead
    h, n = 0.1, 120
    rng = np.random.default_rng(1)
    t = np.arange(n) * h
    y = 0.3 + 0.05 * t + 0.01 * t**2 + 0.02 * rng.standard_normal(n)
    eso = SecondOrderESO((1,), h, 1.0, 1.0)
    eso.reset(y[0])
    for k in range(n):
        eso.beta1, eso.beta2 = (np.asarray(g) for g in expanding_memory_gains(k, h))
        z1, z2 = eso.update(y[k])
        if k >= 1:
            b, a = np.polyfit(t[:k + 1], y[:k + 1], 1)
            assert z2[0] == pytest.approx(b, rel=1e-9, abs=1e-12)
            assert z1[0] == pytest.approx(a + b * (t[k] + h), rel=1e-9)
    # the gains fall as 4 / t and 6 / t^2: the default floor (0.1, 0.0025) is reached at sqrt(6) / 0.05 s
    assert ESOTDAligner().eso_floor_s == pytest.approx(np.sqrt(6) / 0.05, abs=0.1)


def test_the_least_squares_differentiator_fits_a_line_and_moves_with_it():
    rng = np.random.default_rng(2)
    X = np.cumsum(rng.uniform(0.5, 1.5, 50))
    Y = 2.0 - 0.3 * X + 0.01 * rng.standard_normal(50)
    td = LeastSquaresDifferentiator((1,))
    for x, y in zip(X[:30], Y[:30]):
        td.add(np.array([x]), np.array([y]))
    b, a = np.polyfit(X[:30], Y[:30], 1)
    value, slope = td.fit(np.array([X[29]]))
    assert slope[0] == pytest.approx(b, rel=1e-9) and value[0] == pytest.approx(a + b * X[29], rel=1e-9)
    # a correction changes the data from now on by a line (value dv at X[29], slope ds): shifting the past by
    # the same line makes the fit that of the corrected data throughout
    dv, ds = 0.05, 0.1
    td.shift(np.array([dv]), np.array([ds]), np.array([X[29]]))
    Y2 = Y + dv + ds * (X - X[29])
    for x, y in zip(X[30:], Y2[30:]):
        td.add(np.array([x]), np.array([y]))
    b2, a2 = np.polyfit(X, Y2, 1)
    value, slope = td.fit(np.array([X[-1]]))
    assert slope[0] == pytest.approx(b2, rel=1e-9) and value[0] == pytest.approx(a2 + b2 * X[-1], rel=1e-9)
