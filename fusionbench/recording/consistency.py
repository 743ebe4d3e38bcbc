"""Consistency of alignment methods on a recording without truth: window against window, method against method.

A quasi-static recording (a ship at the mooring, a vehicle idling) is cut into consecutive windows of
``window_s``; every method aligns every window on its own. Window k's attitude, at its last sample
``t_end[k]``, is carried with the gyros to the end of window k+1 (:func:`carry`) and compared with window
k+1's own attitude there. Were both right, they would agree up to the noise of the two windows and of the
carry; the disagreement (:attr:`Consistency.disagreement`, a small misalignment angle, ENU, rad) measures how
repeatable a method is on this data. Window by window, each method is also compared with the others
(:attr:`Consistency.agreement`).

What it cannot see: an error common to every window. A constant gyro or accelerometer bias puts every window
of an accurate method on the same theoretical limit (the azimuth off by the east gyro bias over the
horizontal earth rate, the level by the accelerometer bias over g): the windows agree although each is wrong.
Only a constant north or up gyro bias shows, as the drift of the carry (bias x window length: 0.05 arcmin for
0.01 deg/h over 300 s). The theoretical limits (:func:`fusionbench.scoring.metrics.theoretical_limits`) and a
simulated twin of the recording answer for the biases; this module answers for the rest: noise, a method's
own wander, a timing error.

With an IMU model the attainable bound of one window (:func:`fusionbench.scoring.metrics.attainable_bound`) gives
what the data allow: two independent windows each at the bound disagree by about sqrt(2) x the bound
(:func:`expected_disagreement` adds the carry's own noise). A method within it, and within it of the
others, does as well as the data allow.

A moving base is checked with its receiver's rows (:class:`~fusionbench.simulation.aiding.Aiding`): each window
gets the rows valid in it and starts at their first position (:func:`window_site`). The carry leaves out the
transport rate ``v / R`` (at 10 m/s 2 % of the earth rate: some 1.6 arcmin over a 300-s carry).

Frames: body RFU (x right, y forward, z up), navigation ENU fixed to the earth at the site; attitude
``C_bn``; misalignment as :mod:`fusionbench.simulation.attitude`. Report and figure:
:mod:`fusionbench.recording.consistency_report`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fusionbench.files import progress as progress_mod
from fusionbench.methods.aligner import Site, call_align, check_time_rule, load_method
from fusionbench.simulation import attitude, earth
from fusionbench.simulation.aiding import EDGE_TOLERANCE, Aiding
from fusionbench.simulation.imudata import IMUData
from fusionbench.simulation.strapdown import NavState, Strapdown

__all__ = ["Consistency", "consistency", "carry", "window_bounds", "expected_disagreement"]


@dataclass
class Consistency:
    """Windows, attitudes, disagreements and agreements of a consistency check (SI: rad, s).

    Attributes
    ----------
    window_s : float
        Window length asked for, s.
    samples_per_window : int
        Samples in each window (``round(window_s / dt)``).
    t_start, t_end : ndarray, shape (K,)
        Each window's initial state (``IMUData.t0`` of the window) and last sample, s.
    record_s : float
        Length of the whole recording, s (``IMUData.duration``).
    site : Site
    methods : list of str
        Method names, in the order asked.
    C_bn : ndarray, shape (M, K, 3, 3)
        Each method's attitude at the end of each window (body RFU to ENU); NaN where it refused the window.
    refused : list of list of str or None
        ``refused[m][k]``: method m's one-line refusal of window k, or None when it aligned it.
    disagreement : ndarray, shape (M, K - 1, 3)
        Window k+1's attitude against window k's carried to ``t_end[k + 1]`` (where pair k ends): ``d`` with
        ``C_{k+1} = exp(-[d x]) carry(C_k)``, rad, ENU (east, north: level; up: azimuth); NaN where one is refused.
    disagreement_euler : ndarray, shape (M, K - 1, 3)
        The same pair as Euler-angle differences ``[pitch, roll, yaw]`` (window k+1 minus carried window k), rad.
    agreement : ndarray, shape (M, K, 3)
        Each method against the others in each window: the median over the other methods of
        ``misalignment(C_m, C_other)``, rad, ENU; NaN with a single method or where it refused.
    pairwise_rms : ndarray, shape (M, M, 3)
        RMS over the windows both aligned of ``misalignment(C_m, C_n)``, rad, ENU (NaN without a common window).
    imu_model : str or None
        Name of the IMU model the methods were given (and the bound computed with).
    bound : ndarray, shape (3,), or None
        Attainable bound of one window about the theoretical limit, rad, ENU (:func:`expected_disagreement`).
    expected : ndarray, shape (3,), or None
        Standard deviation of the disagreement of two independent windows at the bound, carry included, rad, ENU.
    aiding_rows : ndarray of int, shape (K,), or None
        Rows of the aiding each window was given (valid in it); None without aiding.
    """

    window_s: float
    samples_per_window: int
    t_start: np.ndarray
    t_end: np.ndarray
    record_s: float
    site: Site
    methods: list
    C_bn: np.ndarray
    refused: list
    disagreement: np.ndarray
    disagreement_euler: np.ndarray
    agreement: np.ndarray
    pairwise_rms: np.ndarray
    imu_model: str | None = None
    bound: np.ndarray | None = None
    expected: np.ndarray | None = None
    aiding_rows: np.ndarray | None = None

    @property
    def windows(self) -> int:
        return int(self.t_end.size)

    def summary(self, name):
        """One method's figures (rad): ``pairs`` (window pairs both aligned), ``windows`` (aligned),
        ``disagreement_mean``, ``disagreement_std`` (about the mean), ``disagreement_rms`` (about zero),
        ``agreement_mean``, ``agreement_rms``, each (3,) ENU, NaN where undefined."""
        m = self.methods.index(name)
        d = self.disagreement[m]
        ok = np.all(np.isfinite(d), axis=1)
        a = self.agreement[m]
        a_ok = np.all(np.isfinite(a), axis=1)
        nan = np.full(3, np.nan)

        def over(x, sel, f):
            return f(x[sel]) if sel.any() else nan.copy()

        return {"windows": int(sum(r is None for r in self.refused[m])), "pairs": int(ok.sum()),
                "disagreement_mean": over(d, ok, lambda x: x.mean(axis=0)),
                "disagreement_std": over(d, ok, lambda x: x.std(axis=0)),
                "disagreement_rms": over(d, ok, lambda x: np.sqrt(np.mean(x ** 2, axis=0))),
                "agreement_mean": over(a, a_ok, lambda x: x.mean(axis=0)),
                "agreement_rms": over(a, a_ok, lambda x: np.sqrt(np.mean(x ** 2, axis=0)))}


def window_bounds(imu: IMUData, window_s: float):
    """Sample ranges of the consecutive windows: ``(n, [(a, b), ...])``, window k holding samples ``a:b``.

    Each window holds ``n = round(window_s / dt)`` samples, so consecutive windows' last samples are ``n dt``
    apart; the last partial window is dropped. A window of increments spans ``n dt``, one of rate samples
    ``(n - 1) dt`` (its first sample is its initial state).

    Raises
    ------
    ValueError
        One line: a window that is not a positive length, shorter than two samples, or that leaves fewer than two
        windows in the record.
    """
    try:
        w = float(window_s)
    except (TypeError, ValueError):
        raise ValueError(f"consistency window: expected a positive length in s, found {window_s!r}") from None
    if not (np.isfinite(w) and w > 0):
        raise ValueError(f"consistency window: expected a positive length in s, found {window_s!r}")
    n = int(round(w / imu.dt))
    if n < 2:
        raise ValueError(f"consistency window: expected at least two samples of {imu.dt:g} s, found {w:g} s")
    k = imu.samples // n
    if k < 2:
        raise ValueError(f"consistency window: expected at least two windows of {w:g} s in the record, found a "
                         f"record of {imu.duration:g} s (windows of at most {imu.duration / 2:g} s)")
    return n, [(i * n, (i + 1) * n) for i in range(k)]


def _increment_index(t_inc, t, imu):
    """Index in ``t_inc`` (increment end times) of the time ``t`` (s); -1 for the initial state ``imu.t0``."""
    tol = 1e-6 * imu.dt
    if abs(t - imu.t0) <= tol:
        return -1
    i = int(np.searchsorted(t_inc, t - tol))
    if i >= t_inc.size or abs(t_inc[i] - t) > tol:
        raise ValueError(f"carry: expected a sample time of the record ({imu.t0:g} to {t_inc[-1]:g} s, every "
                         f"{imu.dt:g} s), found {t:.10g} s")
    return i


def carry(C_bn, imu: IMUData, t_from: float, t_to: float, site: Site, run: int = 0):
    """Carry attitudes with the gyros from the sample ``t_from`` to the sample ``t_to``: attitude-only strapdown.

    The navigation frame is ENU fixed to the earth at ``site`` (the earth rate rotates it; no transport rate: a
    quasi-static base): ``C(t + dt) = exp(-[zeta x]) C exp([phi x])`` with ``zeta = omega_ie^n dt`` and ``phi``
    the body angle increment with the two-sample coning correction. It is
    :class:`fusionbench.simulation.strapdown.Strapdown` with the position fixed, whose attitude never reads its
    velocity there (the velocity is discarded). Exactly the increments ending in ``(t_from, t_to]`` are integrated;
    the one ending at ``t_from`` only enters the coning correction of the first.

    Parameters
    ----------
    C_bn : array_like, shape (..., 3, 3)
        Attitudes (body RFU to ENU) at ``t_from``, any number of them (e.g. one per method).
    imu : IMUData
        The recording; ``run`` selects one of its recordings.
    t_from, t_to : float
        Times, s, ``t_from <= t_to``: increment end times of ``imu`` (``imu.increments()[0]``) or ``imu.t0``.
    site : Site

    Returns
    -------
    ndarray, shape like ``C_bn``
        The attitudes at ``t_to``.
    """
    C = np.asarray(C_bn, dtype=float)
    lead = C.shape[:-2]
    C = C.reshape(-1, 3, 3)
    t_inc, dth, dv = imu.increments()
    i0, i1 = _increment_index(t_inc, t_from, imu), _increment_index(t_inc, t_to, imu)
    if i1 < i0:
        raise ValueError(f"carry: expected t_to at or after t_from ({t_from:.10g} s), found {t_to:.10g} s")
    if i1 == i0:
        return C.reshape(lead + (3, 3)).copy()
    m = C.shape[0]
    sd = Strapdown(NavState.broadcast(m, C, lat=site.lat, lon=site.lon, h=site.h), imu.dt, position_fixed=True)
    if i0 >= 0:  # the increment ending at t_from enters the first coning correction
        state = sd.compiled_state()
        state[6][:] = dth[run, i0]
        state[7][:] = dv[run, i0]
    seg = slice(i0 + 1, i1 + 1)
    sd.run(np.broadcast_to(dth[run, seg], (m,) + dth[run, seg].shape),
           np.broadcast_to(dv[run, seg], (m,) + dv[run, seg].shape), record_every=i1 - i0)
    return sd.state.C_bn.reshape(lead + (3, 3)).copy()


def expected_disagreement(spec, site: Site, window_duration_s: float, window_s: float, C_bn=None):
    """Attainable bound of one window and the disagreement two independent windows at it show, rad, ENU.

    The bound is :func:`fusionbench.scoring.metrics.attainable_bound` of ``spec`` over ``window_duration_s`` on a static
    base at ``site`` (exact zero velocity) with the per-recording constant bias part (``bias_sigma``) left out:
    in one recording it is the same in every window and makes no disagreement (like the fixed bias). Bias
    instability and random walk are counted as if independent between windows (an upper estimate when their
    correlation time is much longer than a window).

    The disagreement of window k+1 with window k carried over ``window_s`` is ``phi_{k+1} - N^T phi_k - w``
    with ``N^T = exp(-[omega_ie^n window_s x]))`` the turn of the earth (it leaks a share ``omega_N window_s``
    of the azimuth error into the east level) and ``w`` the gyro white noise integrated by the carry (variance
    ``C diag(ARW^2) C^T window_s``); its covariance is ``N^T P N + P + Q_w`` with ``P = diag(bound^2)``.

    Returns
    -------
    bound, expected : ndarray, shape (3,)
        Standard deviations, rad, ENU: one window's about its limit, and the disagreement's (about
        ``sqrt(2) x bound``, plus the carry's noise).
    """
    from fusionbench.scoring.metrics import attainable_bound

    window_spec = replace(spec, gyro=replace(spec.gyro, bias_sigma=(0.0,) * 3),
                          accel=replace(spec.accel, bias_sigma=(0.0,) * 3))
    C = np.eye(3) if C_bn is None else np.asarray(C_bn, dtype=float)
    _, sigma = attainable_bound(window_spec, window_duration_s, site=site, C_bn=C)
    bound = sigma[-1]
    P = np.diag(bound ** 2)
    Nt = attitude.rotvec_to_dcm(-earth.earth_rate_n(site.lat) * window_s)
    Qw = C @ np.diag(np.square(spec.gyro.white)) @ C.T * window_s
    cov = Nt @ P @ Nt.T + P + Qw
    return bound, np.sqrt(np.diag(cov))


def _align_all(imu, site, methods, imu_model, spans, progress, aiding=None):
    """``C (M, K, 3, 3)`` at each window's end (NaN where refused), the refusals ``[m][k]``, the rows each window
    was given (K,) or None: the aiding valid in ``(t0, t_last]`` of the window."""
    objs = [load_method(name, imu=imu_model) for name in methods]
    C = np.full((len(methods), len(spans), 3, 3), np.nan)
    refused = [[None] * len(spans) for _ in methods]
    rows = None if aiding is None else np.zeros(len(spans), int)
    bar = progress_mod.bar(progress, len(methods) * len(spans), "consistency")
    try:
        for k, (a, b) in enumerate(spans):
            part = IMUData(imu.t[a:b], imu.gyro[:, a:b], imu.accel[:, a:b], imu.kind)
            win, where = None, site
            if aiding is not None:
                tol = EDGE_TOLERANCE * imu.dt
                win = aiding.window(part.t0 + tol, part.t_last + tol)
                rows[k] = 0 if win is None else win.t.size
                where = site if k == 0 else window_site(site, win)
            for m, (name, method) in enumerate(zip(methods, objs)):
                try:
                    res = call_align(method, part, where, aiding=win)
                except ValueError as exc:
                    refused[m][k] = " ".join(str(exc).split()) or type(exc).__name__
                else:
                    check_time_rule(res, part, name)
                    C[m, k] = res.C_bn_final[0]
                bar.update(1)
    finally:
        bar.close()
    return C, refused, rows


def window_site(site: Site, rows) -> Site:
    """Where a window after the first starts: the first position of its aiding ``rows`` (the antenna's; its height
    when measured), else ``site``."""
    if rows is None or not rows.has_position:
        return site
    lat, lon, h = rows.position[..., np.flatnonzero(rows.position_rows())[0], :].reshape(-1, 3)[0]
    return Site(float(lat), float(lon), float(h) if np.isfinite(h) else site.h)


def _agreement(C):
    """``(agreement (M, K, 3), pairwise_rms (M, M, 3))`` of the attitudes ``C (M, K, 3, 3)`` (module docstring)."""
    M, K = C.shape[:2]
    ok = np.all(np.isfinite(C), axis=(-2, -1))  # (M, K)
    diff = np.full((M, M, K, 3), np.nan)
    for i in range(M):
        for j in range(M):
            both = ok[i] & ok[j]
            if i != j and both.any():
                diff[i, j, both] = attitude.misalignment(C[i, both], C[j, both])
    agree = np.full((M, K, 3), np.nan)
    pair = np.full((M, M, 3), np.nan)
    for i in range(M):
        others = np.delete(diff[i], i, axis=0)  # (M - 1, K, 3)
        for k in range(K):
            vals = others[:, k][np.all(np.isfinite(others[:, k]), axis=1)]
            if vals.size:
                agree[i, k] = np.median(vals, axis=0)
        for j in range(M):
            fin = np.all(np.isfinite(diff[i, j]), axis=1)
            if fin.any():
                pair[i, j] = np.sqrt(np.mean(diff[i, j, fin] ** 2, axis=0))
    return agree, pair


def consistency(imu: IMUData, site: Site, methods, window_s: float = 300.0, imu_model=None,
                progress=None, aiding: Aiding | None = None) -> Consistency:
    """Align consecutive windows of a recording with each method and compare them (module docstring).

    Parameters
    ----------
    imu : IMUData
        One quasi-static recording (``runs`` 1), kind ``"rate"`` or ``"increment"``, body RFU.
    site : Site
        Where it was recorded (latitude and height drive the earth rate and gravity).
    methods : sequence of str
        Method names (``fusionbench list``) or ``module:Class`` paths, each loaded with
        :func:`fusionbench.methods.aligner.load_method`.
    window_s : float
        Window length, s; windows are consecutive and do not overlap, the last partial one is dropped
        (:func:`window_bounds`).
    imu_model : str, path or IMUSpec, optional
        The IMU noise model given to the methods that take one; with it the attainable bound and the expected
        disagreement are computed (:func:`expected_disagreement`).
    progress : None, bool or a bar
        As :func:`fusionbench.files.progress.bar`, advanced by one per window and method.
    aiding : fusionbench.simulation.aiding.Aiding, optional
        A receiver's rows for the recording (a moving base), every row valid inside it: each window gets those
        valid in it (module docstring).

    Returns
    -------
    Consistency

    Raises
    ------
    ValueError
        One line: not one recording, no method or a repeated one, a window that is not a positive length or
        leaves fewer than two windows, aiding rows outside the record, an unknown method, a method breaking the
        time rule, or every method refusing every window (their messages).
    """
    if not isinstance(imu, IMUData):
        raise ValueError(f"consistency imu: expected an IMUData, found {type(imu).__name__}")
    if imu.runs != 1:
        raise ValueError(f"consistency imu: expected one recording, found {imu.runs}")
    methods = [methods] if isinstance(methods, str) else list(methods)
    if not methods:
        raise ValueError("consistency methods: expected at least one method name, found none")
    if len(set(methods)) != len(methods):
        raise ValueError(f"consistency methods: expected each method once, found {methods}")
    n, spans = window_bounds(imu, window_s)
    if aiding is not None:
        if not isinstance(aiding, Aiding):
            raise ValueError(f"consistency aiding: expected an Aiding, found {type(aiding).__name__}")
        aiding.check_record(imu.t0, imu.t_last, imu.dt, "consistency")
    C, refused, aiding_rows = _align_all(imu, site, methods, imu_model, spans, progress, aiding)
    if all(r is not None for rows in refused for r in rows):
        raise ValueError("consistency: every method refused every window: "
                         + "; ".join(dict.fromkeys(r for rows in refused for r in rows)))
    ends = np.array([imu.t[b - 1] for _, b in spans])
    starts = np.array([imu.t[a] - imu.dt if imu.kind == "increment" else imu.t[a] for a, _ in spans])
    M, K = len(methods), len(spans)
    d = np.full((M, K - 1, 3), np.nan)
    de = np.full((M, K - 1, 3), np.nan)
    ok = np.all(np.isfinite(C), axis=(-2, -1))
    for k in range(K - 1):
        sel = ok[:, k] & ok[:, k + 1]
        if sel.any():
            carried = carry(C[sel, k], imu, ends[k], ends[k + 1], site)
            d[sel, k] = attitude.misalignment(C[sel, k + 1], carried)
            e = attitude.dcm_to_euler(C[sel, k + 1]) - attitude.dcm_to_euler(carried)
            e[:, 2] = np.angle(np.exp(1j * e[:, 2]))  # yaw difference in (-pi, pi]
            de[sel, k] = e
    agree, pair = _agreement(C)
    name, bound, expected = None, None, None
    if imu_model is not None:
        from fusionbench.simulation.imu import load_spec

        spec = load_spec(imu_model)
        name = spec.name
        ref = C[:, 0][ok[:, 0]]
        bound, expected = expected_disagreement(spec, site, float(ends[0] - starts[0]), float(ends[1] - ends[0]),
                                                C_bn=ref[0] if ref.size else None)
    return Consistency(float(window_s), n, starts, ends, imu.duration, site, methods, C, refused, d, de, agree, pair,
                       name, bound, expected, aiding_rows)
