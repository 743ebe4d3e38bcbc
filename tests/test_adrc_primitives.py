"""Han's ADRC primitives (seed 000, eqs. 7-11) against closed-form behaviour."""

import numpy as np
import pytest

from adrc.primitives import ExtendedStateObserver, TrackingDifferentiator, fal, fhan, nlsef


@pytest.mark.parametrize("x0", [1.0, -0.3, 2.0])
def test_fhan_brings_a_double_integrator_to_rest_in_finite_steps(x0):
    r, h = 10.0, 0.01

    def run(h0):
        x1, x2, steps, overshoot = x0, 0.0, 0, 0.0
        while steps < 2000 and (abs(x1) > 1e-12 or abs(x2) > 1e-12):
            u = fhan(x1, x2, r, h0)
            assert abs(u) <= r * (1 + 1e-12)  # the acceleration bound holds
            x1, x2 = x1 + h * x2, x2 + h * u
            overshoot = max(overshoot, -np.sign(x0) * x1)
            steps += 1
        return steps, overshoot

    # h0 = h: Han's discrete time-optimal synthesis, at rest in about the continuous optimum
    # 2 sqrt(|x0| / r) (plus a few steps), with at most one step's travel r h^2 past the origin
    steps, overshoot = run(h)
    assert steps * h <= 2 * np.sqrt(abs(x0) / r) + 5 * h
    assert overshoot <= r * h * h
    # h0 = 2 h (the usual choice against chattering): no overshoot at all, still finite time
    steps, overshoot = run(2 * h)
    assert overshoot == 0.0 and steps < 2000


def test_fhan_is_odd_and_zero_at_the_origin():
    x1 = np.linspace(-2, 2, 9)
    x2 = np.linspace(1, -1, 9)
    assert fhan(x1, x2, 3.0, 0.1) == pytest.approx(-fhan(-x1, -x2, 3.0, 0.1), abs=1e-15)
    assert fhan(0.0, 0.0, 3.0, 0.1) == 0.0


def test_fal_is_linear_inside_delta_and_a_power_outside():
    assert fal(0.01, 0.5, 0.04) == pytest.approx(0.01 / 0.04**0.5)
    assert fal(-9.0, 0.5, 0.04) == pytest.approx(-3.0)
    assert fal(0.04, 0.25, 0.04) == pytest.approx(0.04**0.25)  # continuous at |e| = delta


def test_td_follows_a_step_and_differentiates_a_ramp():
    td = TrackingDifferentiator((1,), h=0.01, r0=100.0, h0=0.01)
    for _ in range(200):
        v1, v2 = td.update(1.0)
    assert v1[0] == pytest.approx(1.0, abs=1e-9) and v2[0] == pytest.approx(0.0, abs=1e-9)
    td = TrackingDifferentiator((1,), h=0.01, r0=100.0, h0=0.01)
    for k in range(500):
        v1, v2 = td.update(0.3 * k * 0.01)
    assert v2[0] == pytest.approx(0.3, rel=1e-3)


def test_td_started_at_rest_on_a_zero_reference_stays_at_zero():
    # the gyrocompass's level channels track a zero velocity error: their TD would output v1 = v2 = 0
    # for ever, which is why adrc.gyrocompass does not evaluate it
    td = TrackingDifferentiator((3, 2), h=0.02, r0=2500.0, h0=0.02)
    for _ in range(1000):
        v1, v2 = td.update(0.0)
    assert not v1.any() and not v2.any()


def _linear_eso_error_gain(h, b1, b2, b3, w):
    """|f - z3| / |f| in steady state for f = sin(w t), from the discrete ESO's transfer function.

    The plant x'' = f sampled exactly gives y = -f / w^2 at the samples; the linear ESO is
    z+ = A z + B y (e = z1 - y), so z3 = C (zI - A)^-1 B y with z = exp(j w h)."""
    A = np.array([[1 - h * b1, h, 0], [-h * b2, 1, h], [-h * b3, 0, 1]])
    B = np.array([h * b1, h * b2, h * b3])
    H = np.linalg.solve(np.exp(1j * w * h) * np.eye(3) - A, B)[2]
    return abs(1 + H / w**2)


def test_eso_tracks_a_sinusoidal_disturbance_within_the_derived_bound():
    h, w0, delta = 0.001, 50.0, 1e4
    b1, b2, b3 = 3 * w0, 3 * w0**2, w0**3  # bandwidth parametrisation of the linear ESO
    # eq. 9 with |e| << delta: fal is linear, fe = e / delta^0.5, fe1 = e / delta^0.75
    eso = ExtendedStateObserver((1,), h, b1, b2 * delta**0.5, b3 * delta**0.75, delta, b0=1.0)
    w = 2 * np.pi * 0.2
    t = np.arange(30000) * h
    y = -np.sin(w * t) / w**2  # x'' = sin(w t) with x(0) = 0, x'(0) = -1/w
    err = []
    for k in range(t.size):
        _, _, z3 = eso.update(y[k], 0.0)
        err.append(np.sin(w * t[k]) - z3[0])
    err = np.abs(np.array(err[15000:]))  # after the transient (time constant 1/w0 = 0.02 s)
    bound = _linear_eso_error_gain(h, b1, b2, b3, w)
    # about 3 w / w0 for w << w0: 7.5 % of the disturbance amplitude here
    assert bound == pytest.approx(3 * w / w0, rel=0.05)
    assert err.max() == pytest.approx(bound, rel=0.05)


def test_printed_eq11_is_unstable_for_negative_b0_and_the_sign_fix_is_stable():
    g, h = 9.8, 0.02

    def run(fix):
        b0 = -g
        eso = ExtendedStateObserver((1,), h, 1 / h, 1 / (3 * h**2), 1 / (18**2 * h**3), 20000.0, b0)
        x, xd, u = 0.1, 0.0, np.zeros(1)
        for _ in range(15000):
            z1, z2, z3 = eso.update(np.array([x]), u)
            u = nlsef(-z1, -z2, z3, np.array([b0]), 1 / h, 10 * h, 0.8) if fix else \
                -fhan(-z1, -z2, 1 / h, 10 * h, 0.8) - z3 / b0
            xd += h * (b0 * u[0] + 0.01)  # plant x'' = f + b u with a constant disturbance
            x += h * xd
            if abs(x) > 1e6:
                return np.inf
        return abs(x)

    # the corrected law settles (300 s, the printed slow ESO included); the printed one runs away
    assert run(fix=True) < 1e-4
    assert run(fix=False) == np.inf
