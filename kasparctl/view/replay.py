"""A finished (or any) session replayed in the live view, record by record, at its own pace.

The records are shown at the pace they were written (their `clock`, the
robot's monotonic seconds), `speed` times faster; a gap longer than
MAX_GAP_S (a break, a restart of the daemon, whose clock starts anew) is
shortened to it. Keys: space pauses and goes on, right and left (or n and
p) step one record while paused, + and - double and halve the speed, Home
and End (or g and G) go to the start and the end, q quits. "How long ago"
on screen is measured from the record shown, not from today.
"""

from __future__ import annotations

import datetime as dt
import itertools
import selectors
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from hal.errors import KasparError
from kasparctl.game.jsonl import read_records
from kasparctl.game.records import AnyRecord
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE
from kasparctl.view.ages import Now, parse_time
from kasparctl.view.fold import SessionFold
from kasparctl.view.follow import read_plan
from kasparctl.view.frame import frame
from kasparctl.view.live import QUIT_KEYS, Waker
from kasparctl.view.model import SessionView, WatchView
from kasparctl.view.screen import Keys, Screen

MAX_GAP_S = 5.0
# A record whose clock goes back (a new daemon's clock) is shown this long after the last.
RESTART_GAP_S = 1.0
MIN_SPEED, MAX_SPEED = 1 / 16, 1024.0


class ReplayError(KasparError):
    """A session to replay that cannot be found or read; names what was looked for."""


def find_session(name: str, state_dir: Path | None) -> Path:
    """A session directory: `name` as a path to one, or a session id in `state_dir`."""
    given = Path(name)
    if (given / PLAN_FILE).is_file() or (given / RECORDS_FILE).is_file():
        return given
    if state_dir is not None:
        candidate = state_dir / "sessions" / name
        if (candidate / PLAN_FILE).is_file() or (candidate / RECORDS_FILE).is_file():
            return candidate
        where = f"{given} nor {candidate}"
    else:
        where = f"{given}"
    raise ReplayError(
        f"{name}: no session to replay: expected a session directory (with {PLAN_FILE} and "
        f"{RECORDS_FILE}), found neither {where}"
    )


def gaps(records: Sequence[AnyRecord]) -> list[float]:
    """Seconds of the session between each record and the one before (0 for the first)."""
    waits = [0.0]
    for before, after in itertools.pairwise(records):
        gap = after.clock - before.clock
        waits.append(RESTART_GAP_S if gap < 0 else min(gap, MAX_GAP_S))
    return waits


@dataclass
class Position:
    """Where the replay is: records shown, speed, paused."""

    shown: int
    total: int
    speed: float
    paused: bool

    def describe(self, has_keys: bool) -> str:
        """The footer: where, how fast, and the keys."""
        state = "paused" if self.paused else f"x{self.speed:g}"
        if self.shown >= self.total:
            state = "end"
        keys = "  space pause  <- -> step  +/- speed  q quit" if has_keys else ""
        return f"replay {self.shown}/{self.total} records  {state}{keys}"


class Replay:
    """The view of one session's records, shown one after another on a screen."""

    def __init__(
        self, directory: Path, screen: Screen, keys: Keys | None = None, speed: float = 1.0
    ) -> None:
        """Replay the session in `directory` on `screen`, `speed` times its own pace."""
        read = read_records(directory / RECORDS_FILE)
        if not read.records:
            raise ReplayError(f"{directory / RECORDS_FILE}: no records to replay")
        self.directory = directory
        self.plan = read_plan(directory)
        self.records = read.records
        self.warnings = read.warnings
        self.waits = gaps(read.records)
        self.screen = screen
        self.keys = keys
        self.position = Position(0, len(read.records), speed, paused=False)
        self._fold = SessionFold(self.plan)
        self._folded = 0  # records the fold has taken
        self.waker = Waker()

    def session_at(self, shown: int) -> SessionView:
        """The view after the first `shown` records (moving on from the last one if it can)."""
        if shown < self._folded:
            self._fold = SessionFold(self.plan)
            self._folded = 0
        for record in self.records[self._folded : shown]:
            self._fold.apply(record)
        self._folded = shown
        view = replace(self._fold.view, warnings=tuple(self.warnings))
        return view if view.session else replace(view, session=self.directory.name)

    def view_at(self, shown: int) -> WatchView:
        """The whole picture after `shown` records."""
        return WatchView(
            state_dir=str(self.directory.parent.parent),
            session=self.session_at(shown),
            sessions=1,
            footer=self.position.describe(self.keys is not None),
        )

    def now_at(self, shown: int) -> Now:
        """The replay's "now": the moment of the last record shown, on the session's
        monotonic clock (its `clock`, in its run of the daemon) and its wall clock."""
        record = self.records[max(shown - 1, 0)]
        wall = parse_time(record.time) or dt.datetime.now(dt.UTC)
        return Now(wall, record.clock, self.session_at(shown).run)

    def draw(self) -> None:
        """Show the picture at the current position."""
        shown = self.position.shown
        width, height = self.screen.size()
        view = self.view_at(shown)
        self.screen.draw(frame(view, self.now_at(shown), width, height, self.screen.glyphs))

    def run(self) -> None:
        """Play to the end (and wait for q there when there are keys)."""
        position = self.position
        with selectors.DefaultSelector() as selector:
            selector.register(self.waker.read_fd, selectors.EVENT_READ, "wake")
            if self.keys is not None:
                selector.register(self.keys, selectors.EVENT_READ, "keys")
            due = time.monotonic()
            while True:
                at_end = position.shown >= position.total
                if not position.paused and not at_end and time.monotonic() >= due:
                    position.shown += 1
                    following = position.shown
                    wait = self.waits[following] if following < position.total else 0.0
                    due = max(due, time.monotonic() - 1.0) + wait / position.speed
                self.draw()
                if position.shown >= position.total and self.keys is None:
                    return
                timeout = (
                    None
                    if position.paused or position.shown >= position.total
                    else max(due - time.monotonic(), 0.0)
                )
                for key, _ in selector.select(timeout):
                    if key.data == "wake":
                        self.waker.drain()
                    elif key.data == "keys" and self.keys is not None:
                        for pressed in self.keys.read():
                            if pressed in QUIT_KEYS:
                                return
                            due = self._key(pressed, due)

    def _key(self, pressed: str, due: float) -> float:
        """Act on one key; the new moment the next record is due."""
        position = self.position
        if pressed == " ":
            position.paused = not position.paused
            return time.monotonic()
        if pressed in ("right", "n"):
            position.paused = True
            position.shown = min(position.shown + 1, position.total)
        elif pressed in ("left", "p"):
            position.paused = True
            position.shown = max(position.shown - 1, 0)
        elif pressed in ("home", "g"):
            position.shown = 0
        elif pressed in ("end", "G"):
            position.shown = position.total
        elif pressed == "+":
            position.speed = min(position.speed * 2, MAX_SPEED)
        elif pressed == "-":
            position.speed = max(position.speed / 2, MIN_SPEED)
        return due

    def close(self) -> None:
        """Close the wake-up pipe."""
        self.waker.close()
