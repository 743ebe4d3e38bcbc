"""Command line: ``fusionbench list / run / align / check`` (the contract: docs/contract.md).

Bad input ends with one line ``fusionbench: error: ...`` naming the file or field, exit status 2.
"""

from __future__ import annotations

import argparse
import inspect
import json
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__, attitude, progress, provenance, reportdir, scenarios
from .aligner import (MAX_BIAS_TO_EARTH_RATE, Site, available_methods, check_time_rule, load_method, supports,
                      uses_noise_model)
from .imu import load_spec


def _parser():
    p = argparse.ArgumentParser(prog="fusionbench", description="Benchmark of INS initial-alignment methods "
                                "on a shared, exact IMU simulator.")
    p.add_argument("--version", action="version", version=f"fusionbench {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="built-in scenarios and alignment methods, one per line")
    a = sub.add_parser("align", help="align a stationary or swaying IMU recording (CSV, NPZ, PSINS .imu)")
    a.add_argument("imu_file")
    a.add_argument("--lat", type=float, required=True, help="latitude, deg")
    a.add_argument("--lon", type=float, default=0.0, help="longitude, deg")
    a.add_argument("--height", type=float, default=0.0, help="height, m")
    a.add_argument("--method", default="coarse", help="method name (see list; named variants included) or "
                   "module:Class (default coarse)")
    a.add_argument("--imu", help="IMU noise model for methods that use one: a preset name or an IMU spec .toml file "
                   "(default: the method's own, shown by list)")
    a.add_argument("--json", action="store_true", help="print one JSON object")
    r = sub.add_parser("run", help="Monte Carlo run of a scenario (a built-in name, 'all', or a .toml file)")
    r.add_argument("scenario")
    r.add_argument("--methods", help="comma-separated method names (default: the scenario's)")
    r.add_argument("--runs", type=int, help="Monte Carlo runs (default: the scenario's)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--quick", action="store_true", help="reduced size for CI")
    r.add_argument("--out", default="report",
                   help="output folder (default ./report): one scenario's report goes into it, 'all' puts one "
                        "folder per scenario and the overview in it; a report folder is replaced whole when the "
                        "new one is complete, and only if it is new, empty or a previous report (metrics.json, no "
                        "sub-folder): any other folder is refused, nothing in it touched")
    r.add_argument("--jobs", type=int, default=-1,
                   help="parallel workers over batches of runs (joblib); default -1, all cores; 1 runs in this "
                        "process; the numbers do not depend on it")
    c = sub.add_parser("check", help="compare DIR/metrics.json (or DIR/*/metrics.json) with reference metrics")
    c.add_argument("dir")
    c.add_argument("--reference", help="reference folder or file (default: the references installed with "
                   "fusionbench for the run's size, --quick or default, seed 0)")
    return p


def _cmd_list(args):
    print("scenarios:")
    for name in scenarios.builtin_names():
        print(f"  {name:<28} {scenarios.get(name).description}")
    print("methods:")
    for name, ep in sorted(available_methods().items()):
        cls = ep.load()
        print(f"  {name:<28} {getattr(cls, 'description', '')}{_method_notes(cls)}")
    from importlib.metadata import entry_points

    from .aligner import GROUP
    from .experiment import all_experiments

    for exp_name, exp in all_experiments().items():  # methods of another kind, from the experiment that runs them
        if exp.method_group != GROUP:
            print(f"methods of the {exp_name} experiment:")
            for ep in sorted(entry_points(group=exp.method_group), key=lambda e: e.name):
                print(f"  {ep.name:<28} {getattr(ep.load(), 'description', '')}")
    return 0


def _method_notes(cls):
    """What ``list`` adds to a method's description: the options of a named variant, its default noise model."""
    notes = []
    claims = supports(cls)
    notes.append("not an aligner: needs an initial attitude" if claims.needs_init else
                 f"claims {', '.join(claims.bases)} up to {claims.max_abs_lat_deg:g} deg"
                 + (f", gyro bias up to {claims.max_bias_ratio:g} of the horizontal earth rate"
                    if claims.max_bias_ratio < MAX_BIAS_TO_EARTH_RATE else "") if claims.bases else
                 "claims no condition: kept to reproduce its paper")
    if getattr(cls, "variant_of", None):
        opts = ", ".join(f"{k}={v!r}" for k, v in cls.variant_options.items())
        notes.append(f"variant of {cls.variant_of}: {opts}")
    if uses_noise_model(cls):
        default = inspect.signature(cls).parameters["imu"].default
        notes.append("--imu: checks that the azimuth is observable" if default is None else
                     f"noise model: {getattr(default, 'name', default)} unless --imu")
    return "".join(f" [{n}]" for n in notes)


def _cmd_align(args):
    from .imufiles import IMUFileError, read_imu

    noise = None if args.imu is None else load_spec(args.imu)
    method = load_method(args.method, imu=noise)
    site = Site.from_degrees(args.lat, args.lon, args.height)
    imu, _ = read_imu(args.imu_file)
    if imu.duration < method.min_duration_s:
        raise IMUFileError(f"{args.imu_file}: too short for method {method.name}: {imu.duration:g} s, "
                           f"it needs at least {method.min_duration_s:g} s")
    res = method.align(imu, site)
    check_time_rule(res, imu, args.method)
    C = res.C_bn_final[0]
    pitch, roll, yaw = np.degrees(attitude.dcm_to_euler(C))
    out = {"method": method.name, "t_end": res.t_end, "C_bn": C.tolist(), "pitch_deg": float(pitch),
           "roll_deg": float(roll), "yaw_deg": float(yaw), "heading_deg": float(np.degrees(attitude.heading(np.radians(yaw))))}
    if args.json:
        print(json.dumps(out))
    else:
        model = res.imu_model
        print(f"method {out['method']}, t_end {out['t_end']:.3f} s" + (f", noise model {model}" if model else ""))
        print(f"pitch {out['pitch_deg']:.4f} deg, roll {out['roll_deg']:.4f} deg, heading {out['heading_deg']:.4f} deg")
    return 0


def _cmd_run(args):
    from .overview import write_overview
    from .experiment import write_scenario_report
    from .experiment import run_scenario

    names = scenarios.builtin_names() if args.scenario == "all" else [args.scenario]
    scns = [scenarios.get(n) for n in names]  # validate every scenario before running any
    methods = args.methods.split(",") if args.methods else None
    out_dir = Path(args.out)
    if args.scenario == "all" and reportdir.is_report(out_dir):
        raise ValueError(f"{out_dir}: expected a folder for the reports of 'all', found one scenario's report: give "
                         f"--out another folder")
    outs = []
    # one bar for the whole command (scenarios x runs, elapsed and left) on a terminal; else a line per scenario
    total = sum(progress.expected_runs(scn, args.runs, args.quick) for scn in scns)
    pbar = None
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
                               n_jobs=args.jobs, progress=pbar)
            wall = time.perf_counter() - t0
            m = res.metrics
            m["provenance"] = provenance.collect(seed=args.seed, runs=m.get("runs", args.runs or 0),
                                                 duration_s=m.get("duration_s", scn.sized(args.quick)[0]),
                                                 quick=args.quick, wall_s=wall)
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
    from .check import compare, format_table, load_metrics, metrics_files, packaged_reference, reference_for

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
    return 1 if failed else 0


def _size(m):
    return bool(m.get("quick")), m.get("runs"), m.get("seed")


def _size_text(m):
    return f"{'--quick' if m.get('quick') else 'default'} size, {m.get('runs')} runs, seed {m.get('seed')}"


def main(argv=None):
    args = _parser().parse_args(argv)
    try:
        return {"list": _cmd_list, "align": _cmd_align, "run": _cmd_run, "check": _cmd_check}[args.command](args)
    except (ValueError, OSError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"fusionbench: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
