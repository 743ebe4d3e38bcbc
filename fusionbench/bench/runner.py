"""Monte Carlo runner: every method on identical simulated data, errors against truth and limits.

For a scenario the runner simulates runs in batches (the IMU errors of run k depend only on the
seed and k, never on the batch: see :mod:`fusionbench.simulation.imu`), gives each batch to every method,
and keeps the misalignment history of each run against truth. The figures of ``metrics.json``
(docs/contract.md) come from these histories; the histories feed the report's figures.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from joblib import Parallel, delayed

from fusionbench.bench import streaming
from fusionbench.bench.memory import default_batch_size, pin_mmap_threshold, release_freed_heap
from fusionbench.bench.run_metrics import run_metrics
from fusionbench.files.progress import bar as progress_bar
from fusionbench.methods.aligner import call_align, check_time_rule
from fusionbench.scoring import metrics
from fusionbench.scoring.bound import scenario_bound
from fusionbench.simulation import earth, imu as imu_mod, units
from fusionbench.simulation.aiding import Aiding
from fusionbench.simulation.aidingsim import simulate_aiding
from fusionbench.simulation.imudata import IMUData

#: Longest history kept per method for figures (points).
HISTORY_POINTS = 400
#: Window of the level-error RMS figure at the end of the record, s.
LEVEL_WINDOW_S = 100.0


@dataclass
class BatchOutcome:
    """One method on one batch of runs: what the runner keeps before the batches are joined.

    ``t`` (M,) s and ``phi`` (R, M, 3) rad are the decimated history, ``wall_s`` the method's time on the batch,
    ``per_run`` the per-run figures of :class:`MethodOutcome` over the batch's runs, ``series`` the method's own
    series (R, M) at ``t``, ``figures`` the scalar figures the method reports."""

    description: str
    t: np.ndarray
    phi: np.ndarray
    wall_s: float
    per_run: dict
    series: dict
    figures: dict


@dataclass
class MethodOutcome:
    """One method's results over all runs.

    Attributes
    ----------
    name : str
        Its label in metrics.json and the report (:func:`method_labels`).
    t : ndarray, shape (M,)
        History times, s (at most HISTORY_POINTS of the method's own).
    phi : ndarray, shape (R, M, 3)
        Misalignment against truth (E, N, U), rad, at ``t``.
    wall_s : float
        The method's time over all runs, s.
    per_run : dict
        Per-run figures, the runs first: ``phi_end`` (R, 3) rad at the last sample, ``settle`` (R,) s (NaN where
        not measured), ``settled`` (R,) bool, ``level_ms`` (R, 2) rad^2 over the last LEVEL_WINDOW_S, ``sigma_end``
        (R, 3) rad the method's predicted sigma at the end (NaN without one), and the metric features' own
        (:meth:`fusionbench.bench.feature.Feature.collect`).
    series : dict of str to ndarray, shape (R, M)
        What the method reports about itself at ``t`` (:attr:`fusionbench.methods.aligner.AlignmentResult.series`).
    figures : dict of str to float
        Its scalar figures (:attr:`fusionbench.methods.aligner.AlignmentResult.figures`).
    """

    name: str
    description: str
    t: np.ndarray
    phi: np.ndarray
    wall_s: float
    per_run: dict = field(default_factory=dict)
    series: dict = field(default_factory=dict)
    figures: dict = field(default_factory=dict)


@dataclass
class RunOutput:
    """A finished scenario run: its metrics (the metrics.json mapping) and the methods' histories (by the names they
    were given by; their labels in the metrics: ``MethodOutcome.name``)."""

    scenario: object
    metrics: dict
    outcomes: dict
    limits: np.ndarray
    refused: dict = field(default_factory=dict)


def _decimate(t):
    """Indices of at most HISTORY_POINTS evenly spread samples of ``t``."""
    if t.size <= HISTORY_POINTS:
        return np.arange(t.size)
    return np.unique(np.linspace(0, t.size - 1, HISTORY_POINTS).round().astype(int))


def _simulate_batch(scn, first_run, runs, seed, duration):
    """Runs first_run..first_run+runs-1: (trajectory, IMU data, aiding or None, initial guess or None)."""
    traj = scn.trajectory(duration)
    data = imu_mod.simulate(traj, scn.imu_spec, scn.dt, runs=runs, seed=seed, first_run=first_run)
    t_inc, _, _ = data.increments()
    aiding = None  # a fixed base without a reference's noise: the zero-velocity assumption, as a user's align makes it
    if scn.aiding_spec is not None:  # a receiver at its own rate, lever arm, latency and outages
        aiding = simulate_aiding(traj, scn.aiding_spec, duration, runs, seed, first_run, grid=t_inc)
    elif streaming.needs_vref(scn, traj):
        vref = imu_mod.simulate_vref(traj, scn.vref_spec, t_inc, runs=runs, seed=seed, first_run=first_run)
        aiding = Aiding.from_vref(t_inc, vref, at_rest=traj.translation.is_static(), source="the scenario's reference")
    return traj, data, aiding, scn.initial_guess(traj.truth([data.t0]).C_bn[0])


def _stream_batch(scn, first_run, runs, seed, duration):
    """Runs first_run..first_run+runs-1 as a stream of chunks (:mod:`fusionbench.bench.streaming`): (trajectory, stream,
    None, initial guess or None), the stream in place of the data and its reference."""
    traj = scn.trajectory(duration)
    stream = streaming.SimulatedStream(scn, traj, first_run, runs, seed, duration)
    return traj, stream, None, scn.initial_guess(traj.truth([stream.t0]).C_bn[0])


def _run_units(scn, method_names, first_run, runs, seed, duration, refusals=False):
    """Simulate runs first_run..first_run+runs-1 once and yield ``(name, outcome)`` as each method finishes.

    A record of at least :data:`fusionbench.bench.streaming.STREAM_MIN_S` goes as a stream of chunks to the methods that
    take one; the others share one simulation of the whole batch. With ``refusals`` a method that refuses the data
    (ValueError) gets its message instead of an outcome."""
    pin_mmap_threshold()  # large arrays mapped apart, in a worker as here: freed, they leave the process
    whole = None
    for name in method_names:
        if duration >= streaming.STREAM_MIN_S and streaming.takes_chunks(scn.method(name)):
            sim = _stream_batch(scn, first_run, runs, seed, duration)
        else:
            whole = whole or _simulate_batch(scn, first_run, runs, seed, duration)
            sim = whole
        outcome = _align_batch(scn, name, sim, first_run, refusals)
        release_freed_heap()  # what the method freed, before the next unit's arrays come on top
        yield name, outcome


def _run_unit(scn, name, first_run, runs, seed, duration, refusals=False):
    """One method on runs first_run..first_run+runs-1, simulated here (a worker's unit): ``(name, outcome)``."""
    return next(_run_units(scn, [name], first_run, runs, seed, duration, refusals))


def _align_batch(scn, name, sim, first_run, refusals):
    """One method on one simulated batch: its BatchOutcome, or its refusal message."""
    traj, data, aiding, init = sim
    method = scn.method(name)
    desc = method.description
    if name in scn.variants:
        opts = ", ".join(f"{k}={v}" for k, v in scn.variants[name].items() if k != "method")
        desc = f"`{scn.variants[name]['method']}` with {opts}: {desc}"
    stream = isinstance(data, streaming.SimulatedStream)
    n_meas = _measured_runs(first_run, data.runs)
    if not stream and n_meas and callable(getattr(method, "keeping_solutions", None)):  # a smoother whose prefixes
        method = method.keeping_solutions(n_meas)  # start from its record's solution: keep it (_prefix_settling)
    t0 = time.perf_counter()
    try:
        res = method.align_chunks(data, scn.site, data, init=init) if stream else \
            call_align(method, data, scn.site, aiding, init)
    except ValueError as exc:
        if not refusals:
            raise
        return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    except Exception as exc:  # not a refusal: a defect of the method, named in one line (the trace is chained)
        raise ValueError(f"method {name!r}: align() raised {type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''}") from exc
    wall = time.perf_counter() - t0
    check_time_rule(res, data, name)
    truth_C = traj.truth(res.t).C_bn
    phi = metrics.misalignment_history(res.C_bn, truth_C)
    limit_u = scenario_limits(scn, traj, res.t, truth_C)[:, 2]  # (M,) rad: it moves with the attitude on a sway
    band = scn.settling_band_arcmin * units.ARCMIN
    if res.causal:
        settle = metrics.settling_time(res.t, phi[..., 2], band, limit_u)
        done = metrics.settled(phi[..., 2], band, limit_u)
    elif stream:  # a smoother's settling needs its record's prefixes, which a stream does not hold: not measured
        settle, done = np.full(phi.shape[0], np.nan), np.abs(phi[:, -1, 2] - limit_u[-1]) <= band
    else:  # a smoother: each estimate uses the whole record, so settling is read off growing prefixes
        settle, done = _prefix_settling(method, data, aiding, init, traj, scn, phi[:, -1, 2], limit_u[-1],
                                        first_run)
    idx = _decimate(res.t)
    t_h, phi_h = res.t[idx], phi[:, idx]
    last = res.t >= res.t[-1] - LEVEL_WINDOW_S
    level_ms = np.mean(phi[:, last, :2] ** 2, axis=1)  # (runs, 2) mean square over the window
    # copies, not views: a view would keep the batch's whole history alive after it is scored
    per_run = {"phi_end": phi[:, -1].copy(), "level_ms": level_ms, "settle": settle, "settled": done,
               "sigma_end": np.full((phi.shape[0], 3), np.nan) if res.sigma_phi is None else res.sigma_phi[:, -1].copy()}
    for feature in scn.features:  # the scenario's metric features: their per-run figures
        per_run.update(feature.collect(res.t, phi, band, limit_u))
    # what a method reports about itself: scalar figures and (R, M) series kept like the history
    series = {k: np.asarray(v)[:, idx] for k, v in res.series.items()}
    return BatchOutcome(desc, t_h, phi_h, wall, per_run, series, res.figures)


#: Spacing of the record prefixes on which a smoother's settling is measured, s.
PREFIX_STEP_S = 25.0
#: Runs (the first ones of a seed) on which a smoother's settling is measured: each costs about five alignments
#: of the whole record; the other runs' settling is NaN and the statistics are over these.
PREFIX_RUNS = 5


def scenario_limits(scn, traj, t, C_bn):
    """The limits (M, 3) rad of the scenario's fixed IMU biases at times ``t`` (M,) and true attitudes ``C_bn``
    (M, 3, 3): on a fixed base the theoretical limits (:func:`fusionbench.scoring.metrics.theoretical_limits`); on a
    moving one, where an acceleration or a turn makes the biases partly observable, the mean error of the optimal
    estimator that does not know them (:func:`fusionbench.scoring.bound.bias_limit`, with the scenario's aiding); for a
    navigation scenario (a navigator estimates no bias) the stationary formula with the motion's specific force and
    frame rate, for the record."""
    bg, ba = scn.imu_spec.gyro.bias, scn.imu_spec.accel.bias
    if traj.translation.is_static():
        return metrics.theoretical_limits(bg, ba, C_bn, scn.site.lat, scn.site.h)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if scn.kind == "navigation":  # a navigator estimates no bias: the stationary limit along the path, for the record
        v, _ = traj.translation.mean_velocity(t)
        a = v - traj.translation.mean_velocity(t - 1.0)[0]  # over the last second
        lat, _, h = traj.position(t)
        w_ie, w_en = earth.earth_rate_n(lat), earth.transport_rate_n(v, lat, h)
        f_n = a + np.cross(2 * w_ie + w_en, v) - earth.gravity_n(lat, h)
        return metrics.theoretical_limits(bg, ba, C_bn, lat, h, f_n=f_n, w_in=w_ie + w_en)
    t_grid, limit, _ = scn.moving_limit(traj)
    return np.stack([np.interp(t, t_grid, limit[:, i]) for i in range(3)], axis=-1)


def method_labels(scn, methods):
    """``{given: label}``: the label in metrics.json and the report of each method of ``methods`` (the names it was
    given by): a ``module:Class`` path's object's ``name``, unless another method of the run has it (then the path);
    a registered name or a scenario's variant is its own label."""
    labels = {m: (getattr(scn.method(m), "name", m) if ":" in m and m not in scn.variants else m) for m in methods}
    taken = list(labels.values())
    return {m: (lab if taken.count(lab) == 1 else m) for m, lab in labels.items()}


def _measured_runs(first_run, runs):
    """How many of the batch's ``runs`` (from run ``first_run`` of the seed) a smoother's settling is measured on:
    those among the seed's first :data:`PREFIX_RUNS`."""
    return int(np.clip(PREFIX_RUNS - first_run, 0, runs))


def _prefix_settling(method, data, aiding, init, traj, scn, phiu_end, limit_end, first_run=0):
    """Settling of a method that is not causal (a smoother), per run: its final azimuth error on the prefixes of
    the record ending every PREFIX_STEP_S seconds, against the limit at each prefix's end; the first prefix
    end after which every later one (and the whole record) is inside the band. Prefixes are aligned from the
    end backwards until every run has left the band (or the shortest prefix the method accepts is reached).
    Only runs ``first_run + i < PREFIX_RUNS`` are measured (the same runs whatever the batching); the others
    get NaN. A method with ``estimate_only()`` aligns the prefixes with that copy (the same attitudes without the
    uncertainty figures: gtsam's marginals); one with ``prefix_aligner(imu, site, aiding, init)`` with the copy that
    returns, which starts each prefix from the whole record's solution (the graphs): the one ``method`` kept when
    it is the copy ``keeping_solutions(n)`` returned (``n`` the batch's measured runs) and aligned the record
    (:func:`_align_batch`), else one the copy solves.

    Returns ``(settle (R,) s, settled (R,) bool)``; ``settled`` (inside the band at the end) for every run."""
    band = scn.settling_band_arcmin * units.ARCMIN
    # only the final attitudes are read: a method may offer a cheaper copy without its uncertainty figures
    method = method.estimate_only() if callable(getattr(method, "estimate_only", None)) else method
    t_inc = data.increments()[0]
    first_out = np.abs(phiu_end - limit_end) > band  # the whole record: not settled at all
    n_meas = _measured_runs(first_run, data.runs)
    result = np.full(data.runs, np.nan)
    if n_meas == 0:
        return result, ~first_out
    data = IMUData(data.t, data.gyro[:n_meas], data.accel[:n_meas], data.kind)
    aiding = None if aiding is None else aiding.select_runs(slice(0, n_meas))
    settle = np.where(first_out[:n_meas], t_inc[-1], np.nan)
    prev = np.full(data.runs, t_inc[-1])
    step = max(1, int(round(PREFIX_STEP_S / data.dt)))
    ends = np.arange(t_inc.size - 1 - step, -1, -step)  # last sample index of each prefix, backwards
    for k in ends:
        if not np.isnan(settle).any():
            break
        n = k + 1 + (data.kind == "rate")  # samples of the prefix (rates: one more than increments)
        part = IMUData(data.t[:n], data.gyro[:, :n], data.accel[:, :n], data.kind)
        if part.duration < getattr(method, "min_duration_s", 0.0):
            break
        if k == ends[0] and callable(getattr(method, "prefix_aligner", None)):  # prefixes needed: solve the record
            method = method.prefix_aligner(data, scn.site, aiding, init)
        res = call_align(method, part, scn.site, None if aiding is None else aiding.window(-np.inf, t_inc[k]),
                         None if init is None else init)
        C_true = traj.truth([t_inc[k]]).C_bn
        err = (metrics.misalignment_history(res.C_bn[:, -1:], C_true)[:, 0, 2]
               - scenario_limits(scn, traj, [t_inc[k]], C_true)[0, 2])
        out = np.isnan(settle) & (np.abs(err) > band)
        settle[out] = prev[out]
        prev[:] = t_inc[k]
    open_ = np.isnan(settle)  # inside the band on every prefix tried: settled by the shortest one
    settle[open_] = prev[open_]
    result[:n_meas] = settle
    return result, ~first_out


def run_alignment(scn, methods=None, runs=None, seed=0, quick=False, n_jobs=1, progress=None, batch_size=None,
                  refusals=False):
    """Run an alignment scenario's Monte Carlo and compute its metrics (the ``alignment`` experiment;
    :func:`fusionbench.bench.experiment.run_scenario` runs any scenario).

    Parameters are :func:`fusionbench.bench.experiment.run_scenario`'s; here ``n_jobs`` are workers over batches (1,
    or a single batch, runs in this process), ``batch_size`` defaults to
    :func:`fusionbench.bench.memory.default_batch_size`, and with ``refusals`` a method that refuses the data
    (ValueError) is recorded in ``RunOutput.refused`` (name: message) and left out of the metrics instead of stopping
    the run.

    Returns
    -------
    RunOutput
    """
    methods = list(methods or scn.methods)
    for m in methods:  # fail early, with the method's own message
        scn.method(m)
    labels = method_labels(scn, methods)
    duration, default_runs = scn.sized(quick)
    runs = default_runs if runs is None else int(runs)
    if runs < 1:
        raise ValueError(f"runs: expected a positive number of Monte Carlo runs, found {runs}")
    if int(seed) < 0:
        raise ValueError(f"seed: expected a non-negative integer, found {seed}")
    for feature in scn.features:
        feature.validate(duration, quick, scn.source or scn.name)
    if batch_size is None:
        batch_size = default_batch_size(runs, int(round(duration / scn.dt)), duration >= streaming.STREAM_MIN_S,
                                        n_jobs)
    starts = list(range(0, runs, batch_size))
    jobs = [(k0, min(batch_size, runs - k0)) for k0 in starts]
    # the unit of work is one method on one batch, so that the bar moves as methods finish, not only as batches do
    units = [(k0, n, name) for k0, n in jobs for name in methods]
    pbar = progress_bar(progress, runs, scn.name)
    if n_jobs == 1 or len(units) == 1:  # in this process: each batch simulated once for all its methods
        done = ((name, r) for k0, n in jobs for name, r in _run_units(scn, methods, k0, n, seed, duration, refusals))
    else:  # a worker simulates its batch again for each method (a fraction of a second; the methods take seconds)
        done = Parallel(n_jobs=n_jobs, return_as="generator")(
            delayed(_run_unit)(scn, name, k0, n, seed, duration, refusals) for k0, n, name in units)
    results = {k0: {} for k0, _ in jobs}
    shown, acc = 0, 0.0
    for (k0, n, name), (got, r) in zip(units, done):
        results[k0][got] = r
        acc += n / len(methods)  # runs finished, counted in fractions of a batch
        if int(acc + 1e-9) > shown:
            pbar.update(int(acc + 1e-9) - shown)
            shown = int(acc + 1e-9)
    if runs > shown:
        pbar.update(runs - shown)
    pbar.close()
    results = [results[k0] for k0, _ in jobs]

    traj = scn.trajectory(duration)
    limits = scenario_limits(scn, traj, [duration], traj.truth([duration]).C_bn)[0]
    bound = scenario_bound(scn, traj, duration)  # None but for an alignment kind
    outcomes, refused = {}, {}
    for name in methods:
        parts = [r[name] for r in results]
        if any(isinstance(p, str) for p in parts):  # refused on some batch: the first message stands for all
            refused[name] = next(p for p in parts if isinstance(p, str))
            continue
        first = parts[0]
        join = lambda get: np.concatenate([get(p) for p in parts])  # noqa: E731 (batches along the runs)
        per_run = {key: ({k: join(lambda p: p.per_run[key][k]) for k in val} if isinstance(val, dict)
                         else join(lambda p: p.per_run[key])) for key, val in first.per_run.items()}
        series = {key: join(lambda p: p.series[key]) for key in first.series}
        outcomes[name] = MethodOutcome(labels[name], first.description, first.t, join(lambda p: p.phi),
                                       sum(p.wall_s for p in parts), per_run, series, first.figures)
    return RunOutput(scn, run_metrics(scn, outcomes, limits, runs, seed, quick, duration, bound), outcomes, limits,
                     refused)
