"""The comparison study from one import: ``import fusionbench as fb``, then ``fb.align(imu, site, method="kf")``.

:func:`align` is what ``fusionbench align`` does for a recording, for data in memory: it builds a registered method
(or a ``module:Class`` path) with its options and calls it as the runner and the command line do
(:func:`fusionbench.methods.aligner.call_align`), so a method refuses in one line what it does not claim. The other
names of the top-level API (``fb.Site``, ``fb.simulate``, ``fb.read_imu``, ``fb.metrics``, ...) are the library's own
objects, listed in :data:`fusionbench.API`.
"""

from __future__ import annotations

from fusionbench.methods.aligner import AlignmentResult, Site, call_align, load_method
from fusionbench.simulation.imudata import IMUData

__all__ = ["align"]


def align(imu: IMUData, site: Site, method: str = "kf", *, aiding=None, init=None, imu_spec=None,
          **options) -> AlignmentResult:
    """Align IMU data with a named method.

    Parameters
    ----------
    imu : IMUData
        R recordings, body RFU (right, front, up): increments (rad, m/s) or rates (rad/s, m/s^2), from
        :func:`fusionbench.simulation.imu.simulate` or :func:`fusionbench.files.imufiles.read_imu` (its first return
        value).
    site : Site
        Latitude, longitude (rad) and height (m) of the start (:meth:`Site.from_degrees` takes degrees).
    method : str
        A name of ``fusionbench list`` (``"kf"``, ``"gtsam"``, ``"adrc"``, ...) or a ``module:Class`` path.
    aiding : fusionbench.simulation.aiding.Aiding, optional
        Velocity or position rows (ENU, m/s or geodetic) with their times of validity, for a moving base
        (:func:`fusionbench.files.aidingfiles.read_aiding`, :func:`fusionbench.simulation.aidingsim.simulate_aiding`);
        None: the base is at rest, which the methods check.
    init : ndarray, shape (3, 3) or (R, 3, 3), optional
        Initial attitude guess ``C_bn`` (body RFU to ENU) for the methods that take one (the fine-alignment filters
        and graphs); None: each method's own coarse start.
    imu_spec : str, path or IMUSpec, optional
        The IMU noise model (a preset name such as ``"navigation"``, an IMU spec TOML file or an
        :class:`fusionbench.simulation.imu.IMUSpec`) given to a method that uses one, as ``--imu`` on the command line.
    **options
        The method's constructor options (its class docstring), e.g. ``step_s=0.5``.

    Returns
    -------
    AlignmentResult
        ``t`` (M,) s, ``C_bn`` (R, M, 3, 3) the attitude at each time, and the method's extras.

    Raises
    ------
    ValueError
        One line: an unknown method or option, or data outside what the method claims (a moving base without
        aiding, an IMU whose gyro bias hides the earth rate, ...).

    Examples
    --------
    >>> import numpy as np
    >>> import fusionbench as fb
    >>> site = fb.Site.from_degrees(34.0, 108.0, 450.0)
    >>> truth = fb.trajectory.Trajectory(site.lat, site.lon, site.h, fb.trajectory.EulerSway(
    ...     mean=np.radians([1.0, -2.0, -123.0])), duration=300.0)
    >>> imu = fb.simulate(truth, fb.PRESETS["navigation"], dt=0.01, runs=2, seed=1)
    >>> result = fb.align(imu, site, method="coarse")
    >>> err = fb.metrics.misalignment_history(result.C_bn[:, -1:], truth.truth([result.t[-1]]).C_bn)
    >>> bool(np.all(np.abs(err[:, 0, :2]) < np.radians(0.1)))
    True
    """
    return call_align(load_method(method, imu=imu_spec, **options), imu, site, aiding=aiding, init=init)
