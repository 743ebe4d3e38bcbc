"""Baseline alignment methods: analytic coarse alignment, the classical PID gyrocompass, Kalman fine alignment
(filterpy) and factor-graph alignment (gtsam)."""
