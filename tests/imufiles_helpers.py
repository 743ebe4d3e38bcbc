"""What the tests of fusionbench.files.imufiles share: the tests/data folder, synthetic rate and increment IMU data,
and the check that reading a file is refused in one line naming it."""

from pathlib import Path

import numpy as np
import pytest

from fusionbench.files.imufiles import IMUFileError, read_imu
from fusionbench.simulation.imudata import IMUData

DATA = Path(__file__).parent / "data"


def _rate_imu(n=200, dt=0.01, runs=1, seed=0):
    rng = np.random.default_rng(seed)
    t = 3.0 + dt * np.arange(n)
    gyro = 1e-3 * rng.standard_normal((runs, n, 3)) + np.array([1e-5, 5e-5, 3e-5])
    accel = 1e-2 * rng.standard_normal((runs, n, 3)) + np.array([0.1, -0.2, 9.79])
    return IMUData(t, gyro, accel, kind="rate")


def _incr_imu(n=500, dt=0.02, runs=2, seed=1):
    r = _rate_imu(n, dt, runs, seed)
    return IMUData(r.t, r.gyro * dt, r.accel * dt, kind="increment")


def _assert_error(path, words, **kw):
    with pytest.raises(IMUFileError) as ei:
        read_imu(path, **kw)
    msg = str(ei.value)
    assert Path(path).name in msg, msg
    assert "\n" not in msg, msg
    assert any(w in msg.lower() for w in words), msg
    return msg
