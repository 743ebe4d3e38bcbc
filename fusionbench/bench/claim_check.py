"""Is an answer inside what its method claims? The record, the IMU and the aiding against the method's
:class:`~fusionbench.methods.claims.Supports` (``fusionbench align`` warns when they are not; docs/contract.md).

The kind of base comes from the aiding and the record: rows of a moving base (not all at rest) make it
``"moving"``; otherwise the gyros tell a stationary base from a swaying one (:func:`rate_scatter`). On a
stationary base the mean gyro rate over any second is the earth rate plus a bias, the same second after second but
for the gyros' noise; a sway adds its own rate, which changes from one second to the next. So per run and axis
the rates are averaged over blocks of :data:`BLOCK_S`, and the variance of those block means is compared with the
noise's share of it: each block is cut into :data:`SUB_BLOCKS` sub-blocks, whose means' scatter about a straight
line through the block (which a sway's slow rate barely leaves) over the number of sub-blocks is what the noise
gives a block mean. A base sways when, on some axis, the block means' variance exceeds :data:`SWAY_RATIO` times
the noise's share **and** their RMS scatter exceeds :data:`SWAY_FLOOR_RAD_S` (a record without noise has no share
to compare with). Figures (simulated at 47 deg, 1 run, the largest over the axes; the variance ratio and the RMS
scatter of the block means over the earth rate Omega):

==============================================================  ==============  ===============  ======
record                                                          variance ratio  scatter / Omega  base
==============================================================  ==============  ===============  ======
static, navigation / tactical / MEMS, 600 s, 100 Hz             1.01 / 1.01 /   0.008 / 0.40 /   static
                                                                1.02            1.2
the same at 50 Hz (increments or rates alike)                   1.07 - 1.13     0.008 - 1.3      static
static MEMS at 100 Hz through a 5- / 20-sample moving average   1.27 / 3.13     1.2              static
static, navigation grade, 20 s at 100 Hz                        0.99            0.008            static
static, navigation grade without noise, 120 s at 100 Hz         1e262           2e-15            static
sway 0.001 deg (0.2, 0.12, 0.05 Hz), navigation, 300 s, 50 Hz   468             0.20             sway
the same, tactical / MEMS                                       1.3 / 1.1       0.46 / 1.3       static
sway 0.01 deg, navigation / tactical / MEMS                     1e4 / 25 / 3.8  2.0 / 2.0 / 2.3  sway, sway, static
sway 0.1 deg, navigation / tactical / MEMS                      4.8e4 / 1.1e3   20               sway
                                                                / 239
seed 000's Table-1 mooring (5-9 deg), navigation, 600 s         1.3e3           1.9e3            sway
seed 004's sea sway (1.2, 1.2, 0.8 deg), tactical, 600 s        2.2e4           176              sway
==============================================================  ==============  ===============  ======

Seed 000 is Zhou 2011 (ADRC gyrocompass), seed 004 Gu 2017 (adaptive Schuler damping). A sway below the gyros' noise
(0.001 deg under a tactical gyro, 0.01 deg under a MEMS one) counts as static: its rate is lost in the record's
noise, for the method too. Noise correlated over more than a sub-block (an output low-passed at a tenth of the
sample rate or less) raises the ratio of a static record toward the threshold.
"""

from __future__ import annotations

import numpy as np

from fusionbench.methods.claims import azimuth_bias_ratio, gyro_bias, supports
from fusionbench.simulation import earth, units

#: Length of the blocks the gyro rates are averaged over, s (shorter than a quarter of a sway's period of 5 to 30
#: s; a record shorter than 20 blocks has blocks of a twentieth of it).
BLOCK_S = 1.0
#: Each block is cut into this many sub-blocks (of at least one sample), whose scatter about a straight line gives the
#: noise's share: noise correlated over less than a sub-block (an anti-aliasing filter, rates from increments) counts.
SUB_BLOCKS = 10
#: A base sways when the variance of the block means exceeds this many times the white noise's share of it (under
#: white noise the ratio is about 1, within 0.13 for 120 blocks).
SWAY_RATIO = 4.0
#: ... and when their RMS scatter exceeds this, rad/s: 1 % of the earth rate (a sway below it turns the mean rate of
#: a 120-s record by about 0.002 deg/h, under a navigation-grade gyro bias).
SWAY_FLOOR_RAD_S = 0.01 * earth.OMEGA_IE


