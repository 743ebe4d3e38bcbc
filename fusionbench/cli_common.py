"""What the command line's modules share: argparse types and the one-line naming of a method's failure."""

from __future__ import annotations

import argparse
import math

from fusionbench.methods.aligner import entry_class


def integer(expected, ok):
    """An argparse type: an integer for which ``ok`` holds, else one line saying what was ``expected``."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not ok(value):
            raise argparse.ArgumentTypeError(f"expected {expected}, found {text!r}")
        return value
    return parse


def seconds(text):
    """An argparse type: a finite number (of seconds), else one line saying what was expected."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a number of seconds, found {text!r}")
    return value


def named(spec, call, what="", also=(), group=None):
    """``call()``, an error in it turned into one ValueError naming method ``spec`` and the exception (``what``:
    the call, for the message); a ValueError that names ``spec`` or one of ``also`` (the method's own name: a
    method refusing the data says who refuses) is left as it is. With ``group`` (its entry-point group) a
    ``module:Class`` spec must name something callable."""
    module, colon, cls = spec.partition(":")
    if colon and not (module and cls):
        raise ValueError(f"method {spec!r}: expected a registered name or module:Class, found {spec!r}")
    try:
        if colon and group:  # a module:Class path: something to instantiate
            obj = entry_class(group, spec, "method")
            if not callable(obj):
                raise ValueError(f"method {spec!r}: expected a class, found {kind(obj)}")
        return call()
    except ValueError as exc:
        if any(name and name in str(exc) for name in (spec, *also)):
            raise
        raise ValueError(f"method {spec!r}: {exception_text(exc)}") from exc
    except Exception as exc:  # a user's module:Class raising, not a class, not importable (SyntaxError)
        raise ValueError(f"method {spec!r}: {what}raised {exception_text(exc)}") from exc


def kind(value):
    name = type(value).__name__
    return "None" if value is None else f"{'an' if name[0] in 'aeiou' else 'a'} {name}"


def exception_text(exc):
    """``Type: first line of the message`` (the message alone for a ValueError or an OSError)."""
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if isinstance(exc, (ValueError, OSError)) and msg:
        return msg
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


