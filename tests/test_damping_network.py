"""Seed 004's damping network (eqs. 1-10): closed-form properties against scipy.signal computations."""

import numpy as np
import pytest
from scipy import signal
from scipy.optimize import minimize_scalar

from damping import network as N
from fusionbench.simulation import earth


@pytest.mark.parametrize("q", [1.5, 3.0, 8.0])
def test_network_is_one_at_zero_and_infinite_frequency(q):
    H = N.network(q)
    _, r = signal.freqresp(H, [1e-9, 1e6])
    assert np.abs(r) == pytest.approx([1.0, 1.0], abs=1e-6)
    assert H.num[0] / H.den[0] == pytest.approx(1.0)  # leading coefficients: H(inf) = 1 exactly


@pytest.mark.parametrize("q", [1.5, 2.0, 4.0, 8.0])
def test_phase_of_the_network_peaks_at_the_crossover(q):
    H = N.network(q)  # the frequency of H's largest phase lead, found numerically
    res = minimize_scalar(lambda lw: -np.angle(signal.freqresp(H, [10**lw])[1][0]),
                          bounds=(np.log10(N.WS) - 3, np.log10(N.WS) + 3), method="bounded", options={"xatol": 1e-10})
    assert 10**res.x == pytest.approx(N.crossover(q), rel=1e-6)
    # and the crossover is where the damped loop's asymptote q T ws^2 / s crosses 0 dB
    assert N.crossover(q) == pytest.approx(q * N.time_constant(q) * N.WS**2, rel=1e-12)


def test_printed_phase_peak_formula_holds_only_near_q_3():
    assert N.printed_phase_peak_x(3.0) == pytest.approx(N.phase_peak_x(3.0), rel=0.015)
    assert N.printed_phase_peak_x(8.0) < 0.75 * N.phase_peak_x(8.0)


def test_undamped_loop_oscillates_with_the_schuler_period():
    # q = 1: H = 1, eq. 1 is s / (s^2 + ws^2): a gyro step gives sin(ws t) / ws, amplitude 1 / ws
    t = np.arange(0.0, 6 * 3600.0, 1.0)
    _, y, _ = signal.lsim(N.gyro_to_attitude(1.0), np.ones_like(t), t)
    up = np.nonzero((y[:-1] < 0) & (y[1:] >= 0))[0]
    period = np.diff(t[up]).mean()
    assert period / 60 == pytest.approx(2 * np.pi / N.WS / 60, abs=0.05)
    assert period / 60 == pytest.approx(84.4, abs=0.1)
    assert np.abs(y).max() == pytest.approx(1 / N.WS, rel=1e-3)


@pytest.mark.parametrize("q", [2.0, 4.0, 8.0])
def test_damping_ratio_two_ways_against_the_papers_fit(q):
    xi_peak, xi_poles = N.damping_from_peak(q), N.damping_from_poles(q)
    assert 0 < xi_peak <= xi_poles < 1
    # the fit xi = 0.09 (q - 1) overestimates: by about 60 % at q = 2, 10 % at q = 8 (pole pair)
    assert N.paper_fit(q) > xi_poles
    assert xi_poles / N.paper_fit(q) == pytest.approx({2.0: 0.64, 4.0: 0.91, 8.0: 0.90}[q], abs=0.03)


@pytest.mark.parametrize("xi", [0.1, 0.3, 0.5])
def test_closed_form_peak_error_matches_the_second_order_simulation(xi):
    # eq. 10 is the exact peak of eq. 8's second-order loop for a step of acceleration
    a, ws = 0.05, N.WS
    g = float(earth.gravity(np.radians(35.0)))
    R = g / ws**2
    sys = signal.TransferFunction([-2 * xi / ws / R, 0.0], [1.0, 2 * xi * ws, ws**2])  # eq. 8, input: the acceleration
    t = np.arange(0.0, 6 * 3600.0, 1.0)
    _, y, _ = signal.lsim(sys, np.full(t.size, a), t)
    assert N.peak_attitude_error(a, xi, g=g) == pytest.approx(np.abs(y).max(), rel=2e-3)


def test_closed_form_underestimates_the_error_of_the_actual_network():
    # with the actual H(s) in eq. 2 (and xi from the least-damped poles) eq. 10 is 11-38 % low
    for q, ratio in ((2.0, 0.62), (3.0, 0.72), (6.5, 0.89)):
        cf = N.peak_attitude_error(0.05, N.damping_from_poles(q))
        assert cf / N.simulated_peak_error(0.05, q) == pytest.approx(ratio, abs=0.02)
