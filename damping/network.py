"""The continuously adjustable damping network of seed 004 (Gu, Wang, Zheng, Zhao 2017), eqs. 1-10.

North level loop of a strapdown attitude system (eq. 1, Fig. 1): with the damping network H(s)
in the loop, the attitude error responds to the east gyro error and to the vehicle's acceleration::

    da / eps_E  = s / (s^2 + H(s) ws^2)                     (eq. 1)
    da / dV_N   = (1 - H(s)) / (s^2 + H(s) ws^2) / R        (eq. 2, dV_N the acceleration)

with ws = sqrt(g / R) the Schuler frequency (rad/s). The network (eqs. 3, 7)::

    H(s) = (q T s + 1)(T s / q + 1) / (T s + 1)^2,    1 <= q <= 8

has H(0) = H(inf) = 1 (no steady error, no high-frequency effect) and a phase lead that must peak at
the loop's crossover wc (eq. 5). Its peak lies at wc T = x*(q), the root of
dphi/dx = 0 (:func:`phase_peak_x`); the paper's printed closed form
X^(1/4) / q^(3/4), X = (q + 1)(q - sqrt(q^2 + 1)) + 1, is that root only near q = 3 and is not used.
The paper places wc at the crossover of the damped loop's asymptotes, wc = q T ws^2; the two
relations fix T and wc for each q: ``T = sqrt(x* / q) / ws``, ``wc = sqrt(q x*) ws``.

Damping ratio of the closed loop (open loop H ws^2 / s^2), two ways: from the resonant peak of
the closed loop H ws^2 / (s^2 + H ws^2), Mr = 1 / (2 xi sqrt(1 - xi^2)), as the paper does, and
from the least-damped pole pair. The paper fits xi = 0.09 (q - 1) (eq. 6).

Acceleration error (eqs. 8-10): with the loop approximated by a second-order system of damping xi,
a step of acceleration a gives da(t) = -2 a xi exp(-xi ws t) sin(wd t) / (g sqrt(1 - xi^2)),
wd = ws sqrt(1 - xi^2), whose largest magnitude is 2 a xi exp(-xi ws t*) / g at
t* = atan(sqrt(1 - xi^2) / xi) / wd.

Units: rad, rad/s, s, m/s^2.
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.optimize import brentq

from fusionbench.simulation import earth

#: Schuler frequency at the paper's latitude (35 deg), rad/s.
WS = float(earth.schuler_frequency(np.radians(35.0)))


def phase_peak_x(q):
    """x* = wc T at which the phase of H peaks: the root of
    q / (1 + q^2 x^2) + (1/q) / (1 + x^2 / q^2) = 2 / (1 + x^2)  (q > 1; 1/sqrt(3)... for q -> 1)."""
    q = float(q)
    if q <= 1.0:
        return 1.0 / np.sqrt(3.0)
    f = lambda x: q / (1 + q * q * x * x) + (1 / q) / (1 + x * x / (q * q)) - 2 / (1 + x * x)  # noqa: E731
    return brentq(f, 1e-9, 1.0)


def printed_phase_peak_x(q):
    """The paper's printed closed form for wc T: ((q + 1)(q - sqrt(q^2 + 1)) + 1)^(1/4) / q^(3/4).

    Not used by the navigator: it matches the true phase peak (:func:`phase_peak_x`) only near q = 3 (1 %
    there); it is 29 % high at q = 1.5 and 27 % low at q = 8. Kept as documented API, the paper's formula
    as printed, so that the reproduction check of that claim (``tests/test_damping_network.py``) reads it here."""
    q = float(q)
    X = (q + 1) * (q - np.sqrt(q * q + 1)) + 1
    return X**0.25 / q**0.75


def time_constant(q, ws=WS):
    """Network time constant T (s) for coefficient q, with wc at the loop's crossover (module docstring)."""
    return np.sqrt(phase_peak_x(q) / q) / ws


def crossover(q, ws=WS):
    """Crossover frequency wc (rad/s) = q T ws^2 = frequency of the network's largest phase lead (eq. 5).

    Documented API for the paper's closed-form relation; the navigator uses :func:`time_constant`, and
    ``tests/test_damping_network.py`` checks this frequency against the numerically found peak of H's phase."""
    return q * time_constant(q, ws) * ws**2


def network(q, ws=WS):
    """H(s) as a :class:`scipy.signal.TransferFunction` (eq. 3)."""
    T = time_constant(q, ws)
    num = np.polymul([q * T, 1.0], [T / q, 1.0])
    den = np.polymul([T, 1.0], [T, 1.0])
    return signal.TransferFunction(num, den)


