"""The built-in experiments (``fusionbench.experiments`` entry points): alignment and navigation, the conformance
matrix, and the overview of many runs."""
