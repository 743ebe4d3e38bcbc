"""Jittered time stamps (issue 24): a known motion sampled at jittered times, written as a rate CSV (the rates at the
actual times) and as a KF-GINS increment file (the exact increments over the actual intervals), read back onto a
uniform grid (fusionbench.files.resample), through the strapdown and through ``align``.

The motion is coning: pitch and roll of 2 deg at 1 Hz, a quarter period apart, so ``w x dw/dt`` is steady
(``alpha^2 W^3``) and the componentwise resampling of the angle errs most. The attitude a jittered file gives at the
last sample is compared with the one the same motion sampled uniformly over the same span gives (the resampling
error, asserted within the bound ``c int |w x dw/dt| dt`` of fusionbench.files.resample), and for the increment file
with the theory's own prediction ``sum_j c_j (dw/dt x w) dt``, ``c_j`` computed here from the times. A yaw-only sway at
the same jitter shows the mechanism: its axis is fixed, so its error is the earth rate's share only. The bad files
(a gap, a duplicate time, a reversal, too short a step) end in one line naming the file and the row, exit status 2.
"""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fusionbench.cli import main
from fusionbench.files.imufiles import read_imu
from fusionbench.files.layouts import read_layout
from fusionbench.simulation import attitude, trajectory as tj, units
from fusionbench.simulation.imudata import IMUData
from fusionbench.simulation.strapdown import NavState, Strapdown

D = np.pi / 180
ARCSEC = units.ARCSEC
LAT = 34 * D
DT = 0.01
N = 6001  # 60 s at 100 Hz
T0 = 1.0
WEEK_S = 345600.0  # KF-GINS times are GNSS seconds of week
#: fusionbench's body axes (x right, y forward, z up) as front-right-down ones: (y, x, -z)
RFU_TO_FRD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
JITTERS = (0.001, 0.01, 0.1)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(6)  # this file's own quadrature (fusionbench's uses 4 points)


def _trajectory(amplitude, frequency, phase, mean=(0.0, 0.0, 30 * D)):
    return tj.Trajectory(LAT, 0.0, 0.0, tj.EulerSway(mean=mean, amplitude=amplitude, frequency=frequency,
                                                     phase=phase), duration=80.0)


CONING = _trajectory((2 * D, 2 * D, 0.0), (1.0, 1.0, 0.0), (0.0, np.pi / 2, 0.0))
YAW_SWAY = _trajectory((0.0, 0.0, 10 * D), (0.0, 0.0, 0.5), (0.0, 0.0, 0.0))


def _times(x, seed=0, pin_ends=False):
    """N stamps of a 100 Hz clock, each off by a uniform draw within +-x of the step."""
    eps = np.random.default_rng(seed).uniform(-x, x, N) * DT
    if pin_ends:
        eps[[0, -1]] = 0.0
    return T0 + DT * np.arange(N) + eps


def _increments(tr, starts, ends):
    """Exact angle and velocity increments over (starts, ends], body RFU (6-point Gauss-Legendre per interval)."""
    mid, half = 0.5 * (starts + ends), 0.5 * (ends - starts)
    w, f = tr.kinematics((mid[:, None] + half[:, None] * _GL_X).ravel())
    wts = half[:, None] * _GL_W
    return (np.einsum("nqi,nq->ni", w.reshape(-1, _GL_X.size, 3), wts),
            np.einsum("nqi,nq->ni", f.reshape(-1, _GL_X.size, 3), wts))


def _rate_csv(path, tr, t):
    w, f = tr.kinematics(t)
    np.savetxt(path, np.column_stack([t, w, f]), fmt="%.17g", delimiter=",", header="t,gx,gy,gz,ax,ay,az",
               comments="")
    return path


def _kfgins(path, t, dth, dv):
    np.savetxt(path, np.column_stack([WEEK_S + t, dth @ RFU_TO_FRD.T, dv @ RFU_TO_FRD.T]), fmt="%.17g")
    return path


def _attitude_at_end(tr, imu, t_shift=0.0):
    """C_bn at the last sample of a position-fixed strapdown from the true state at ``imu.t0`` (file time minus
    ``t_shift`` is trajectory time)."""
    _, dth, dv = imu.increments()
    s0 = tr.truth([imu.t0 - t_shift])
    nav = NavState.broadcast(1, s0.C_bn[0], lat=s0.lat[0], lon=s0.lon[0], h=s0.h[0])
    return Strapdown(nav, imu.dt, position_fixed=True).run(dth, dv, record_every=dth.shape[1])["C_bn"][0, -1]


