"""Validation of values read from TOML tables (scenario files, IMU spec files), one line per error.

Every error is a :class:`FieldError` (a ValueError) whose message names the file and the field, what
was expected and what was found: ``"my.toml: field 'imu.arw_dpsh': expected ..., found ..."``.
"""

from __future__ import annotations

import tomllib

import numpy as np


class FieldError(ValueError):
    """A file's field is missing or invalid; the message is one line naming the file and the field."""


def where(src, key):
    """``"<src>: field '<key>'"``, the start of every message."""
    return f"{src}: field '{key}'"


def is_number(v):
    """True for a finite int or float that is not a bool."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v))


#: What :func:`_value` returns for an absent key that has a default.
_ABSENT = object()


def _value(d, key, src, default, label):
    """``d[key]``; a FieldError when it is absent and required (``default`` None), else :data:`_ABSENT`."""
    if key in d:
        return d[key]
    if default is None:
        raise FieldError(f"{where(src, label)} is missing")
    return _ABSENT


def number(d, key, src, default=None, lo=-np.inf, hi=np.inf, label=None):
    """The number ``d[key]`` within ``[lo, hi]`` as a float, or ``default`` when absent (None: required)."""
    label = label or key
    v = _value(d, key, src, default, label)
    if v is _ABSENT:
        return default
    if not is_number(v) or not lo <= v <= hi:
        raise FieldError(f"{where(src, label)}: expected a number in [{lo:g}, {hi:g}], found {v!r}")
    return float(v)


def vector(d, key, src, default=(0.0, 0.0, 0.0), n=3, lo=-np.inf, hi=np.inf, label=None):
    """``n`` numbers (a list, or one number repeated) as a tuple of floats, or ``default`` when absent."""
    label = label or key
    if key not in d:
        return tuple(default)
    v = d[key]
    if is_number(v):
        v = [v] * n
    if not isinstance(v, list) or len(v) != n or not all(is_number(x) and lo <= x <= hi for x in v):
        bounds = "" if (lo, hi) == (-np.inf, np.inf) else f" in [{lo:g}, {hi:g}]"
        raise FieldError(f"{where(src, label)}: expected {n} numbers{bounds}, found {v!r}")
    return tuple(float(x) for x in v)


def string(d, key, src, default=None, choices=None, label=None):
    """The string ``d[key]`` (one of ``choices`` if given), or ``default`` when absent (None: required)."""
    label = label or key
    v = _value(d, key, src, default, label)
    if v is _ABSENT:
        return default
    if not isinstance(v, str) or (choices is not None and v not in choices):
        expected = f"one of {sorted(choices)}" if choices is not None else "a string"
        raise FieldError(f"{where(src, label)}: expected {expected}, found {v!r}")
    return v


def table(d, key, src, keys, label=None):
    """The sub-table ``d[key]`` (``{}`` when absent), checked to hold only ``keys``."""
    label = label or key
    t = d.get(key, {})
    if not isinstance(t, dict):
        raise FieldError(f"{where(src, label)}: expected a table, found {t!r}")
    bad = sorted(set(t) - set(keys))
    if bad:
        raise FieldError(f"{where(src, label + '.' + bad[0])}: unknown (expected one of {sorted(keys)})")
    return t


def read_toml(path, what):
    """The TOML file ``path`` as a dict, or a one-line ValueError naming the file when it is missing, a folder,
    unreadable or not TOML; ``what`` names the file expected (e.g. "layout file")."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such {what}") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: is a directory, expected a {what}") from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid TOML ({' '.join(str(exc).split())})") from None
