"""Adaptive Schuler damping (seed 004: Gu, Wang, Zheng and Zhao, "Internal horizontal damping network of SAMS by
applying adaptively adjustable damping ratio", Infrared and Laser Engineering 46(5), 2017): the damping network H(s)
and its damping ratio (``network``), the acceleration -> q RBF map (``qmap``), damped free-inertial navigation
``damped-nav`` (``navigator``) and the paper's design figures (``figures``)."""

import fusionbench  # noqa: E402,F401  (first: it points numba's cache at the per-user directory)
