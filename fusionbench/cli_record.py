"""The commands on a user's recording: ``align``, ``identify`` and ``consistency`` (the contract:
docs/contract.md), with what they share: the file's format (``--format``), its site (``--lat``, or a ``.imu``
header) and, for ``align`` and ``consistency``, a receiver's rows (``--aiding`` and the options that say how to
read them: :mod:`fusionbench.files.aidingfiles`, docs/aiding.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from fusionbench.cli_common import kind, named, seconds
from fusionbench.methods.aligner import METHODS_GROUP, AlignmentResult, Site, call_align, check_time_rule, load_method
from fusionbench.simulation import attitude, units
from fusionbench.simulation.aiding import MAX_DELAY_S, MAX_LEVER_ARM_M
from fusionbench.simulation.imu import load_spec

#: How far the mean specific force of a record given to ``align`` may be from the site's gravity (relative): a unit
#: check. A moored ship's sway changes it by far less, so does a car's drive (its accelerations, brakings and turns
#: average out: 0.004 % over the tests' 300-s drive); a unit error (g for m/s^2) or dead accelerometers by far more.
GRAVITY_TOLERANCE = 0.05


def add_parsers(sub, debug):
    """The ``align``, ``identify`` and ``consistency`` sub-commands of the parser ``sub``."""
    a = sub.add_parser("align", parents=[debug],
                       help="align an IMU recording (CSV, NPZ, PSINS .imu): a stationary or swaying base, or a "
                            "moving one with its receiver's rows (--aiding)")
    a.add_argument("imu_file")
    record_arguments(a)
    aiding_arguments(a)
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
    aiding_arguments(k)
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


def aiding_arguments(p):
    """The options of a command that takes a receiver's rows (docs/aiding.md): the file and how to read it."""
    from fusionbench.files.aidingfiles import FORMATS

    p.add_argument("--aiding", metavar="FILE", help="the velocity and/or position rows of a receiver (GNSS, "
                   "odometer) beside the IMU, at its own epochs: what a moving base needs (docs/aiding.md)")
    p.add_argument("--aiding-format", choices=FORMATS, help="the aiding file's format (default csv: t and vE,vN,vU "
                   "and/or lat,lon,h; kf-gins: KF-GINS's GNSS file; nmea: NMEA 0183 RMC, GGA, VTG, GST)")
    p.add_argument("--lever-arm", metavar="X,Y,Z", type=lever_arm_text, help="from the IMU to the antenna, m, body "
                   "right, front, up (default 0,0,0)")
    p.add_argument("--aiding-delay", metavar="S", type=seconds, help="the receiver's latency, s: a row stamped t is "
                   "valid at t - S (default 0)")
    p.add_argument("--aiding-time-offset", metavar="S", type=seconds, help="added to the aiding file's times to put "
                   "them on the IMU file's clock, s (e.g. NMEA's seconds since 00:00 UTC against the IMU's clock; "
                   "default 0)")


def lever_arm_text(text):
    """``X,Y,Z`` (m, body right, front, up) as an array: an argparse type."""
    import argparse

    from fusionbench.files.aidingfiles import check_lever_arm

    try:
        return check_lever_arm([float(x) for x in text.split(",")])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers X,Y,Z in m (body right, front, up), at most "
                                         f"{MAX_LEVER_ARM_M:g} m long, found {text!r}") from None


#: The options that say how to read --aiding, each of which needs it.
AIDING_OPTIONS = (("--aiding-format", "aiding_format"), ("--lever-arm", "lever_arm"),
                  ("--aiding-delay", "aiding_delay"), ("--aiding-time-offset", "aiding_time_offset"))


def check_aiding_options(args):
    """Refuse, in one line, an option that says how to read --aiding given without it."""
    if args.aiding is None:
        for opt, key in AIDING_OPTIONS:
            if getattr(args, key) is not None:
                raise ValueError(f"{opt}: applies to a receiver's rows: give them with --aiding FILE")
    elif args.aiding_delay is not None and abs(args.aiding_delay) > MAX_DELAY_S:
        raise ValueError(f"--aiding-delay: expected a receiver's latency within +-{MAX_DELAY_S:g} s, found "
                         f"{args.aiding_delay:g} s (an offset of the clocks is --aiding-time-offset)")


def read_aiding_file(args):
    """The rows of ``--aiding`` (an :class:`~fusionbench.simulation.aiding.Aiding`) read with the options, or None."""
    check_aiding_options(args)
    if args.aiding is None:
        return None
    from fusionbench.files.aidingfiles import read_aiding

    return read_aiding(args.aiding, args.aiding_format or "csv",
                       lever_arm=np.zeros(3) if args.lever_arm is None else args.lever_arm,
                       delay=args.aiding_delay or 0.0, time_offset=args.aiding_time_offset or 0.0)


