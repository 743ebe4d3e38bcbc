"""NMEA 0183 logs as aiding rows: RMC, GGA, VTG and GST sentences, parsed by pynmea2, one row per epoch.

* **Sentences.** Each non-blank line not starting with ``#`` is one sentence, parsed by :func:`pynmea2.parse` with
  its checksum checked (a sentence without one, or with a wrong one, is refused). Sentences of other types (GSA,
  GSV, a receiver's proprietary ones) are skipped; so are those of a type pynmea2 does not know. Any talker (GP,
  GN, GL, GA, ...).
* **Epochs.** Consecutive RMC, GGA and GST sentences with the same time of day make one epoch (the first of a type
  counts when a type repeats in it); VTG has no time and belongs to the epoch of the sentence before it (one
  before any timed sentence is skipped).
* **Time.** Seconds since 00:00 UTC of the first epoch's date: a time of day that falls back by more than 12 h
  is the next day, and an RMC's date sets the day of its epoch (GGA carries none).
* **Invalid fixes.** An epoch whose RMC has status V (or mode N) or whose GGA has fix quality 0 (or none) is
  skipped whole; a VTG of mode N is ignored.
* **Position.** GGA's latitude, longitude and altitude plus geoid separation (the height above the ellipsoid; an
  empty separation counts as 0: the receiver gives the ellipsoidal height as the altitude); RMC's latitude and
  longitude (height not measured) when the epoch has no GGA.
* **Velocity.** Speed over ground (VTG's knots, else its km/h, else RMC's knots) along the true course (deg
  clockwise from north): ``vE = s sin(course)``, ``vN = s cos(course)``, ``vU`` not measured (NaN). A speed of
  zero without a course is a zero velocity; a speed without a course is not measured.
* **Position sigmas.** GST's standard deviations of latitude, longitude and altitude (m) as ``sigma_p`` (E = the
  longitude's, N = the latitude's, U = the altitude's). An epoch without a GST takes the latest one before it (in
  an epoch of its own too; the first one for the epochs before any); without any GST ``sigma_p`` is None (the
  method's own figure). No velocity sigma: ``sigma_v`` None.
"""

from __future__ import annotations

import datetime
from decimal import Decimal

import numpy as np
import pynmea2

from fusionbench.files.aidingtext import AidingFileError, text_lines
from fusionbench.files.imufiles import _cell
from fusionbench.simulation import units

#: One day, s; a time of day that falls back by more than half of it is the next day.
DAY_S = 86400.0
TYPES = ("RMC", "GGA", "VTG", "GST")


def read_nmea_rows(path) -> dict:
    """The epochs of an NMEA log (module docstring) as the fields of :class:`~fusionbench.simulation.aiding.Aiding`
    (times not yet checked), with ``where(k)`` naming epoch k (its first sentence's line) for messages."""
    epochs = _epochs(path)
    rows, skipped = [], 0
    date0, day, prev_tod, gst, first_gst = None, 0, None, None, None
    for ep in epochs:
        tod = ep["tod"]
        if prev_tod is not None and tod < prev_tod - DAY_S / 2:  # past midnight
            day += 1
        prev_tod = tod
        date = _date(path, ep)
        if date is not None:
            if date0 is None:
                date0 = date - datetime.timedelta(days=day)
            day = (date - date0).days
        if not _valid(path, ep):
            skipped += 1
            continue
        gst = _gst(path, ep) or gst  # the latest GST, its own epoch's or one before (a GST alone is an epoch too)
        first_gst = first_gst or gst
        pos = _position(path, ep)
        vel = _velocity(path, ep)
        if pos is None and vel is None:
            continue
        rows.append((ep["line"], tod + DAY_S * day, pos, vel, gst))
    if not rows:
        raise AidingFileError(path, f"no rows: expected RMC, GGA or VTG sentences of a valid fix, found "
                                    f"{len(epochs)} epochs" + (f" ({skipped} of an invalid fix)" if skipped else ""))
    lines = [r[0] for r in rows]
    nan3 = (np.nan,) * 3
    pos = np.array([r[2] if r[2] is not None else nan3 for r in rows], dtype=float)
    vel = np.array([r[3] if r[3] is not None else nan3 for r in rows], dtype=float)
    has_p = np.isfinite(pos[:, 0])
    out = {"t": np.array([r[1] for r in rows]), "where": lambda k: f"epoch {k} (line {lines[k]})",
           "velocity": vel if np.isfinite(vel[:, 0]).any() else None, "position": pos if has_p.any() else None,
           "sigma_v": None, "sigma_p": None, "at_rest": None}
    if first_gst is not None and has_p.any():  # the epochs before the first GST take it
        out["sigma_p"] = np.array([r[4] or first_gst for r in rows], dtype=float)
    return out


