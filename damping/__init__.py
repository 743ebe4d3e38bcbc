"""Adaptive Schuler damping network (seed 004)."""