def aiding_json(args, aiding):
    """What ``--json`` and consistency.json say of the rows: :func:`fusionbench.files.aidingfiles.aiding_summary` with
    the file's format and the time offset applied."""
    from fusionbench.files.aidingfiles import aiding_summary

    return {**aiding_summary(aiding), "format": args.aiding_format or "csv",
            "time_offset_s": float(args.aiding_time_offset or 0.0)}


def read_record(args, min_samples=2):
    """The recording ``args.imu_file`` (one run, SI, body RFU) and its meta, read by ``--format`` or by extension."""
    if args.format is None:
        from fusionbench.files.imufiles import read_imu

        return read_imu(args.imu_file, min_samples=min_samples)
    from fusionbench.files.layouts import layout_from_name_or_file, read_layout

    return read_layout(args.imu_file, layout_from_name_or_file(args.format), min_samples=min_samples)


def record_site(args, meta):
    """The site of a recording: each of --lat, --lon, --height given on the command line wins over the file's
    header (a PSINS .imu holds all three); a file without a header needs --lat (longitude and height default
    to 0)."""
    if not meta:  # the command line's own values alone
        return Site.from_degrees(args.lat, args.lon or 0.0, args.height or 0.0) if args.lat is not None else None
    if args.lat is None and "lat" not in meta:
        from fusionbench.files.imufiles import IMUFileError

        raise IMUFileError(meta["path"], f"a {meta['format']} file holds no site: give --lat DEG (and --lon DEG, "
                                         f"--height M; they default to 0)")
    lat = args.lat if args.lat is not None else np.degrees(meta["lat"])
    lon = args.lon if args.lon is not None else np.degrees(meta.get("lon", 0.0))
    h = args.height if args.height is not None else meta.get("h", 0.0)
    return Site.from_degrees(lat, lon, h)


def cmd_align(args):
    from fusionbench.files.imufiles import IMUFileError

    noise = None if args.imu is None else load_spec(args.imu)
    method = named(args.method, lambda: load_method(args.method, imu=noise), group=METHODS_GROUP)
    record_site(args, {})  # what the command line gives is checked before the file is read
    aiding = read_aiding_file(args)
    imu, meta = read_record(args)
    site = record_site(args, meta)
    if imu.duration < method.min_duration_s:
        raise IMUFileError(f"{args.imu_file}: too short for method {method.name}: {imu.duration:g} s, "
                           f"it needs at least {method.min_duration_s:g} s")
    f_mean = float(np.linalg.norm(imu.mean_rates()[1][0]))
    if abs(f_mean - site.g) > GRAVITY_TOLERANCE * site.g:  # a unit check: a vehicle's motion averages out
        raise IMUFileError(f"{args.imu_file}: expected accelerometers in m/s^2, whose mean specific force over the "
                           f"record is gravity ({site.g:.4f} m/s^2 at the site, within {100 * GRAVITY_TOLERANCE:g} %), "
                           f"found {f_mean:.4g} m/s^2 (specific force in g or other units? dead accelerometers? a base "
                           f"accelerating through the whole record?)")
    res = named(args.method, lambda: call_align(method, imu, site, aiding=aiding), "align() ",
                also=(getattr(method, "name", ""),))
    if not isinstance(res, AlignmentResult):
        raise ValueError(f"method {args.method!r}: align() returned {kind(res)}, expected an AlignmentResult")
    check_time_rule(res, imu, args.method)
    C = res.C_bn_final[0]
    pitch, roll, yaw = np.degrees(attitude.dcm_to_euler(C))
    out = {"method": method.name, "t_end": res.t_end, "C_bn": C.tolist(), "pitch_deg": float(pitch),
           "roll_deg": float(roll), "yaw_deg": float(yaw), "heading_deg": float(np.degrees(attitude.heading(np.radians(yaw))))}
    if aiding is not None:
        out["aiding"] = aiding_json(args, aiding)
    out.update(answer_claims(method, res, imu, site, aiding, noise))
    if out["outside_claim"] is not None:
        print(f"fusionbench: warning: {method.name}: outside its claim: {out['outside_claim']}", file=sys.stderr)
    if args.json:
        print(json.dumps(out, allow_nan=False))
    else:
        model = res.imu_model
        print(f"method {out['method']}, t_end {out['t_end']:.3f} s" + (f", noise model {model}" if model else ""))
        if aiding is not None:
            print(aiding_line(out["aiding"]))
        print(f"pitch {out['pitch_deg']:.4f} deg, roll {out['roll_deg']:.4f} deg, heading {out['heading_deg']:.4f} deg")
        print(f"base {out['base']}; predicted sigma {enu_text(out['sigma_arcmin'], 'none (the method gives none)')}")
        print(f"limit of the IMU's fixed biases: {enu_text(out['limit_arcmin'], 'none (' + str(out['limit_note']) + ')')}")
        print("inside the method's claim" if out["outside_claim"] is None else
              f"outside the method's claim: {out['outside_claim']}")
    return 0


