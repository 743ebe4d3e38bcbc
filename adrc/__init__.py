"""Active disturbance rejection control (Han's TD, ESO, NLSEF) and the aligners built on it."""