def _polys(q, ws):
    H = network(q, ws)
    num, den = H.num, H.den
    char = np.polyadd(np.polymul([1.0, 0.0, 0.0], den), ws**2 * num)  # den (s^2 + H ws^2)
    return num, den, char


def closed_loop(q, ws=WS):
    """Closed loop H ws^2 / (s^2 + H ws^2) (the complementary sensitivity), a TransferFunction."""
    num, _, char = _polys(q, ws)
    return signal.TransferFunction(ws**2 * num, char)


def gyro_to_attitude(q, ws=WS):
    """da / eps_E = s / (s^2 + H ws^2) (eq. 1), rad per rad/s.

    Documented API, the paper's eq. 1 as a transfer function (the navigator's loop is the strapdown's own;
    ``tests/test_damping_network.py`` checks the undamped loop's Schuler period through it)."""
    _, den, char = _polys(q, ws)
    return signal.TransferFunction(np.polymul([1.0, 0.0], den), char)


def accel_to_attitude(q, ws=WS, radius=None):
    """da / dV_N = (1 - H) / (s^2 + H ws^2) / R (eq. 2), rad per m/s^2; R = g / ws^2 by default."""
    _, _, char = _polys(q, ws)
    R = earth.gravity(np.radians(35.0)) / ws**2 if radius is None else radius
    T = time_constant(q, ws)
    # (1 - H) (T s + 1)^2 = (T s + 1)^2 - (q T s + 1)(T s / q + 1) = -T (q - 1)^2 / q s exactly;
    # char is normalised by T^2 (scipy's monic denominator of H), so the numerator is too
    return signal.TransferFunction([-(q - 1) ** 2 / (q * T) / R, 0.0], char)


def damping_from_peak(q, ws=WS):
    """Damping ratio from the closed loop's resonant peak Mr = 1 / (2 xi sqrt(1 - xi^2)) (the paper's way).

    Returns 1/sqrt(2) or more (reported as such) when there is no peak above 1 (Mr <= 1)."""
    cl = closed_loop(q, ws)
    w = np.logspace(np.log10(ws) - 2, np.log10(ws) + 2, 4000)
    _, resp = signal.freqresp(cl, w)
    mr = float(np.max(np.abs(resp)))
    if mr <= 1.0:
        return np.sqrt(0.5)
    return brentq(lambda x: 1 / (2 * x * np.sqrt(1 - x * x)) - mr, 1e-9, np.sqrt(0.5))


def damping_from_poles(q, ws=WS):
    """Damping ratio of the closed loop's least-damped complex pole pair (or 1 if all poles are real)."""
    poles = np.roots(_polys(q, ws)[2])
    cplx = poles[np.abs(poles.imag) > 1e-12 * np.abs(poles).max()]
    if cplx.size == 0:
        return 1.0
    return float(np.min(-cplx.real / np.abs(cplx)))


def paper_fit(q):
    """Seed 004's fit xi = 0.09 (q - 1), eq. 6."""
    return 0.09 * (np.asarray(q, dtype=float) - 1.0)


def peak_attitude_error(accel, xi, ws=WS, g=None):
    """Largest abs(attitude error) (rad) from a step of acceleration ``accel`` (m/s^2), eq. 10."""
    g = float(earth.gravity(np.radians(35.0))) if g is None else g
    xi = np.asarray(xi, dtype=float)
    t = np.arctan(np.sqrt(1 - xi**2) / xi) / (ws * np.sqrt(1 - xi**2))
    return 2 * np.asarray(accel) * xi * np.exp(-xi * ws * t) / g


def simulated_peak_error(accel, q, ws=WS, hours=3.0):
    """Largest abs(attitude error) (rad) of eq. 2 with the actual H(s) for a step of acceleration,
    by :func:`scipy.signal.lsim` (1 s steps)."""
    if q <= 1.0:  # H = 1: the Schuler-tuned loop has no acceleration error at all (eq. 2)
        return 0.0
    t = np.arange(0.0, hours * 3600.0, 1.0)
    _, y, _ = signal.lsim(accel_to_attitude(q, ws), np.full(t.size, float(accel)), t)
    return float(np.max(np.abs(y)))


def gain(q):
    """k(q) = (q - 1)^2 / q, the weight of the lag difference in the realisation of H (see :func:`state_space`)."""
    q = np.asarray(q, dtype=float)
    return (q - 1.0) ** 2 / q