def _rate_derivative(tr, t, h=1e-4, sensor=0):
    """w (rad/s) and dw/dt (rad/s^2) at ``t`` (``sensor=1``: f and df/dt), the derivative by central differences."""
    return tr.kinematics(t)[sensor], (tr.kinematics(t + h)[sensor] - tr.kinematics(t - h)[sensor]) / (2 * h)


def _check_cumulative(tr, imu, knots, grid, source, c):
    """At every grid time the cumulative angle and velocity of the read file miss the exact ones by at most
    ``c max|dw/dt|`` and ``c max|df/dt|`` per component (the interpolation), plus, for the rate file, its trapezoid
    rule's own cumulative error over the actual steps (computed here against this file's quadrature)."""
    exact = _increments(tr, grid[:-1], grid[1:])
    if source == "csv":
        w, f = tr.kinematics(knots)
        h = np.diff(knots)[:, None]
        trap = (0.5 * h * (w[1:] + w[:-1]), 0.5 * h * (f[1:] + f[:-1]))
        trap_err = [np.abs(np.cumsum(a - b, axis=0)).max(axis=0)
                    for a, b in zip(trap, _increments(tr, knots[:-1], knots[1:]))]
    else:
        trap_err = [0.0, 0.0]
    dense = np.linspace(grid[0], grid[-1], 20 * grid.size)
    # rounding: the KF-GINS times (seconds of week, written to 17 digits) keep 6e-11 s, so g times 2e-10 s
    for j, (got, want, slack) in enumerate(zip((imu.gyro[0], imu.accel[0]), exact, (1e-12, 2e-9))):
        slope = np.abs(_rate_derivative(tr, dense, sensor=j)[1]).max(axis=0)
        miss = np.abs(np.cumsum(got, axis=0) - np.cumsum(want, axis=0)).max(axis=0)
        assert np.all(miss <= c.max() * slope + trap_err[j] + slack), (j, miss, c.max() * slope, trap_err[j])


def _theory(tr, knots, grid):
    """This file's reading of the docstring's error terms: ``c_j`` at each grid time, the prediction
    ``sum_j c_j (dw/dt x w) dt`` (rad, body), ``int |w x dw/dt| dt`` (rad^2/s^2, dense trapezoid)."""
    k = np.clip(np.searchsorted(knots, grid, side="right") - 1, 0, knots.size - 2)
    c = 0.5 * (grid - knots[k]) * (knots[k + 1] - grid)
    w, wd = _rate_derivative(tr, grid)
    pred = (c[:, None] * np.cross(wd, w)).sum(axis=0) * (grid[1] - grid[0])
    dense = np.linspace(grid[0], grid[-1], 20 * grid.size)
    w, wd = _rate_derivative(tr, dense)
    return c, pred, np.trapezoid(np.linalg.norm(np.cross(w, wd), axis=1), dense)


def _read_jittered(tmp_path, tr, source, tau):
    """The jittered file of ``source`` read back, with the actual interval ends (knots, from its start) and the
    uniform grid the reader must use, and the reference: the same motion on that grid."""
    if source == "csv":
        imu, meta = read_imu(_rate_csv(tmp_path / "jit.csv", tr, tau))
        knots, grid = tau, np.linspace(tau[0], tau[-1], N)
        w, f = tr.kinematics(grid)
        return imu, meta, knots, grid, IMUData(grid, w, f, "rate"), 0.0
    start = tau[0] - (tau[-1] - tau[0]) / (N - 1)  # KF-GINS's first interval: one mean step (the reader's rule)
    knots = np.r_[start, tau]
    imu, meta = read_layout(_kfgins(tmp_path / "jit.txt", tau, *_increments(tr, knots[:-1], knots[1:])), "kf-gins")
    grid = np.linspace(start, tau[-1], N + 1)
    ref = IMUData(WEEK_S + grid[1:], *_increments(tr, grid[:-1], grid[1:]), "increment")
    return imu, meta, knots, grid, ref, WEEK_S


