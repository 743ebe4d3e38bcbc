import json
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"


@pytest.fixture
def data_dir():
    return DATA


def load_fixture(stem):
    """A pyins fixture: (t, gyro (N,3) rad/s, accel (N,3) m/s^2, meta dict)."""
    d = np.loadtxt(DATA / f"{stem}.csv", delimiter=",", skiprows=1)
    meta = json.loads((DATA / f"{stem}.json").read_text())
    return d[:, 0], d[:, 1:4], d[:, 4:7], meta
