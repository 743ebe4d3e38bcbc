"""The top-level API: ``import fusionbench as fb`` gives the comparison study's names, loaded on first use, and
``fb.align`` calls a method as the command line does."""

import doctest
import subprocess
import sys

import numpy as np
import pytest

import fusionbench as fb
from fusionbench import api
from fusionbench.files import imufiles
from fusionbench.methods import aligner
from fusionbench.scoring import metrics
from fusionbench.simulation import imu, trajectory


def test_import_loads_no_submodule_until_a_name_is_used():
    """``import fusionbench`` loads only the 0.1 paths' aliases (``_moved``, 60 lines of names) until a name is used."""
    code = ("import sys, fusionbench as fb; before = sorted(m for m in sys.modules if m.startswith('fusionbench.')); "
            "fb.Site; print(before, 'fusionbench.methods.aligner' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["['fusionbench._moved']", "True"]


def test_every_name_is_the_librarys_own_object():
    assert fb.Site is aligner.Site and fb.align is api.align and fb.simulate is imu.simulate
    assert fb.read_imu is imufiles.read_imu and fb.Trajectory is trajectory.Trajectory and fb.metrics is metrics
    for name, module in fb.API.items():
        assert getattr(fb, name) is not None, name
        assert name in dir(fb)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        fb.nothing


@pytest.fixture(scope="module")
def sway():
    site = fb.Site.from_degrees(34.0, 108.0, 450.0)
    truth = fb.Trajectory(site.lat, site.lon, site.h, fb.EulerSway(mean=np.radians([1.0, -2.0, -123.0])),
                          duration=300.0)
    spec = fb.PRESETS["navigation"]
    return site, truth, spec, fb.simulate(truth, spec, dt=0.02, runs=4, seed=5)


def test_align_lands_on_the_limits_with_the_scenario_noise_model(sway):
    site, truth, spec, data = sway
    result = fb.align(data, site, method="kf", imu_spec=spec)
    assert result.imu_model == "navigation"
    C_true = truth.truth([result.t[-1]]).C_bn[0]
    phi = fb.attitude.misalignment(result.C_bn_final, C_true)
    limit = fb.metrics.theoretical_limits(spec.gyro.bias, spec.accel.bias, C_true, site.lat, site.h)
    # every axis within 4 attainable bounds of its limit (4 runs; the bound at 300 s: 0.018 arcmin in level, 2.08 in
    # azimuth; measured up to 1.7 bounds)
    _, bound = fb.metrics.attainable_bound(spec, 300.0, trajectory=truth)
    assert np.all(np.abs(phi - limit) < 4 * bound[-1])


def test_align_passes_options_and_refuses_in_one_line(sway):
    site, truth, spec, data = sway
    with pytest.raises(ValueError, match="method 'nope': expected one of"):
        fb.align(data, site, method="nope")
    with pytest.raises(ValueError, match=r"^method 'kf': option 'bogus': expected one of \[.*'step_s'"):
        fb.align(data, site, method="kf", bogus=1.0)
    # an IMU whose gyro bias hides the earth rate: refused, naming it
    with pytest.raises(ValueError, match="unobservable"):
        fb.align(data, site, method="kf", imu_spec="mems")
    # a car that drives, handed over without aiding: refused before the method runs, naming --aiding
    car = fb.car_drive(site.lat, site.lon, site.h, duration=120.0)
    drive = fb.simulate(car, spec, dt=0.02, seed=1)
    with pytest.raises(ValueError, match="aiding") as err:
        fb.align(drive, site, method="kf")
    assert "\n" not in str(err.value)


def test_the_docstring_example_runs():
    failures, tried = doctest.testmod(api, verbose=False)
    assert tried > 0 and failures == 0
