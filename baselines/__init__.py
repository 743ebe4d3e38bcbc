"""Baseline alignment methods: analytic coarse alignment, the classical PID gyrocompass, Kalman fine alignment
(filterpy) and factor-graph alignment (gtsam)."""

import fusionbench  # noqa: E402,F401  (first: it points numba's cache at the per-user directory)
