"""Baseline alignment methods: analytic coarse alignment, and (later) PID gyrocompass, Kalman and factor-graph alignment."""