def state_space(q, ws=WS):
    """H(s) realised as two equal first-order lags, a :class:`scipy.signal.StateSpace`.

    With x1 = u / (T s + 1) and x2 = x1 / (T s + 1) (states in the input's units, e.g. m/s),
    ``H u = u + k (x1 - x2)``, k = (q - 1)^2 / q, because
    H(s) - 1 = T (q + 1/q - 2) s / (T s + 1)^2 = k T s / (T s + 1)^2 and x1 - x2 = T s u / (T s + 1)^2.
    The states are lagged copies of the input whatever q is, so q can change from one step to
    the next without the states jumping (only the output weight k changes); at q = 1 the output is
    the input (H = 1).
    """
    T = time_constant(q, ws)
    k = float(gain(q))
    A = np.array([[-1.0 / T, 0.0], [1.0 / T, -1.0 / T]])
    B = np.array([[1.0 / T], [0.0]])
    return signal.StateSpace(A, B, np.array([[k, -k]]), np.array([[1.0]]))


class DiscreteNetwork:
    """The lag realisation of H (:func:`state_space`) discretised for a step ``dt`` (s) on a grid of q,
    so that q may change at every step.

    Each grid point is discretised with :func:`scipy.signal.cont2discrete` (zero-order hold); between
    grid points the discrete matrices are interpolated linearly in q (grid step 0.005: the
    interpolation error is below 1e-9 of the state). One step is ``x <- Ad(q) x + Bd(q) u`` after the
    output ``y = u + k(q) (x1 - x2)``. The navigator reads the tables ``q``, ``Ad``, ``Bd`` in its numba kernel,
    which inlines that step; :meth:`matrices`, :meth:`output` and :meth:`step` are its NumPy reference (the
    tests check the tables and the step against the continuous network through them).

    Parameters
    ----------
    dt : float
        Step, s.
    ws : float
        Schuler frequency of the loop, rad/s.
    q_range : (float, float)
        Range of q covered (default [1, 8], the network's range).
    """

    def __init__(self, dt, ws=WS, q_range=(1.0, 8.0), q_step=0.005):
        self.dt, self.ws = float(dt), float(ws)
        n = int(round((q_range[1] - q_range[0]) / q_step)) + 1
        self.q = np.linspace(q_range[0], q_range[1], n)
        self.Ad = np.empty((n, 2, 2))
        self.Bd = np.empty((n, 2))
        self.T = np.array([time_constant(q, ws) for q in self.q])  # lag time constant, s
        for i, q in enumerate(self.q):
            ss = state_space(q, ws)
            Ad, Bd, _, _, _ = signal.cont2discrete((ss.A, ss.B, ss.C, ss.D), self.dt, method="zoh")
            self.Ad[i], self.Bd[i] = Ad, Bd[:, 0]

    def matrices(self, q):
        """(Ad, Bd) for coefficients ``q`` of any shape S: (S + (2, 2), S + (2,))."""
        q = np.asarray(q, dtype=float)
        bad = ~np.isfinite(q) | (q < self.q[0] - 1e-12) | (q > self.q[-1] + 1e-12)
        if np.any(bad):
            raise ValueError(f"q: expected values in [{self.q[0]:g}, {self.q[-1]:g}], found {q[bad].ravel()[:3].tolist()}")
        return self._matrices(q)

    def _matrices(self, q):
        x = (np.clip(q, self.q[0], self.q[-1]) - self.q[0]) * (1.0 / (self.q[1] - self.q[0]))
        i = np.minimum(x.astype(np.intp), self.q.size - 2)
        w = (x - i)[..., None]
        Bd = self.Bd[i] * (1 - w) + self.Bd[i + 1] * w
        w = w[..., None]
        return self.Ad[i] * (1 - w) + self.Ad[i + 1] * w, Bd

    @staticmethod
    def output(q, x, u):
        """Network output ``u + k(q) (x1 - x2)`` for states ``x`` (..., 2) and input ``u`` (...)."""
        return u + gain(q) * (x[..., 0] - x[..., 1])

    def step(self, q, x, u, matrices=None):
        """One step: returns (y, x_next) for coefficients ``q`` (...), states ``x`` (..., 2), input ``u`` (...).

        ``matrices`` may pass precomputed ``self.matrices(q)`` when q does not change."""
        Ad, Bd = self._matrices(np.asarray(q, dtype=float)) if matrices is None else matrices
        y = self.output(q, x, u)
        x_next = np.einsum("...ij,...j->...i", Ad, x) + Bd * np.asarray(u)[..., None]
        return y, x_next
