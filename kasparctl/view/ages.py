"""Times as the view shows them: a record's clock time, and "12 s ago" with when it changes.

Records carry their time as UTC ISO 8601 (the robot's wall clock, which may be
hours or years off: kasparctl.game.wallclock) and `clock`, the daemon's
monotonic seconds. How long ago something was is measured on the monotonic
clock wherever both ends count in the same run of the daemon (`Now.run`; the
live view only on the robot's own boot), and on the wall clock only where they
do not. The view must be drawn again when a reading changes: next_change says
when, and the live loop sleeps until then, never on a fixed tick.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Now:
    """The moment the view is drawn for: the wall clock's, and the session's monotonic
    seconds then with the run of the daemon they count in (None: not known here)."""

    wall: dt.datetime
    clock: float | None = None
    run: str | None = None


@dataclass(frozen=True, slots=True)
class Stamp:
    """When something was recorded: its wall time, its monotonic seconds and their run."""

    time: str | None
    clock: float | None = None
    run: str = ""


def _now(now: Now | dt.datetime) -> Now:
    return now if isinstance(now, Now) else Now(now)


def _stamp(then: Stamp | str | None) -> Stamp:
    return then if isinstance(then, Stamp) else Stamp(then)


def seconds_since(then: Stamp | str | None, now: Now | dt.datetime) -> float | None:
    """How long before `now` `then` was: on the monotonic clock within one run of the
    daemon, else on the wall clock; None when it cannot be told."""
    stamp, moment = _stamp(then), _now(now)
    if (
        moment.clock is not None
        and stamp.clock is not None
        and stamp.run
        and stamp.run == moment.run
        and moment.clock >= stamp.clock
    ):
        return moment.clock - stamp.clock
    when = parse_time(stamp.time)
    return None if when is None else (moment.wall - when).total_seconds()


def parse_time(text: str | None) -> dt.datetime | None:
    """A record's time (ISO 8601; UTC when it names no zone); None if it is not one."""
    if not text:
        return None
    try:
        when = dt.datetime.fromisoformat(text)
    except ValueError:
        return None
    return when if when.tzinfo is not None else when.replace(tzinfo=dt.UTC)


def ago(then: Stamp | str | None, now: Now | dt.datetime) -> str:
    """How long ago `then` (a Stamp, or a UTC ISO 8601 time) was, in words a glance reads:
    "12 s ago"."""
    seconds = seconds_since(then, now)
    if seconds is None:
        return "?"
    if seconds < 1:
        return "just now"
    if seconds < 60:
        return f"{int(seconds)} s ago"
    if seconds < 3600:
        return f"{int(seconds // 60)} min ago"
    if seconds < 86400:
        return f"{int(seconds // 3600)} h ago"
    return f"{int(seconds // 86400)} d ago"


def next_change(then: Stamp | str | None, now: Now | dt.datetime) -> float | None:
    """Seconds until ago(then) reads differently; None if it never will (unknown time)."""
    since = seconds_since(then, now)
    if since is None:
        return None
    seconds = max(since, 0.0)
    unit = (
        1.0 if seconds < 60 else 60.0 if seconds < 3600 else 3600.0 if seconds < 86400 else 86400.0
    )
    return unit - math.fmod(seconds, unit)


def clock_time(text: str | None) -> str:
    """The local wall-clock time of a record, HH:MM:SS."""
    when = parse_time(text)
    return when.astimezone().strftime("%H:%M:%S") if when is not None else "--:--:--"
