"""The commands on a user's recording: ``align``, ``identify`` and ``consistency`` (the contract:
docs/contract.md), with what they share: the file's format (``--format``) and its site (``--lat``, or a ``.imu``
header)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import attitude
from .aligner import GROUP, AlignmentResult, Site, check_time_rule, load_method
from .cli_common import kind, named
from .imu import load_spec

#: How far the mean specific force of a record given to ``align`` may be from the site's gravity (relative): a
#: moored ship's sway changes it by far less, a unit error (g for m/s^2) or an accelerating vehicle by far more.
GRAVITY_TOLERANCE = 0.05


def add_parsers(sub, debug):
    """The ``align``, ``identify`` and ``consistency`` sub-commands of the parser ``sub``."""
    a = sub.add_parser("align", parents=[debug],
                       help="align a stationary or swaying IMU recording (CSV, NPZ, PSINS .imu)")
    a.add_argument("imu_file")
    record_arguments(a)
    a.add_argument("--method", default="coarse", help="method name (see list; named variants included) or "
                   "module:Class (default coarse)")
    a.add_argument("--imu", help="IMU noise model for methods that use one: a preset name or an IMU spec .toml file "
                   "(default: the method's own, shown by list)")
    a.add_argument("--json", action="store_true", help="print one JSON object")
    i = sub.add_parser("identify", parents=[debug],
                       help="the noise terms of a static recording from its Allan deviation, and an IMU spec .toml "
                            "the other commands take (--imu)")
    i.add_argument("imu_file")
    i.add_argument("--format", help="the file's layout (as for align)")
    i.add_argument("--name", help="the IMU's name in the spec (default: the file's name)")
    i.add_argument("--out", default="identify", help="output folder for imu_spec.toml, identify.json and allan.png "
                   "(default ./identify)")
    k = sub.add_parser("consistency", parents=[debug],
                       help="align consecutive windows of a recording without truth with each method and compare "
                            "them (self-consistency, and the methods' agreement)")
    k.add_argument("imu_file")
    record_arguments(k)
    k.add_argument("--methods", default="coarse,coarse-i0,pid,adrc,kf",
                   help="comma-separated method names (default coarse,coarse-i0,pid,adrc,kf)")
    k.add_argument("--window", type=float, default=300.0, help="window length, s (default 300)")
    k.add_argument("--imu", help="IMU noise model (a preset or an IMU spec .toml, as `identify` writes it): given to "
                   "the methods that use one, and with it the report shows what the data allow (the attainable bound)")
    k.add_argument("--out", default="consistency", help="output folder for consistency.json and consistency.png "
                   "(default ./consistency)")


def record_arguments(p):
    """The options of a command that reads a user's recording: its format and its site."""
    p.add_argument("--format", help="the file's layout: a built-in (pyins, pyins-increment, kf-gins, fusionbench-csv) "
                   "or a layout .toml (docs/layouts.md); default: by extension (.csv, .npz, .imu)")
    p.add_argument("--lat", type=float, help="latitude, deg (default: the file's header, for .imu; required for "
                   "other files)")
    p.add_argument("--lon", type=float, help="longitude, deg (default: the file's header, else 0)")
    p.add_argument("--height", type=float, help="height, m (default: the file's header, else 0)")


def read_record(args, min_samples=2):
    """The recording ``args.imu_file`` (one run, SI, body RFU) and its meta, read by ``--format`` or by extension."""
    if args.format is None:
        from .imufiles import read_imu

        return read_imu(args.imu_file, min_samples=min_samples)
    from .layouts import layout_from_name_or_file, read_layout

    return read_layout(args.imu_file, layout_from_name_or_file(args.format), min_samples=min_samples)


