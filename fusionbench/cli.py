"""Command line: ``fusionbench list / run / check`` here, ``align / identify / consistency`` in
:mod:`fusionbench.cli_record` (the contract: docs/contract.md).

Bad input ends with one line ``fusionbench: error: ...`` naming the file or field, exit status 2; so does an
error inside a method (naming it). Ctrl-C ends with ``fusionbench: interrupted``, exit status 130; a reader that
stops reading (``fusionbench list | head -1``) ends it quietly with exit status 141. ``--traceback`` or
``FUSIONBENCH_TRACEBACK=1`` shows the full trace instead of the line.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import os
import re
import signal
import sys
import time
import traceback
from pathlib import Path

import numpy as np
from joblib import parallel_config

from fusionbench import __version__, cli_record
from fusionbench.bench import scenarios
from fusionbench.cli_common import exception_text, integer, named
from fusionbench.files import progress, provenance, reportdir
from fusionbench.methods.aligner import METHODS_GROUP, available_methods, uses_noise_model
from fusionbench.methods.claims import MAX_BIAS_TO_EARTH_RATE, supports

#: Exit statuses: a check found a regression; bad input or a failed method; interrupted (128 + SIGINT); the
#: reader of standard output went away (128 + SIGPIPE, what a shell reports for a tool SIGPIPE ended).
EXIT_REGRESSED, EXIT_ERROR, EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 1, 2, 130, 141
TRACEBACK_ENV = "FUSIONBENCH_TRACEBACK"


class _Parser(argparse.ArgumentParser):
    """argparse with the contract's one error line (no usage block)."""

    def error(self, message):
        self.exit(EXIT_ERROR, f"fusionbench: error: {message} (see {self.prog} --help)\n")


def _parser():
    debug = _Parser(add_help=False)  # --traceback also after the command, without overriding one before it
    debug.add_argument("--traceback", action="store_true", default=argparse.SUPPRESS,
                       help=f"on an error show the full trace, not one line (or set {TRACEBACK_ENV}=1)")
    p = _Parser(prog="fusionbench", description="Benchmark of INS initial-alignment methods "
                "on a shared, exact IMU simulator.")
    p.add_argument("--version", action="version", version=f"fusionbench {__version__}")
    p.add_argument("--traceback", action="store_true",
                   help=f"on an error show the full trace, not one line (or set {TRACEBACK_ENV}=1)")
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", parents=[debug], help="built-in scenarios and alignment methods, one per line")
    cli_record.add_parsers(sub, debug)
    r = sub.add_parser("run", parents=[debug],
                       help="Monte Carlo run of a scenario (a built-in name, 'all', or a .toml file)")
    r.add_argument("scenario")
    r.add_argument("--methods", help="comma-separated method names (default: the scenario's)")
    r.add_argument("--runs", type=integer("a positive number of Monte Carlo runs", lambda v: v >= 1),
                   help="Monte Carlo runs (default: the scenario's)")
    r.add_argument("--seed", type=integer("a non-negative integer", lambda v: v >= 0), default=0)
    r.add_argument("--quick", action="store_true", help="reduced size for CI")
    r.add_argument("--out", default="report",
                   help="output folder (default ./report): one scenario's report goes into it, 'all' puts one "
                        "folder per scenario and the overview in it; a report folder is replaced whole when the "
                        "new one is complete, and only if it is new, empty or a previous report (metrics.json, no "
                        "sub-folder): any other folder is refused, nothing in it touched")
    r.add_argument("--imu", help="your IMU for one scenario: a preset or an IMU spec .toml (as `identify` writes "
                   "it); replaces the scenario's [imu] (a conformance matrix's imu); required by a template (twin)")
    r.add_argument("--site", type=_site_text, help="your site for one scenario: LAT[,LON[,H]] in deg, deg, m; "
                   "replaces the scenario's [site]; required by a template (twin)")
    where = r.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="run the Monte Carlo on a Dask cluster: the address of "
                       "its scheduler (tcp://host:8786); needs pip install 'fusionbench[cluster]'; the numbers are "
                       "those of --jobs 1")
    where.add_argument("--cluster", metavar="local[:N]", help="run the Monte Carlo on a Dask LocalCluster of N worker "
                       "processes on this machine (default one per core)")
    r.add_argument("--jobs", type=integer("a non-zero worker count (-1: all cores)", lambda v: v != 0), default=-1,
                   help="parallel workers over batches of runs (joblib); default -1, all cores; 1 runs in this "
                        "process; the numbers do not depend on it")
    c = sub.add_parser("check", parents=[debug],
                       help="compare DIR/metrics.json (or DIR/*/metrics.json) with reference metrics")
    c.add_argument("dir")
    c.add_argument("--reference", help="reference folder or file (default: the references installed with "
                   "fusionbench for the run's size, --quick or default, seed 0)")
    return p


