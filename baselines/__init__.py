"""Baseline alignment methods: analytic coarse alignment, the classical PID gyrocompass, Kalman fine alignment
(filterpy) and factor-graph alignment (gtsam); and, in :mod:`baselines.rolling`, seed 002's (Ding, rolling-platform
self-calibration) platform self-calibration family (its model, experiment, method and report)."""

import fusionbench  # noqa: E402,F401  (first: it points numba's cache at the per-user directory)
