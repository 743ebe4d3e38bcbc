"""Active disturbance rejection control (Han's TD, ESO, NLSEF) and the aligners built on it."""

import fusionbench  # noqa: E402,F401  (first: it points numba's cache at the per-user directory)