#: Why ``align``'s ``limit_arcmin`` is null.
NO_LIMIT = {"imu": "no --imu: the limit is that of a named IMU's fixed biases",
            "moving": "a moving base: the static limit does not hold in motion (turns and accelerations make the "
                      "biases partly observable), and the moving one needs the trajectory"}


def answer_claims(method, res, imu, site, aiding, spec):
    """What ``align`` adds to an answer: the kind of base (``base``), the method's predicted sigma at the last sample
    (``sigma_arcmin``, from ``res.sigma_phi``; None without), the limit the fixed biases of ``spec`` put the
    misalignment at, at the answer's attitude and the site (``limit_arcmin``,
    :func:`fusionbench.scoring.metrics.theoretical_limits`; None without ``spec`` or on a moving base, ``limit_note``
    saying why) and why the answer lies outside the method's claim (``outside_claim``,
    :func:`fusionbench.bench.claim_check.outside_claim`; None inside). Angles are ``{"E", "N", "U"}`` misalignment
    components, ENU, arcmin."""
    from fusionbench.bench.claim_check import base_kind, outside_claim
    from fusionbench.scoring.metrics import theoretical_limits

    base = base_kind(imu, aiding)
    sigma = None if res.sigma_phi is None else enu_arcmin(res.sigma_phi[0, -1])
    limit, note = None, NO_LIMIT["imu"] if spec is None else NO_LIMIT["moving"] if base == "moving" else None
    if note is None:
        limit = enu_arcmin(theoretical_limits(spec.gyro.bias, spec.accel.bias, res.C_bn_final[0], site.lat, site.h))
    return {"base": base, "sigma_arcmin": sigma, "limit_arcmin": limit, "limit_note": note,
            "outside_claim": outside_claim(method, imu, site, aiding=aiding, spec=spec)}


def enu_arcmin(phi):
    """``{"E", "N", "U"}`` of a misalignment vector (3,) in rad, in arcmin (None for a value that is not finite)."""
    return {k: float(v / units.ARCMIN) if np.isfinite(v) else None for k, v in zip("ENU", np.asarray(phi, float))}


def enu_text(enu, none):
    """``E x, N y, U z arcmin`` of :func:`enu_arcmin`'s dict, or ``none``."""
    if enu is None:
        return none
    return ", ".join(f"{k} {'n/a' if v is None else f'{v:.3g}'}" for k, v in enu.items()) + " arcmin"


def aiding_line(info):
    """One line on the rows used (:func:`aiding_json`)."""
    return (f"aiding {info['file']} ({info['format']}): {info['rows']} rows of {', '.join(info['kinds'])}, lever arm "
            f"{','.join(f'{x:g}' for x in info['lever_arm_m'])} m, latency {info['delay_s']:g} s")


def cmd_identify(args):
    from fusionbench.recording.identify import run_identify

    imu, _ = read_record(args)
    name = args.name or Path(args.imu_file).stem
    for line in run_identify(imu, Path(args.out), name=name, source=str(args.imu_file)):
        print(line)
    return 0


def cmd_consistency(args):
    from fusionbench.files import reportdir
    from fusionbench.recording.consistency import consistency
    from fusionbench.recording.consistency_report import OUTPUT, summary_lines, write_consistency_report

    methods = [m for m in args.methods.split(",") if m]
    if not methods:
        raise ValueError(f"--methods: expected comma-separated method names, found {args.methods!r}")
    for spec in methods:  # each one builds, or one line names it, before the record is read
        named(spec, lambda: load_method(spec, imu=None if args.imu is None else load_spec(args.imu)),
              group=METHODS_GROUP)
    record_site(args, {})
    aiding = read_aiding_file(args)
    imu, meta = read_record(args)
    site = record_site(args, meta)
    created = reportdir.prepare([Path(args.out)], OUTPUT)  # a folder it may not replace: refused before any work
    try:
        res = consistency(imu, site, methods, window_s=args.window, imu_model=args.imu,  # a bar on a terminal
                          aiding=aiding)
        about = None if aiding is None else aiding_json(args, aiding)
        paths = write_consistency_report(res, Path(args.out), aiding=about)
    except BaseException:
        reportdir.remove_empty(created)
        raise
    print(f"{args.imu_file}: {imu.duration:.0f} s at {1 / imu.dt:g} Hz, site {np.degrees(site.lat):.4f} deg latitude")
    if about is not None:
        print(aiding_line(about))
    for line in summary_lines(res):
        print(line)
    print(f"written: {', '.join(map(str, paths))}")
    return 0