def _site_text(text):
    """``LAT[,LON[,H]]`` (deg, deg, m) as the ``[site]`` table of a scenario."""
    parts = text.split(",")
    try:
        values = [float(x) for x in parts]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 3 or not np.all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"expected LAT[,LON[,H]] in deg, deg, m (e.g. 34.2,108.9,450), found {text!r}")
    return dict(zip(("lat_deg", "lon_deg", "height_m"), values))


def _overrides(args):
    """The scenario entries ``run --imu`` and ``--site`` replace (an IMU file's path made absolute)."""
    out = {}
    if args.imu is not None:
        from fusionbench.simulation.imu import PRESETS

        out["imu"] = args.imu if args.imu in PRESETS else str(Path(args.imu).expanduser().resolve())
    if args.site is not None:
        out["site"] = args.site
    return out


def _cmd_list(args):
    print("scenarios:")
    for name in scenarios.builtin_names():
        print(f"  {name:<28} {scenarios.get(name).description}")
    print("methods:")
    for name, ep in sorted(available_methods().items()):
        cls = ep.load()
        print(f"  {name:<28} {getattr(cls, 'description', '')}{_method_notes(cls)}")
    from importlib.metadata import entry_points

    from fusionbench.bench.experiment import all_experiments

    for exp_name, exp in all_experiments().items():  # methods of another kind, from the experiment that runs them
        if exp.method_group != METHODS_GROUP:
            print(f"methods of the {exp_name} experiment:")
            for ep in sorted(entry_points(group=exp.method_group), key=lambda e: e.name):
                print(f"  {ep.name:<28} {getattr(ep.load(), 'description', '')}")
    return 0


def _moving_claim(claims):
    """What a method claims of the aiding on a moving base, for ``list`` ("" when it claims no moving base)."""
    if "moving" not in claims.bases:
        return ""
    words = [" or ".join(claims.aiding) + " rows"]
    if claims.min_aiding_hz > 0:
        words.append(f"from {claims.min_aiding_hz:g} Hz")
    if np.isfinite(claims.max_outage_s):
        words.append(f"outages to {claims.max_outage_s:g} s")
    if claims.max_bias_ratio_moving is not None and claims.max_bias_ratio_moving < claims.max_bias_ratio:
        words.append(f"gyro bias up to {claims.max_bias_ratio_moving:g} of the horizontal earth rate")
    return "; moving: " + ", ".join(words)


def _method_notes(cls):
    """What ``list`` adds to a method's description: the options of a named variant, its default noise model."""
    notes = []
    claims = supports(cls)
    notes.append("not an aligner: needs an initial attitude" if claims.needs_init else
                 f"claims {', '.join(claims.bases)} up to {claims.max_abs_lat_deg:g} deg"
                 + (f", gyro bias up to {claims.max_bias_ratio:g} of the horizontal earth rate"
                    if claims.max_bias_ratio < MAX_BIAS_TO_EARTH_RATE else "") + _moving_claim(claims)
                 if claims.bases else "claims no condition: kept to reproduce its paper")
    if getattr(cls, "variant_of", None):
        opts = ", ".join(f"{k}={v!r}" for k, v in cls.variant_options.items())
        notes.append(f"variant of {cls.variant_of}: {opts}")
    if uses_noise_model(cls):
        default = inspect.signature(cls).parameters["imu"].default
        notes.append("--imu: checks that the azimuth is observable" if default is None else
                     f"noise model: {getattr(default, 'name', default)} unless --imu")
    return "".join(f" [{n}]" for n in notes)


def _check_methods(scns, methods):
    """Load each ``module:Class`` method named on the command line for every scenario before any work, so that
    one that cannot be imported or built is one line naming it (the registered ones are the package's)."""
    for scn in scns if methods else ():
        for spec in methods:
            if ":" in spec and spec not in scn.variants:
                named(spec, lambda: scn.method(spec), group=scn.experiment_type.method_group)


