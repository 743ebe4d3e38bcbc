"""Time is part of the answer: every registered method, on recordings from an independent simulator (pyins),
written to CSV, NPZ and PSINS .imu and read back, through the Python API and through ``fusionbench align``.

A perfect IMU on seed 000's fast sway (5/7/9 deg at 0.5/0.3/0.2 Hz) turns the attitude by 9-18 arcmin per
20-ms sample (50 Hz), so an attitude labelled one sample off is several arcmin off the truth at its label, while a
method that keeps the time rule lands within a fraction of an arcminute. Each test below is shown to fail on
a copy of a result whose labels are shifted by one sample.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from fusionbench.files.imufiles import read_imu, write_csv, write_npz, write_psins
from fusionbench.methods.aligner import AlignmentResult, Site, available_methods, check_time_rule, load_method
from fusionbench.methods.claims import supports
from fusionbench.simulation import attitude, units
from fusionbench.simulation.imudata import IMUData
from tests import independent

METHODS = sorted(available_methods())
RATE_HZ = 50.0
DURATION_S = 240.0
#: Accuracy of every method claiming the base, perfect IMU, over the last quarter of its history, arcmin
#: (measured: level under 0.1, azimuth under 0.3; a one-sample shift gives 9-18 arcmin on every axis).
TOL_LEVEL, TOL_AZIMUTH = 0.5, 1.0
#: What a one-sample shift must at least produce, arcmin (largest axis), for the test to be able to fail.
SHIFT_SEEN = 3.0

CASES = {  # name: (latitude deg, heading deg, sway amplitude deg, sway frequency Hz)
    "34N-table1": (34.0, 30.0, (5.0, 7.0, 9.0), (0.5, 0.3, 0.2)),
    "45S-mild": (-45.0, -179.0, (1.0, 1.5, 2.0), (0.2, 0.1, 0.05)),
    "60N-table1": (60.0, 90.0, (5.0, 7.0, 9.0), (0.5, 0.3, 0.2)),
}


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """{case: (Recording, {format: IMUData read back from a file})}: the first case in every format."""
    folder = tmp_path_factory.mktemp("timing")
    out = {}
    for name, (lat, heading, amp, freq) in CASES.items():
        rec = independent.sway(lat_deg=lat, heading_deg=heading, amplitude_deg=amp, frequency_hz=freq,
                               rate_hz=RATE_HZ, duration_s=DURATION_S)
        rates = IMUData(rec.t, rec.gyro, rec.accel, "rate")
        files = {"csv": write_csv(folder / f"{name}.csv", rates)}
        if name == "34N-table1":
            files["npz"] = write_npz(folder / f"{name}.npz", rates)
            incs = IMUData(rec.t[1:], rec.dtheta, rec.dvel, "increment")
            files["imu"] = write_psins(folder / f"{name}.imu", incs, attitude.dcm_to_euler(rec.C_bn[0]),
                                       lat=np.radians(lat), lon=np.radians(rec.lon_deg), h=rec.height_m,
                                       gyro_scale_arcsec=1e-4, accel_scale_ugs=0.01)
        out[name] = (rec, {fmt: read_imu(path)[0] for fmt, path in files.items()}, files)
    return out


def _site(rec):
    return Site.from_degrees(rec.lat_deg, rec.lon_deg, rec.height_m)


def _align(name, rec, imu):
    method = load_method(name)
    init = rec.C_bn[0] if supports(method).needs_init else None  # a navigator starts from the truth
    res = method.align(imu, _site(rec), init=init)
    check_time_rule(res, imu, name)
    return method, res


def _late_rms(res, rec, shift=0.0):
    """RMS over the last quarter of the history of the error against the truth at the labels (+ shift), arcmin."""
    late = (res.t >= res.t[0] + 0.75 * (res.t[-1] - res.t[0])) & (res.t + shift <= rec.t[-1] + 1e-9)
    phi = attitude.misalignment(res.C_bn[0, late], rec.truth_at(res.t[late] + shift)) / units.ARCMIN
    return np.sqrt(np.mean(phi**2, axis=0))


def _claims(method, rec):
    s = supports(method)
    return s.needs_init or s.covers("sway", rec.lat_deg)


def _params():
    return [(m, c, f) for c in CASES for f in (("csv", "npz", "imu") if c == "34N-table1" else ("csv",))
            for m in METHODS]


@pytest.mark.parametrize("name, case, fmt", _params())
def test_history_matches_the_truth_at_its_labels_and_a_shifted_copy_does_not(recordings, name, case, fmt):
    rec, imus, _ = recordings[case]
    imu = imus[fmt]
    method, res = _align(name, rec, imu)
    assert res.t[-1] == pytest.approx(rec.t[-1], abs=1e-9)  # the result ends at the file's last sample
    if not _claims(method, rec):
        return  # it does not claim a swaying base at this latitude: only its time rule (above) is checked
    err = _late_rms(res, rec)
    assert np.all(err[:2] < TOL_LEVEL) and err[2] < TOL_AZIMUTH, f"{name} on {case}.{fmt}: {err} arcmin"
    final = attitude.misalignment(res.C_bn[0, -1], rec.C_bn[-1]) / units.ARCMIN
    assert np.all(np.abs(final[:2]) < TOL_LEVEL) and abs(final[2]) < TOL_AZIMUTH, final
    if CASES[case][3] != (0.5, 0.3, 0.2):
        return  # a mild sway turns the attitude by under an arcminute per sample: a shift is not the point here
    # the same history labelled one sample late or early is far outside the tolerance
    dt = 1.0 / RATE_HZ
    for shift in (dt, -dt):
        shifted = AlignmentResult(res.method, res.t + shift, res.C_bn)
        assert _late_rms(shifted, rec).max() > SHIFT_SEEN, f"{name}: a one-sample shift goes unseen"


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("fmt", ["csv", "imu"])  # rates and increments
def test_a_causal_estimate_uses_no_later_sample(recordings, name, fmt):
    # the definition of the time rule, checked exactly: the history at t_k equals the final attitude of the same
    # method run on the record cut at t_k (rate files: the sample at t_k is the last one kept)
    rec, imus, _ = recordings["34N-table1"]
    imu = imus[fmt]
    method, res = _align(name, rec, imu)
    if not res.causal:
        # a smoother's estimates use the whole record by design (declared): its settling is measured on prefixes
        assert res.t[-1] == pytest.approx(rec.t[-1], abs=1e-9)
        return
    for frac in (0.81,):
        k = int(np.searchsorted(res.t, res.t[0] + frac * (res.t[-1] - res.t[0])))
        n = int(np.searchsorted(imu.t, res.t[k] + 1e-9))
        part = IMUData(imu.t[:n], imu.gyro[:, :n], imu.accel[:, :n], imu.kind)
        _, cut = _align(name, rec, part)
        assert cut.t[-1] == pytest.approx(res.t[k], abs=1e-9)
        gap = np.abs(attitude.misalignment(cut.C_bn[0, -1], res.C_bn[0, k])).max() / units.ARCSEC
        assert gap < 1e-3, f"{name}: the estimate at {res.t[k]} s changes when later samples are removed ({gap} arcsec)"
        # a history one entry late would be this far off: the check can fail
        late = np.abs(attitude.misalignment(cut.C_bn[0, -1], res.C_bn[0, k + 1])).max() / units.ARCSEC
        assert late > 1.0


@pytest.mark.parametrize("name", METHODS)
def test_align_command_ends_at_the_last_sample_of_the_file(recordings, name):
    rec, _, files = recordings["34N-table1"]
    r = subprocess.run([sys.executable, "-m", "fusionbench", "align", str(files["imu"]), "--lat", "34", "--lon", "108",
                        "--height", "450", "--method", name, "--json"], capture_output=True, text=True, timeout=300)
    method = load_method(name)
    if supports(method).needs_init:  # a navigator cannot align a file on its own: one line, exit 2
        assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1, r.stderr
        return
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["t_end"] == pytest.approx(rec.t[-1], abs=1e-9)
    if _claims(method, rec):
        err = attitude.misalignment(np.array(out["C_bn"]), rec.C_bn[-1]) / units.ARCMIN
        assert np.all(np.abs(err[:2]) < TOL_LEVEL) and abs(err[2]) < TOL_AZIMUTH, err