@pytest.mark.parametrize("x", JITTERS)
@pytest.mark.parametrize("source", ["csv", "kf-gins"])
def test_a_jittered_file_reaches_the_attitude_of_a_uniform_one_within_the_bound(tmp_path, source, x,
                                                                                record_property):
    tau = _times(x)
    imu, meta, knots, grid, ref, shift = _read_jittered(tmp_path, CONING, source, tau)
    # a uniform grid over the file's span, its jitter and bound coefficient as this file computes them
    assert meta["resampled"] and imu.kind == "increment" and imu.samples == grid.size - 1
    np.testing.assert_allclose(imu.t - shift, grid[1:], rtol=0, atol=1e-9)
    assert imu.t[-1] == pytest.approx(shift + tau[-1], abs=1e-9) and imu.dt == pytest.approx(grid[1] - grid[0])
    jitter = np.abs(knots - grid).max()
    c, pred, cross = _theory(CONING, knots, grid)
    assert meta["jitter_s"] == pytest.approx(jitter, rel=1e-6)
    assert meta["resampling_c_s2"] == pytest.approx(c.max(), rel=1e-6)
    assert c.max() <= 0.5 * jitter * (DT + jitter)
    _check_cumulative(CONING, imu, knots, grid, source, c)
    # the resampling error of the attitude at the last sample, body frame
    C_jit, C_ref = _attitude_at_end(CONING, imu, shift), _attitude_at_end(CONING, ref, shift)
    dphi = Rotation.from_matrix(C_ref.T @ C_jit).as_rotvec()
    bound = c.max() * cross
    if source == "csv":  # the trapezoid rule over the actual steps h against the uniform dt: (<h^3>/<h> - dt^2)/12
        h = np.diff(tau)
        bound += abs(np.sum(h ** 3) / np.sum(h) - np.diff(grid[:2])[0] ** 2) / 12 * cross
    else:  # exact increments: the leading term is the prediction, up to the cone's 2 deg tilt of the body axes
        assert np.linalg.norm(dphi - pred) < 0.1 * np.linalg.norm(pred)
    assert np.linalg.norm(dphi) <= bound
    # and against the truth: no worse than the uniform file by more than the bound
    truth = CONING.truth([tau[-1]]).C_bn[0]
    err_jit = np.linalg.norm(attitude.misalignment(C_jit, truth))
    err_ref = np.linalg.norm(attitude.misalignment(C_ref, truth))
    assert err_jit <= err_ref + bound
    for key, value in (("resampling_error_arcsec", np.linalg.norm(dphi) / ARCSEC), ("bound_arcsec", bound / ARCSEC),
                       ("error_vs_truth_arcsec", err_jit / ARCSEC), ("uniform_vs_truth_arcsec", err_ref / ARCSEC)):
        record_property(key, round(float(value), 4))


def test_a_fixed_rotation_axis_leaves_only_the_earth_rates_share(tmp_path):
    """Yaw sway, 10 deg at 0.5 Hz: ``w x dw/dt`` is the earth rate's cross product with the yaw acceleration alone,
    so the same 10 % jitter that costs the cone its arcseconds costs this file far less, within the same bound."""
    tau = _times(0.1)
    imu, meta, knots, grid, ref, shift = _read_jittered(tmp_path, YAW_SWAY, "kf-gins", tau)
    c, pred, cross = _theory(YAW_SWAY, knots, grid)
    dphi = Rotation.from_matrix(_attitude_at_end(YAW_SWAY, ref, shift).T
                                @ _attitude_at_end(YAW_SWAY, imu, shift)).as_rotvec()
    assert np.linalg.norm(dphi) <= c.max() * cross < 0.05 * ARCSEC
    _, cone_pred, _ = _theory(CONING, knots, grid)
    assert np.linalg.norm(dphi) < 1e-3 * np.linalg.norm(cone_pred)


# ------------------------------------------------------------------------------------------------ alignment

SWAY = tj.Trajectory(47 * D, 8 * D, 400.0, tj.EulerSway(mean=(1.5 * D, -3 * D, -250 * D), amplitude=(1 * D, 1.5 * D, 2 * D),
                                                        frequency=(0.2, 0.1, 0.05)), duration=200.0)
BIAS_G = np.array([1.0, -1.0, 0.5]) * 0.01 * units.DEG_PER_H
BIAS_A = np.array([25.0, -25.0, 10.0]) * units.UG
N_ALIGN = 12001  # 120 s


def _sway_csv(path, t):
    w, f = SWAY.kinematics(t)
    np.savetxt(path, np.column_stack([t, w + BIAS_G, f + BIAS_A]), fmt="%.17g", delimiter=",",
               header="t,gx,gy,gz,ax,ay,az", comments="")
    return path


