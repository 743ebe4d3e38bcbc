"""The events of a run on its figures' time axis: what happens during a record (noise jumps, manoeuvres, the
experiment's phases, a method's own stages), collected as :class:`Event`, marked by number on a panel and named in
a note under the figure.

Events of a method come from an optional ``events(init_given)`` method of the method object (duck-typed):
it returns a list of ``(t_s, label)`` for an instant or ``(t0_s, t1_s, label)`` for a span, times in s from
the start of the record, e.g. ``[(60.0, "coarse -> fine")]``. ``init_given`` tells whether the scenario
hands the method an initial attitude (a coarse stage of its own is skipped then).
"""

from __future__ import annotations

from dataclasses import dataclass




@dataclass(frozen=True)
class Event:
    """Something that happens during a record: an instant (``t1_s`` None) or a span, s from the start.
    ``methods`` names the methods it belongs to (empty: the scenario's); ``shade`` False draws a span's
    bounds only (phases that tile the record)."""

    t0_s: float
    t1_s: float | None
    label: str
    methods: tuple = ()
    shade: bool = True


def scenario_events(scn, duration_s):
    """Events of a scenario: noise schedules of the IMU and of the velocity reference, the jump window of
    the metrics, the motion segments (a manoeuvre) and the experiment's own (its optional
    ``events(scn, duration_s)``, e.g. the segments of a scheme the experiment runs through)."""
    ev = []
    for s in scn.imu_spec.schedules:
        who = "IMU" if set(s.sensors) == {"gyro", "accel"} else "+".join(s.sensors)
        ev.append(Event(s.start, s.end, f"{who} white-noise PSD x{s.factor:g}"))
    for s in scn.vref_spec.schedules:
        ev.append(Event(s.start, s.end, f"reference-velocity noise variance x{s.factor:g}"))
    for feature in scn.features:  # e.g. a jump window, unless a schedule already spans it
        ev += [e for e in feature.events() if not any(o.t0_s == e.t0_s and o.t1_s == e.t1_s for o in ev)]
    for t0, t1, label in scn.translation.manoeuvres():  # a manoeuvre, a drive's turn, unless the whole record
        if not (t0 <= 0 and t1 >= duration_s):
            ev.append(Event(t0, t1, label))
    exp = scn.experiment_type
    if hasattr(exp, "events"):  # the experiment's own phases
        ev += exp.events(scn, duration_s)
    return ev


def method_events(methods, init_given):
    """Events that methods report about themselves through ``events(init_given)`` (module notes); the same
    event of several methods is one :class:`Event` naming them all. ``methods`` maps names to method objects."""
    seen = {}
    for name, obj in methods.items():
        if not hasattr(obj, "events"):
            continue
        for item in obj.events(init_given):
            t0, t1, label = (item[0], None, item[1]) if len(item) == 2 else item
            seen.setdefault((float(t0), None if t1 is None else float(t1), label), []).append(name)
    return [Event(t0, t1, label, tuple(ns)) for (t0, t1, label), ns in seen.items()]


def in_record(events, duration_s):
    """The events that start inside the record (0, duration_s], sorted by time."""
    return sorted((e for e in events if 0 < e.t0_s <= duration_s or (e.t1_s is not None and e.t0_s <= 0 < e.t1_s)),
                  key=lambda e: e.t0_s)


def mark_events(ax, events, scale=1.0, names=None, numbers=True):
    """Mark ``events`` on ``ax`` (x in s / ``scale``): spans lightly shaded, instants as dotted lines, each with
    its number (1-based, the order of ``events``) at the top when ``numbers``. A method's event is drawn only
    in a panel showing that method (``names``; None: every panel)."""
    for i, e in enumerate(events, 1):
        if names is not None and e.methods and not set(e.methods) & set(names):
            continue
        x0 = e.t0_s / scale
        if e.t1_s is None:
            ax.axvline(x0, color="0.3", ls=":", lw=1.0)
        elif e.shade:
            ax.axvspan(x0, e.t1_s / scale, color="gold", alpha=0.15, lw=0)
        else:
            ax.axvline(x0, color="0.6", ls="-", lw=0.6)
        if numbers:
            xm = x0 if e.t1_s is None else 0.5 * (x0 + e.t1_s / scale)
            ax.annotate(str(i), (xm, 1.0), xycoords=("data", "axes fraction"), xytext=(0, 1),
                        textcoords="offset points", ha="center", va="bottom", fontsize=7, color="0.2",
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "0.5", "lw": 0.5})


def events_note(events, scale=1.0, unit="s"):
    """The legend of the event numbers, one paragraph ("" when there are none)."""
    def t(x):
        return f"{x / scale:.4g} {unit}"

    parts = []
    for i, e in enumerate(events, 1):
        when = f"at {t(e.t0_s)}" if e.t1_s is None else f"{t(e.t0_s)} to {t(e.t1_s)}"
        who = f" ({', '.join(e.methods)})" if e.methods else ""
        parts.append(f"[{i}] {e.label}{who}, {when}")
    return "Events: " + "; ".join(parts) + "." if parts else ""