def record_site(args, meta):
    """The site of a recording: each of --lat, --lon, --height given on the command line wins over the file's
    header (a PSINS .imu holds all three); a file without a header needs --lat (longitude and height default
    to 0)."""
    if not meta:  # the command line's own values alone
        return Site.from_degrees(args.lat, args.lon or 0.0, args.height or 0.0) if args.lat is not None else None
    if args.lat is None and "lat" not in meta:
        from .imufiles import IMUFileError

        raise IMUFileError(meta["path"], f"a {meta['format']} file holds no site: give --lat DEG (and --lon DEG, "
                                         f"--height M; they default to 0)")
    lat = args.lat if args.lat is not None else np.degrees(meta["lat"])
    lon = args.lon if args.lon is not None else np.degrees(meta.get("lon", 0.0))
    h = args.height if args.height is not None else meta.get("h", 0.0)
    return Site.from_degrees(lat, lon, h)


def cmd_align(args):
    from .imufiles import IMUFileError

    noise = None if args.imu is None else load_spec(args.imu)
    method = named(args.method, lambda: load_method(args.method, imu=noise), group=GROUP)
    record_site(args, {})  # what the command line gives is checked before the file is read
    imu, meta = read_record(args)
    site = record_site(args, meta)
    if imu.duration < method.min_duration_s:
        raise IMUFileError(f"{args.imu_file}: too short for method {method.name}: {imu.duration:g} s, "
                           f"it needs at least {method.min_duration_s:g} s")
    f_mean = float(np.linalg.norm(imu.mean_rates()[1][0]))
    if abs(f_mean - site.g) > GRAVITY_TOLERANCE * site.g:  # align takes a stationary or swaying record
        raise IMUFileError(f"{args.imu_file}: expected a stationary or swaying record, whose mean specific force is "
                           f"gravity ({site.g:.4f} m/s^2 at the site, within {100 * GRAVITY_TOLERANCE:g} %), found "
                           f"{f_mean:.4g} m/s^2 (accelerometers in other units, or a moving base?)")
    res = named(args.method, lambda: method.align(imu, site), "align() ",
                 also=(getattr(method, "name", ""),))
    if not isinstance(res, AlignmentResult):
        raise ValueError(f"method {args.method!r}: align() returned {kind(res)}, expected an AlignmentResult")
    check_time_rule(res, imu, args.method)
    C = res.C_bn_final[0]
    pitch, roll, yaw = np.degrees(attitude.dcm_to_euler(C))
    out = {"method": method.name, "t_end": res.t_end, "C_bn": C.tolist(), "pitch_deg": float(pitch),
           "roll_deg": float(roll), "yaw_deg": float(yaw), "heading_deg": float(np.degrees(attitude.heading(np.radians(yaw))))}
    if args.json:
        print(json.dumps(out, allow_nan=False))
    else:
        model = res.imu_model
        print(f"method {out['method']}, t_end {out['t_end']:.3f} s" + (f", noise model {model}" if model else ""))
        print(f"pitch {out['pitch_deg']:.4f} deg, roll {out['roll_deg']:.4f} deg, heading {out['heading_deg']:.4f} deg")
    return 0


def cmd_identify(args):
    from .identify import run_identify

    imu, _ = read_record(args)
    name = args.name or Path(args.imu_file).stem
    for line in run_identify(imu, Path(args.out), name=name, source=str(args.imu_file)):
        print(line)
    return 0


def cmd_consistency(args):
    from .consistency import consistency
    from .consistency_report import summary_lines, write_consistency_report

    methods = [m for m in args.methods.split(",") if m]
    if not methods:
        raise ValueError(f"--methods: expected comma-separated method names, found {args.methods!r}")
    for spec in methods:  # each one builds, or one line names it, before the record is read
        named(spec, lambda: load_method(spec, imu=None if args.imu is None else load_spec(args.imu)), group=GROUP)
    record_site(args, {})
    imu, meta = read_record(args)
    site = record_site(args, meta)
    res = consistency(imu, site, methods, window_s=args.window, imu_model=args.imu)  # a bar on a terminal
    paths = write_consistency_report(res, Path(args.out))
    print(f"{args.imu_file}: {imu.duration:.0f} s at {1 / imu.dt:g} Hz, site {np.degrees(site.lat):.4f} deg latitude")
    for line in summary_lines(res):
        print(line)
    print(f"written: {', '.join(map(str, paths))}")
    return 0


