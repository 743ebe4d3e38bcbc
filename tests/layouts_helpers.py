"""The file axes by letter, shared by the tests of fusionbench.files.layouts: the tests' own definitions, from
which they build the file axes (never from the module's matrices)."""

#: The file's x, y, z by letter: R right, L left, F forward, B back, U up, D down, in RFU coordinates.
DIRS = {"R": (1, 0, 0), "L": (-1, 0, 0), "F": (0, 1, 0), "B": (0, -1, 0), "U": (0, 0, 1), "D": (0, 0, -1)}
LETTERS = {"RFU": "RFU", "FRD": "FRD", "FLU": "FLU", "NED-style": "FRD"}
