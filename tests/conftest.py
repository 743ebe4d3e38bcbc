import json
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"


def _plain(value):
    """``value`` with NumPy scalars and arrays turned into Python numbers and lists, recursively through tuples and
    lists: what pytest-xdist's workers can send back to the controller."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    if isinstance(value, (tuple, list)):
        return type(value)(_plain(v) for v in value)
    return value


@pytest.fixture
def record_property(request):
    """pytest's ``record_property``, with the value made plain (:func:`_plain`) so that it survives the trip from an
    xdist worker."""
    def record(name, value):
        request.node.user_properties.append((name, _plain(value)))
    return record


@pytest.fixture
def data_dir():
    return DATA


def load_fixture(stem):
    """A pyins fixture: (t, gyro (N,3) rad/s, accel (N,3) m/s^2, meta dict)."""
    d = np.loadtxt(DATA / f"{stem}.csv", delimiter=",", skiprows=1)
    meta = json.loads((DATA / f"{stem}.json").read_text())
    return d[:, 0], d[:, 1:4], d[:, 4:7], meta


#: The rounding unit of a double, 2.2e-16: two floating-point paths that round differently differ by multiples of it.
EPS = np.finfo(float).eps


def agree_to_rounding(x, y, roundings, scale=None):
    """``x`` and ``y``, one quantity computed along two floating-point paths, agree to rounding: the same shape and
    NaNs, and ``|x - y| <= roundings * EPS * scale`` wherever both are finite.

    ``roundings`` bounds the number of roundings by which the paths may differ (terms summed in another order, steps
    that carry each difference on, the computation's conditioning), and ``scale`` is the size a rounding is relative
    to (default: the quantity's own, ``max |y|``; an array broadcast against ``y`` gives each element its own): each
    caller derives both beside its call. Returns the largest difference in units of ``EPS * scale``.

    The tolerance must stay far below a real difference: a series shifted by one step or sample moves by 1e-2 to 2 of
    its size, so a tolerance above 1e-5 of the quantity's size (three orders below that) is refused as a derivation
    gone wrong, not a bound."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    assert x.shape == y.shape and np.array_equal(np.isnan(x), np.isnan(y)), "shapes or NaNs differ"
    size = np.nanmax(np.abs(y), initial=0.0)
    scale = np.broadcast_to(size if scale is None else np.asarray(scale, dtype=float), y.shape)
    tol = roundings * EPS * scale
    assert np.nanmax(tol, initial=0.0) <= 1e-5 * size, \
        f"tolerance {np.nanmax(tol):.3g} above 1e-5 of the quantity's size {size:.3g}"
    diff = np.abs(x - y)
    worst = np.nanmax(np.where(diff > tol, diff / np.maximum(tol, np.finfo(float).tiny), 0.0), initial=0.0)
    assert worst == 0.0, f"differ by up to {worst:.3g} times the tolerance ({roundings:.3g} roundings)"
    with np.errstate(invalid="ignore", divide="ignore"):
        return float(np.nanmax(np.where(scale > 0, diff / (EPS * scale), 0.0), initial=0.0))


def engines_agree(a, b, roundings):
    """Two AlignmentResults of the same method and data under its two engines agree (:func:`agree_to_rounding`): the
    same times and series names, and the attitudes and every series (``extra``, ``series``) within ``roundings``
    roundings of the series' own size."""
    assert np.array_equal(a.t, b.t)
    assert sorted(a.extra) == sorted(b.extra) and sorted(a.series) == sorted(b.series)
    pairs = [(a.C_bn, b.C_bn)] + [(a.extra[k], b.extra[k]) for k in a.extra] + [(a.series[k], b.series[k])
                                                                             for k in a.series]
    for x, y in pairs:
        agree_to_rounding(x, y, roundings)


# -------------------------------------------------- the command line's failures: tests/test_cli_failures*.py

TINY = """name = "tiny-cli"
description = "30 s static at 50 Hz, 2 runs"
duration_s = 30.0
rate_hz = 50.0
runs = 2
methods = ["coarse"]
[site]
lat_deg = 34.0
[imu]
preset = "navigation"
"""


@pytest.fixture
def tiny(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(TINY)
    return p


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A 60-s stationary CSV recording at 50 Hz."""
    from fusionbench.files.imufiles import write_csv
    from fusionbench.simulation import trajectory as tj
    from fusionbench.simulation.imu import PRESETS, simulate

    tr = tj.Trajectory(0.6, 0.0, 0.0, tj.EulerSway(mean=(0.0, 0.0, 1.0)), duration=60.0)
    data = simulate(tr, PRESETS["navigation"].noise_free(), 0.02)
    return write_csv(tmp_path_factory.mktemp("rec") / "still.csv", data)
