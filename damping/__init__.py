"""Adaptive Schuler damping (seed 004): the damping network H(s) and its damping ratio (``network``), the
acceleration -> q RBF map (``qmap``), damped free-inertial navigation ``damped-nav`` (``navigator``) and the
paper's design figures (``figures``)."""

import fusionbench  # noqa: E402,F401  (first: it points numba's cache at the per-user directory)
