"""Named unit conversions: customary inertial-sensor units to SI and back.

Arrays inside fusionbench are SI (rad, rad/s, m/s^2, s). Sensor specifications are often
quoted in customary units; multiply by a constant here to get SI, divide to get back:

>>> 0.01 * DEG_PER_H          # gyro bias 0.01 deg/h in rad/s
4.84813681109536e-08
>>> 4.84813681109536e-08 / DEG_PER_H
0.01

``G0`` (standard gravity, 9.80665 m/s^2) defines the unit "g" and so "ug"; it is a unit, not
the local gravity (see :func:`fusionbench.simulation.earth.gravity` for that).
"""

from __future__ import annotations

import math

#: Standard gravity, m/s^2: the definition of the unit g.
G0 = 9.80665
#: One degree, rad.
DEG = math.pi / 180.0
#: One arc minute, rad.
ARCMIN = DEG / 60.0
#: One arc second, rad.
ARCSEC = DEG / 3600.0
#: One hour, s.
HOUR = 3600.0
#: One millisecond, s.
MILLISECOND = 1e-3
#: One microsecond, s.
MICROSECOND = 1e-6
#: One nanosecond, s.
NANOSECOND = 1e-9
#: Angular rate 1 deg/s in rad/s.
DEG_PER_S = DEG
#: Angular rate 1 deg/h in rad/s.
DEG_PER_H = DEG / HOUR
#: Angle random walk 1 deg/sqrt(h) in rad/sqrt(s).
DEG_PER_SQRT_H = DEG / math.sqrt(HOUR)
#: Rate random walk 1 deg/h/sqrt(h) in rad/s/sqrt(s).
DEG_PER_H_SQRT_H = DEG_PER_H / math.sqrt(HOUR)
#: Rate ramp 1 deg/h/h in rad/s^2.
DEG_PER_H_PER_H = DEG_PER_H / HOUR
#: Specific force 1 g in m/s^2.
G = G0
#: Specific force 1 micro-g in m/s^2.
UG = 1e-6 * G0
#: Milli-g in m/s^2.
MG = 1e-3 * G0
#: Velocity random walk 1 ug/sqrt(Hz) in m/s^2/sqrt(Hz) = m/s/sqrt(s).
UG_PER_SQRT_HZ = UG
#: Acceleration random walk 1 ug/sqrt(s) in m/s^2/sqrt(s).
UG_PER_SQRT_S = UG
#: Acceleration ramp 1 ug/s in m/s^3.
UG_PER_S = UG
#: Parts per million, dimensionless.
PPM = 1e-6
#: Speed 1 knot (1852 m per hour) in m/s.
KNOT = 1852.0 / HOUR
#: Speed 1 km/h in m/s.
KM_PER_H = 1000.0 / HOUR
#: Velocity random walk 1 m/s/sqrt(h) in m/s/sqrt(s).
M_PER_S_SQRT_H = 1.0 / math.sqrt(HOUR)