def _epochs(path):
    """The sentences of the log grouped by epoch: dicts ``{"line", "tod", type: (line, sentence)}``."""
    epochs, cur = [], None
    for line, text in text_lines(path):
        try:
            msg = pynmea2.parse(text.strip(), check=True)
        except pynmea2.SentenceTypeError:  # a type pynmea2 does not know: not one of ours
            continue
        except pynmea2.ChecksumError as exc:
            why = exc.args[0] if exc.args else "checksum"
            while isinstance(why, tuple) and why:  # pynmea2's (message, fields)
                why = why[0]
            raise AidingFileError(path, f"line {line}: {why} (expected a sentence ending *HH, its checksum), found "
                                        f"{_cell(text.strip())}") from None
        except pynmea2.ParseError:
            raise AidingFileError(path, f"line {line}: expected an NMEA 0183 sentence ($..., *HH), found "
                                        f"{_cell(text.strip())}") from None
        kind = getattr(msg, "sentence_type", None)
        if kind not in TYPES:
            continue
        if kind == "VTG":
            if cur is not None:
                cur.setdefault(kind, (line, msg))
            continue
        ts = msg.timestamp
        if not isinstance(ts, datetime.time):
            raise AidingFileError(path, f"line {line}: {kind} time: expected hhmmss.ss, found {_cell(str(ts))}")
        tod = ts.hour * 3600.0 + ts.minute * 60.0 + ts.second + ts.microsecond * 1e-6
        if cur is None or tod != cur["tod"]:
            cur = {"line": line, "tod": tod}
            epochs.append(cur)
        cur.setdefault(kind, (line, msg))
    return epochs


def _field(path, entry, name):
    """Field ``name`` of a sentence ``entry`` (line, sentence) as a float, None when empty; a non-number is
    refused naming the line."""
    line, msg = entry
    v = getattr(msg, name)
    if v is None or v == "":
        return None
    if isinstance(v, (int, float, Decimal)) and not isinstance(v, bool):
        return float(v)
    try:
        return float(v)
    except ValueError:
        raise AidingFileError(path, f"line {line}: {msg.sentence_type} field '{name}': expected a number, found "
                                    f"{_cell(str(v))}") from None


def _date(path, ep):
    """The RMC's date of an epoch, or None."""
    if "RMC" not in ep:
        return None
    line, msg = ep["RMC"]
    d = msg.datestamp
    if d is None or d == "":
        return None
    if not isinstance(d, datetime.date):
        raise AidingFileError(path, f"line {line}: RMC date: expected ddmmyy, found {_cell(str(d))}")
    return d


def _valid(path, ep):
    """Whether the epoch is a valid fix: RMC status A (mode not N), GGA quality above 0."""
    if "RMC" in ep:
        msg = ep["RMC"][1]
        if msg.status != "A" or getattr(msg, "mode_indicator", "") == "N":
            return False
    if "GGA" in ep:
        q = _field(path, ep["GGA"], "gps_qual")
        if not q:
            return False
    return True


def _latlon(path, entry):
    """(lat, lon) in rad of an RMC or GGA, None when empty."""
    line, msg = entry
    if not (msg.lat and msg.lon):
        return None
    for value, hemi, ok in ((msg.lat, msg.lat_dir, "NS"), (msg.lon, msg.lon_dir, "EW")):
        if hemi not in tuple(ok):
            raise AidingFileError(path, f"line {line}: {msg.sentence_type}: expected a hemisphere "
                                        f"{' or '.join(ok)} after {value}, found {_cell(hemi)}")
    try:
        return np.radians(msg.latitude), np.radians(msg.longitude)
    except ValueError:
        raise AidingFileError(path, f"line {line}: {msg.sentence_type} position: expected ddmm.mmm and "
                                    f"dddmm.mmm, found {_cell(msg.lat)}, {_cell(msg.lon)}") from None


def _position(path, ep):
    """(lat rad, lon rad, h m) of the epoch, h NaN without GGA; None without a position."""
    if "GGA" in ep:
        ll = _latlon(path, ep["GGA"])
        if ll is not None:
            alt = _field(path, ep["GGA"], "altitude")
            sep = _field(path, ep["GGA"], "geo_sep")
            return ll + (np.nan if alt is None else alt + (sep or 0.0),)
    if "RMC" in ep:
        ll = _latlon(path, ep["RMC"])
        if ll is not None:
            return ll + (np.nan,)
    return None


def _velocity(path, ep):
    """(vE, vN, NaN) m/s of the epoch from VTG (mode not N), else RMC; None when not measured."""
    speed = course = None
    vtg = ep.get("VTG")
    if vtg is not None and getattr(vtg[1], "faa_mode", "") != "N":
        kts, kmh = _field(path, vtg, "spd_over_grnd_kts"), _field(path, vtg, "spd_over_grnd_kmph")
        speed = kts * units.KNOT if kts is not None else None if kmh is None else kmh * units.KM_PER_H
        course = _field(path, vtg, "true_track")
    if speed is None and "RMC" in ep:
        kts = _field(path, ep["RMC"], "spd_over_grnd")
        speed = None if kts is None else kts * units.KNOT
        course = _field(path, ep["RMC"], "true_course")
    if speed is None or (course is None and speed != 0.0):
        return None
    c = np.radians(course or 0.0)
    return speed * np.sin(c), speed * np.cos(c), np.nan


def _gst(path, ep):
    """GST's (sigma E, N, U) m of the epoch, or None (no GST, or one with an empty or zero figure)."""
    if "GST" not in ep:
        return None
    s = [_field(path, ep["GST"], f"std_dev_{n}") for n in ("longitude", "latitude", "altitude")]
    return None if any(x is None or not x > 0 for x in s) else tuple(s)  # 0: a receiver's "not known"
