"""Adaptive Schuler damping (seed 004): the damping network H(s) and its damping ratio (``network``), the
acceleration -> q RBF map (``qmap``), damped free-inertial navigation ``damped-nav`` (``navigator``) and the
paper's design figures (``figures``)."""
