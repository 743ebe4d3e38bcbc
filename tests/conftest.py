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


def engines_agree(a, b):
    """Two AlignmentResults of the same method and data under its two engines agree: the same times, and the
    attitudes and every series (``extra``, ``series``) within 1e-12 of the series' own size, NaN where the other has
    NaN (the engines do the same operations in the same order: bit-identical on the x86-64 AVX2 machine they were
    written on; another CPU's vector width may change NumPy's einsum sums in the last bit)."""
    assert np.array_equal(a.t, b.t)
    assert sorted(a.extra) == sorted(b.extra) and sorted(a.series) == sorted(b.series)
    pairs = [(a.C_bn, b.C_bn)] + [(a.extra[k], b.extra[k]) for k in a.extra] + [(a.series[k], b.series[k])
                                                                             for k in a.series]
    for x, y in pairs:
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        assert x.shape == y.shape and np.array_equal(np.isnan(x), np.isnan(y))
        assert np.nanmax(np.abs(x - y), initial=0.0) <= 1e-12 * np.nanmax(np.abs(y), initial=0.0)
