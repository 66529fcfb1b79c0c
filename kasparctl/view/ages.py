"""Times as the view shows them: a record's clock time, and "12 s ago" with when it changes.

Records carry their time as UTC ISO 8601; the view says how long ago a fault
was, so it must be drawn again when that reading changes: next_change says
when, and the live loop sleeps until then, never on a fixed tick.
"""

from __future__ import annotations

import datetime as dt
import math


def parse_time(text: str | None) -> dt.datetime | None:
    """A record's time (ISO 8601; UTC when it names no zone); None if it is not one."""
    if not text:
        return None
    try:
        when = dt.datetime.fromisoformat(text)
    except ValueError:
        return None
    return when if when.tzinfo is not None else when.replace(tzinfo=dt.UTC)


def ago(then: str | None, now: dt.datetime) -> str:
    """How long ago `then` (UTC ISO 8601) was, in words a glance reads: "12 s ago"."""
    when = parse_time(then)
    if when is None:
        return "?"
    seconds = (now - when).total_seconds()
    if seconds < 1:
        return "just now"
    if seconds < 60:
        return f"{int(seconds)} s ago"
    if seconds < 3600:
        return f"{int(seconds // 60)} min ago"
    if seconds < 86400:
        return f"{int(seconds // 3600)} h ago"
    return f"{int(seconds // 86400)} d ago"


def next_change(then: str | None, now: dt.datetime) -> float | None:
    """Seconds until ago(then) reads differently; None if it never will (unknown time)."""
    when = parse_time(then)
    if when is None:
        return None
    seconds = max((now - when).total_seconds(), 0.0)
    unit = (
        1.0 if seconds < 60 else 60.0 if seconds < 3600 else 3600.0 if seconds < 86400 else 86400.0
    )
    return unit - math.fmod(seconds, unit)


def clock_time(text: str | None) -> str:
    """The local wall-clock time of a record, HH:MM:SS."""
    when = parse_time(text)
    return when.astimezone().strftime("%H:%M:%S") if when is not None else "--:--:--"