def _cmd_run(args):
    overrides = _overrides(args)
    if args.scenario == "all":
        if overrides:
            raise ValueError("--imu and --site replace one scenario's sensor and site, not those of 'all': name a "
                             "scenario (e.g. run twin --imu my_imu.toml --site 34.2,108.9,450)")
        names = scenarios.builtin_names(templates=False)
    else:
        names = [args.scenario]
    scns = [scenarios.get(n, overrides) for n in names]  # validate every scenario before running any
    for scn in scns:
        if scn.template and not {"imu", "site"} <= set(overrides):
            raise ValueError(f"scenario {scn.name!r} is a template of your sensor: give --imu FILE.toml (e.g. what "
                             f"`fusionbench identify` writes) and --site LAT,LON,H")
    if args.methods is not None and not args.methods.strip(", "):
        raise ValueError(f"--methods: expected comma-separated method names, found {args.methods!r}")
    methods = args.methods.split(",") if args.methods else None
    _check_methods(scns, methods)
    out_dir = Path(args.out)
    if args.scenario == "all" and reportdir.is_report(out_dir):
        raise ValueError(f"{out_dir}: expected a folder for the reports of 'all', found one scenario's report: give "
                         f"--out another folder")
    # one bar for the whole command (scenarios x runs, elapsed and left) on a terminal; else a line per scenario
    total = sum(progress.expected_runs(scn, args.runs, args.quick) for scn in scns)
    with _workers(args) as n_jobs:
        return _run_all(args, scns, methods, out_dir, total, n_jobs)


@contextlib.contextmanager
def _workers(args):
    """The ``n_jobs`` of the runners: ``--jobs`` on this machine, or a Dask cluster's (``--scheduler``,
    ``--cluster``) while the block runs."""
    if args.scheduler is None and args.cluster is None:
        yield args.jobs
        return
    from fusionbench.bench.cluster import connect, parse_cluster

    size = None if args.cluster is None else parse_cluster(args.cluster)
    with connect(args.scheduler, size) as n_jobs:
        yield n_jobs


def _run_all(args, scns, methods, out_dir, total, n_jobs):
    """Run ``scns`` with ``n_jobs`` workers and write their reports (and the overview of 'all')."""
    from fusionbench.bench.experiment import run_scenario, write_scenario_report
    from fusionbench.experiments.overview import write_overview

    outs, pbar = [], None
    # before any Monte Carlo: every report folder replaceable, its parent writable (created)
    created = reportdir.prepare([out_dir / scn.name for scn in scns] if args.scenario == "all" else [out_dir])
    try:
        print(f"fusionbench run {args.scenario}: {len(scns)} scenario{'s' * (len(scns) > 1)}, {total} Monte Carlo "
              f"runs{' (--quick size)' if args.quick else ''} into {out_dir}", flush=True)
        pbar = progress.terminal_bar(total, "fusionbench run", disable=not sys.stderr.isatty())
        start = time.perf_counter()
        for scn in scns:
            t0 = time.perf_counter()
            pbar.set_postfix_str(scn.name)
            res = run_scenario(scn, methods=methods, runs=args.runs, seed=args.seed, quick=args.quick,
                               n_jobs=n_jobs, progress=pbar)
            wall = time.perf_counter() - t0
            m = res.metrics
            m["provenance"] = provenance.collect(seed=args.seed, runs=m.get("runs", args.runs or 0),
                                                 duration_s=m.get("duration_s", scn.sized(args.quick)[0]),
                                                 quick=args.quick, wall_s=wall)
            overrides = _overrides(args)
            if overrides:  # the sensor and site this run was given instead of the scenario's own
                m["provenance"]["overrides"] = overrides
            folder = out_dir / scn.name if args.scenario == "all" else out_dir
            path = write_scenario_report(res, folder)  # with report.html, whole or not at all
            outs.append((scn, m, path))
            pbar.write(f"{scn.name}: {path} ({wall:.0f} s)", file=sys.stdout)
            sys.stdout.flush()  # a log file gets the line when the scenario ends, not when the buffer fills
    except BaseException:
        reportdir.remove_empty(created)  # folders made for a report that never came
        raise
    finally:
        if pbar is not None:
            pbar.close()
    if args.scenario == "all":
        wall = time.perf_counter() - start
        print(f"overview: {write_overview(out_dir, outs, wall)} ({wall:.0f} s in all)")
    return 0


def _cmd_check(args):
    from fusionbench.bench.check import (compare, format_table, load_metrics, metrics_files, packaged_reference,
                                         reference_for)

    failed = False
    pairs = []
    for path in metrics_files(args.dir):  # every pair first: a run of another size is one line, not N regressions
        new = load_metrics(path, "metrics")
        ref, ref_path = reference_for(args.reference or packaged_reference(bool(new.get("quick"))), new["scenario"])
        if _size(ref) != _size(new):
            raise ValueError(f"{path}: the run is {_size_text(new)}, the reference {ref_path} is {_size_text(ref)}: "
                             f"compare runs of the same size and seed")
        pairs.append((new, ref, ref_path))
    for new, ref, ref_path in pairs:
        bad = compare(new, ref)
        if bad:
            failed = True
            print(f"{new['scenario']}: REGRESSED against {ref_path}")
            print(format_table(bad))
        else:
            print(f"{new['scenario']}: ok against {ref_path}")
    return EXIT_REGRESSED if failed else 0


