"""fusionbench: a shared, exact IMU and trajectory simulator and a benchmark of INS initial-alignment methods.

Frames: navigation n = East-North-Up, body b = Right-Front-Up. Attitude is C_bn (b to n) with
Euler angles C_bn = Rz(yaw) Rx(pitch) Ry(roll). SI units in every array.
"""

__version__ = "0.1.0"
