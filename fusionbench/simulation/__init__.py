"""Simulation and the science every layer uses: the earth model, attitude and units, trajectories (sway, translation,
car drives), the IMU error model and simulator, aiding simulation, the strapdown integration. Imports only NumPy,
SciPy and numba."""