def _size(m):
    return bool(m.get("quick")), m.get("runs"), m.get("seed")


def _size_text(m):
    return f"{'--quick' if m.get('quick') else 'default'} size, {m.get('runs')} runs, seed {m.get('seed')}"


def _culprit(exc, specs):
    """The ``module:Class`` method among ``specs`` whose module raised ``exc`` (in this process or, through
    joblib's remote traceback, in a worker), or None."""
    files = {}
    for spec in specs:
        module = sys.modules.get(spec.partition(":")[0]) if ":" in spec else None
        if getattr(module, "__file__", None):
            files[os.path.realpath(module.__file__)] = spec
    if not files:
        return None
    frames = [f.filename for f in traceback.extract_tb(exc.__traceback__)]
    cause = exc.__cause__
    if cause is not None and type(cause).__name__ == "_RemoteTraceback":
        frames += re.findall(r'File "([^"]+)", line', str(cause))
    for filename in reversed(frames):
        if os.path.realpath(filename) in files:
            return files[os.path.realpath(filename)]
    return None


def _error_line(exc, args):
    """The one line of an error: its message, naming the method it came from when that was a user's
    ``module:Class``; an unexpected exception also gives its type and where to find more."""
    text = exception_text(exc)
    who = _culprit(exc, [*(getattr(args, "methods", None) or "").split(","), getattr(args, "method", "")])
    if who and repr(who) not in text:
        return f"method {who!r}: {text}"
    if isinstance(exc, (ValueError, OSError)) or who:
        return text
    return f"{text} (unexpected: --traceback shows where)"


def _quiet_stdout():
    """The reader of standard output went away: point it at devnull so that Python's last flush is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def _signed_values(argv):
    """``--site -41.3,174.8`` as ``--site=-41.3,174.8`` (and so ``--lever-arm -0.4,1.2,0.9``): argparse takes a
    value that starts with '-' and is not one plain number for an option (a southern latitude with a longitude, an
    antenna left of the IMU, would be refused)."""
    out, k = [], 0
    while k < len(argv):
        if argv[k] in ("--site", "--lever-arm") and k + 1 < len(argv) and re.match(r"-[\d.]", argv[k + 1]):
            out.append(f"{argv[k]}={argv[k + 1]}")
            k += 2
        else:
            out.append(argv[k])
            k += 1
    return out


def _worker_ignores_sigint():
    """A worker process's start: SIGINT ignored (the parent handles a Ctrl-C and stops the workers)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def main(argv=None):
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); returns the exit status (0 done, 1 a check
    found a regression, 2 an error, 130 interrupted, 141 standard output closed)."""
    argv = _signed_values(sys.argv[1:] if argv is None else [str(a) for a in argv])
    try:
        args = _parser().parse_args(argv)
    except SystemExit as done:  # --help, --version, or a usage error (one line already printed)
        return done.code if isinstance(done.code, int) else EXIT_ERROR
    full = getattr(args, "traceback", False) or os.environ.get(TRACEBACK_ENV, "") not in ("", "0")
    # joblib's resource tracker (a child process) warns about the semaphores of workers stopped by a Ctrl-C
    # while it shuts down; that is joblib's housekeeping, not a message for the user
    os.environ.setdefault("PYTHONWARNINGS", "ignore::UserWarning:joblib.externals.loky.backend.resource_tracker")
    commands = {"list": _cmd_list, "align": cli_record.cmd_align, "identify": cli_record.cmd_identify,
                "consistency": cli_record.cmd_consistency, "run": _cmd_run, "check": _cmd_check}
    try:
        # the workers leave a Ctrl-C to this process, which stops them: a worker interrupted inside a library's
        # clean-up would print its own traceback beside our one line
        with parallel_config(backend="loky", initializer=_worker_ignores_sigint):
            status = commands[args.command](args)
        sys.stdout.flush()  # a closed pipe shows here, not in Python's last flush at exit
        return status
    except KeyboardInterrupt:
        if full:
            traceback.print_exc()
        print("fusionbench: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_BROKEN_PIPE
    except Exception as exc:
        if full:
            traceback.print_exc()
        else:
            print(f"fusionbench: error: {_error_line(exc, args)}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