def rate_scatter(imu, block_s=BLOCK_S):
    """The scatter of the gyros' block-mean rates and the white noise's share of it (module docstring).

    Parameters
    ----------
    imu : fusionbench.simulation.imudata.IMUData
        R recordings, body RFU.
    block_s : float
        Length of the blocks, s (at most a twentieth of the record; at least 3 samples).

    Returns
    -------
    scatter : ndarray, shape (R, 3)
        Variance of the block means of the angular rate about their mean, per body axis, (rad/s)^2.
    noise : ndarray, shape (R, 3)
        What white noise of the size seen inside the blocks gives that variance, (rad/s)^2. Both are zero for a
        record of fewer than two blocks.
    """
    w = imu.rates()[0]
    R, N, _ = w.shape
    n = max(3, int(round(min(float(block_s), imu.duration / 20.0) / imu.dt)))
    sub = max(1, n // SUB_BLOCKS)
    m = n // sub
    B = N // (m * sub)
    if B < 2:
        return np.zeros((R, 3)), np.zeros((R, 3))
    x = w[:, :B * m * sub].reshape(R, B, m, sub, 3).mean(axis=3)          # sub-block means (R, B, m, 3)
    mean = x.mean(axis=2)
    s = np.arange(m) - (m - 1) / 2.0
    slope = np.einsum("rbmk,m->rbk", x - mean[:, :, None], s) / np.sum(s * s)
    res = x - mean[:, :, None] - slope[:, :, None] * s[None, None, :, None]
    per_sub = np.sum(res**2, axis=(1, 2)) / (B * (m - 2))
    return mean.var(axis=1, ddof=1), per_sub / m


def base_kind(imu, aiding=None) -> str:
    """``"moving"`` with aiding of a moving base (rows not all at rest), else ``"sway"`` or ``"static"`` as the
    gyros tell (:func:`rate_scatter`, :data:`SWAY_RATIO`, :data:`SWAY_FLOOR_RAD_S`; any run swaying)."""
    if aiding is not None and not aiding.is_at_rest():
        return "moving"
    scatter, noise = rate_scatter(imu)
    sway = (scatter > SWAY_RATIO * noise) & (scatter > SWAY_FLOOR_RAD_S**2)
    return "sway" if sway.any() else "static"


def aiding_outage(aiding, imu) -> float:
    """The longest time without a measuring row inside the record beyond the rows' own interval, s: the gap
    :meth:`fusionbench.simulation.aiding.Aiding.longest_gap` finds from the initial state to the last sample, less one
    interval at the median rate (1-Hz rows with 60 s missing are a 60-s outage)."""
    rate = aiding.rate_hz()
    return max(aiding.longest_gap(imu.t0, imu.t_last) - (1.0 / rate if np.isfinite(rate) else 0.0), 0.0)


def aiding_kinds(aiding) -> tuple:
    """The kinds of rows given: ``"velocity"`` (or at rest) and/or ``"position"``."""
    return tuple(k for k, has in (("velocity", aiding.has_velocity), ("position", aiding.has_position)) if has)


def outside_claim(method, imu, site, aiding=None, spec=None) -> str | None:
    """Why the record, the IMU and the aiding lie outside what ``method`` claims, or None when they are inside.

    Checked against the method's :class:`~fusionbench.methods.claims.Supports`
    (:meth:`~fusionbench.methods.claims.Supports.unclaimed`): the kind of base (:func:`base_kind`: moving with aiding
    of a moving base, else static or sway from the gyros), the site's latitude, the gyro bias of ``spec`` over the
    horizontal earth rate (:func:`~fusionbench.methods.claims.azimuth_bias_ratio`; on a moving base against
    ``max_bias_ratio_moving`` when the method claims one), and on a moving base the aiding kinds, the rows' rate
    (:meth:`~fusionbench.simulation.aiding.Aiding.rate_hz`) and their longest outage (:func:`aiding_outage`). A method
    that claims no condition (a paper's printed variant, a navigator) is always outside.

    Parameters
    ----------
    method : object
        An aligner (its ``supports``: the default :class:`~fusionbench.methods.claims.Supports` without one).
    imu : fusionbench.simulation.imudata.IMUData
        The record, body RFU.
    site : fusionbench.methods.aligner.Site
        Latitude (rad) of the site.
    aiding : fusionbench.simulation.aiding.Aiding, optional
        The rows given to the method.
    spec : fusionbench.simulation.imu.IMUSpec, optional
        The IMU's model (``--imu``); None: the gyro grade is not known and not checked.

    Returns
    -------
    str or None
        The reasons, ``"; "``-separated, each naming the figure and the claim; None inside the claim.
    """
    claims = supports(method)
    base = base_kind(imu, aiding)
    lat_deg = float(np.degrees(site.lat))
    ratio, gyro = None, "the gyro bias"
    if spec is not None:
        ratio = azimuth_bias_ratio(spec, site.lat)
        gyro = f"the gyro bias of IMU '{spec.name}' ({gyro_bias(spec) / units.DEG_PER_H:.3g} deg/h)"
    moving = base == "moving"
    kinds = aiding_kinds(aiding) if moving else ()
    reasons = claims.unclaimed(base, lat_deg, ratio, aiding=kinds,
                               aiding_hz=aiding.rate_hz() if moving else np.inf,
                               outage_s=aiding_outage(aiding, imu) if moving else 0.0, gyro=gyro)
    return "; ".join(reasons) or None