def _align(capsys, path, method):
    status = main(["align", str(path), "--method", method, "--lat", "47", "--lon", "8", "--height", "400", "--json"])
    out, err = capsys.readouterr()
    assert status == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def uniform_alignments():
    """Each method's alignment of the uniform record, made once."""
    return {}


@pytest.mark.parametrize("method, x", [("coarse-i0", 0.001), ("coarse-i0", 0.01), ("coarse-i0", 0.1), ("kf", 0.1)])
def test_align_of_a_jittered_record_lands_within_an_arcsecond_of_the_uniform_one(tmp_path, capsys, method, x,
                                                                                  uniform_alignments,
                                                                                  record_property):
    """A swaying record (1, 1.5, 2 deg at 0.2, 0.1, 0.05 Hz) with fixed navigation-grade biases, 120 s at 100 Hz, as
    a rate CSV at jittered times (first and last on the uniform clock, so both records end at the same time). The
    methods' own limits on it are the biases' (level about 5 arcsec, azimuth 124 arcsec: east gyro bias over the
    earth rate); the jitter may move the result by 1 arcsec, under 1 % of the azimuth's limit."""
    if method not in uniform_alignments:
        uniform_alignments[method] = _align(capsys, _sway_csv(tmp_path / "u.csv", T0 + DT * np.arange(N_ALIGN)),
                                            method)
    a = uniform_alignments[method]
    tau = T0 + DT * np.arange(N_ALIGN)
    eps = np.random.default_rng(1).uniform(-x, x, N_ALIGN) * DT
    eps[[0, -1]] = 0.0
    b = _align(capsys, _sway_csv(tmp_path / "j.csv", tau + eps), method)
    assert b["t_end"] == a["t_end"] == pytest.approx(T0 + (N_ALIGN - 1) * DT)
    truth = SWAY.truth([a["t_end"]]).C_bn[0]
    limit_az = np.hypot(*BIAS_G[:2]) / (7.292115e-5 * np.cos(47 * D))
    assert np.abs(attitude.misalignment(np.array(a["C_bn"]), truth)).max() < 1.2 * limit_az
    diff = attitude.misalignment(np.array(b["C_bn"]), np.array(a["C_bn"]))
    assert np.abs(diff).max() < 1 * ARCSEC
    record_property("difference_arcsec", round(float(np.abs(diff).max() / ARCSEC), 4))


# ------------------------------------------------------------------------------------------------ bad times

BAD_TIMES = [  # (what is done to row 5, the words of the one line)
    ("gap", ["gap in time at row 5", "about 1 sample(s) missing"]),
    ("duplicate", ["time not strictly increasing at row 5", "a duplicate time"]),
    ("reversal", ["time not strictly increasing at row 5", "a reversal"]),
    ("short", ["time step too short at row 5", "an extra sample or a misplaced time stamp"]),
]


def _bad(t, what):
    t = t.copy()
    if what == "gap":  # row 5 onwards one sample later: a sample missing before row 5
        t[5:] += DT
    elif what == "duplicate":
        t[5] = t[4]
    elif what == "reversal":
        t[5] = t[4] - 0.3 * DT
    else:  # row 5 a fifth of a step after row 4, and on time from row 6 on
        t[5] = t[4] + 0.2 * DT
    return t


@pytest.mark.parametrize("what, words", BAD_TIMES)
@pytest.mark.parametrize("source", ["csv", "kf-gins"])
def test_bad_times_end_in_one_line_naming_the_row_and_status_2(tmp_path, capsys, source, what, words):
    t = _bad(_times(0.05)[:400], what)  # jittered times with one defect
    if source == "csv":
        path, args = _rate_csv(tmp_path / "bad.csv", CONING, t), []
        line = "(line 7)"  # the header, then rows 0 to 5
    else:
        dv = np.tile([0.0, 0.0, 9.8 * DT], (t.size, 1))  # a still IMU's increments: the time is what is checked
        path, args = _kfgins(tmp_path / "bad.txt", t, np.zeros((t.size, 3)), dv), ["--format", "kf-gins"]
        line = "(line 6)"
    status = main(["align", str(path), *args, "--lat", "34"])
    _, err = capsys.readouterr()
    assert status == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert str(path) in err and line in err and all(w in err for w in words), err
