"""Record first: each record on disk (fsynced) before Kaspar reacts; those the disk refused
kept, to be written first once it takes records again.

One Recorder for the daemon's life, handed to each game. The game says where its
records go (`to`: its session, or the event log while none is open) and writes in
one of three ways: `write`, a record that must be on disk before it is acted on
(StorageFailed otherwise); `change`, a record that changes the session (write,
apply to GameState, snapshot: the order that makes a crash lose nothing); and
`record`, history that must never stop the game: a record the disk refuses is kept
(up to UNWRITTEN_LIMIT; every one is in the journal whole), the disk becomes a
problem (kasparctl.game.faults.Problems), and the game is told (`attach`).

What was kept is written before anything new, in order; `flush` writes it as far
as the disk takes it now (the daemon between games, the demo at its end). A
session opened again carries on its own kept records from its seq on disk.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, TypeVar, cast

import structlog

from kasparctl.config import GameSettings
from kasparctl.game.faults import Problems
from kasparctl.game.jsonl import record_to_plain
from kasparctl.game.records import FaultSource, Record
from kasparctl.game.session import EventLog, Session
from kasparctl.game.state import GameState
from kasparctl.game.storage import StorageFailed

log = structlog.get_logger(__name__)

# Records that could not be written (the disk full) are kept to write once it takes
# them again, up to this many; beyond, they are in the journal only.
UNWRITTEN_LIMIT = 200

RecordT = TypeVar("RecordT", bound=Record)
# Where a record goes, the record, and the loop's clock when it was made.
Unwritten = tuple[Session | EventLog, Record, float]


def loop_time() -> float:
    """The event loop's clock: what every record is stamped with."""
    return asyncio.get_running_loop().time()


class Recorder:
    """Where the game's records go, and those the disk refused, still to write."""

    def __init__(self, event_log: EventLog | None, problems: Problems) -> None:
        """Records go to `event_log` while no session is open (with none, they are only
        logged); the disk failing or working again is shown in `problems`."""
        self.event_log = event_log
        self.problems = problems
        self.session: Session | None = None
        self._unwritten: list[Unwritten] = []
        self._on_refused: Callable[[StorageFailed], None] = lambda error: None

    @property
    def unwritten(self) -> int:
        """How many records the disk refused are still to write."""
        return len(self._unwritten)

    def attach(self, on_refused: Callable[[StorageFailed], None]) -> None:
        """From now on `on_refused` (the game playing now) is told when the disk refuses."""
        self._on_refused = on_refused

    def to(self, session: Session | None) -> None:
        """From now on records go to `session` (None: the event log).

        Records kept for the same session directory go on from its seq on disk.
        """
        self.session = session
        if session is None:
            return
        self._unwritten = [
            (session if isinstance(t, Session) and t.directory == session.directory else t, r, c)
            for t, r, c in self._unwritten
        ]

    def write(self, record: RecordT) -> RecordT | None:
        """Record first, or not at all: to the session, or the event log when none is open.

        StorageFailed when it cannot be written (records kept from an earlier failure
        are written first, in order). None only when there is nowhere to write.
        """
        target: Session | EventLog | None = self.session or self.event_log
        if target is None:
            log.info("not recorded: no session is open", record=repr(record))
            return None
        self._write_kept()
        written = target.record(record, loop_time())
        # Writing works again, where it failed: a session's files show it for both, the
        # event log only for itself (sessions/ can be broken while the log is not).
        if isinstance(target, Session) or self.problems.storage_in_event_log:
            self.problems.set(FaultSource.STORAGE, None)
        return written

    def record(self, record: RecordT) -> RecordT | None:
        """Record history (a fault, an ignored press): never raises. One the disk refuses is
        kept to write later, logged whole, and stops the game (a storage fault)."""
        target: Session | EventLog | None = self.session or self.event_log
        try:
            return self.write(record)
        except StorageFailed as error:
            if target is not None and len(self._unwritten) < UNWRITTEN_LIMIT:
                self._unwritten.append((target, record, loop_time()))
            # The journal keeps what the disk could not, whole.
            log.error("record not written", error=str(error), record=_plain(record))
            self.refused(error)
            return None

    def refused(self, error: StorageFailed) -> None:
        """A write failed where nothing else stops for it: the disk is a problem, and the
        game is told."""
        self.problems.storage_failed(error)
        self._on_refused(error)

    def change(self, record: RecordT, state: GameState, settings: GameSettings) -> RecordT:
        """Record, apply, snapshot: the order that makes a crash lose nothing.

        StorageFailed when the record cannot be written (nothing is applied) or the
        snapshot cannot (the record is on disk and applied: a resume replays it).
        """
        session = self.session
        if session is None:
            raise RuntimeError("no session is open")
        written = self.write(record)
        assert written is not None  # a session is open
        state.apply(written, settings)
        session.save_state(state)
        return written

    def flush(self) -> int:
        """Write the records the disk refused, in order, as far as it takes them now.

        Returns how many are still unwritten (each is in the journal whole).
        """
        try:
            self._write_kept()
        except StorageFailed as error:
            log.error(
                "records still not written; the journal holds them",
                count=len(self._unwritten),
                error=str(error),
            )
        return len(self._unwritten)

    def _write_kept(self) -> None:
        while self._unwritten:
            target, kept, at = self._unwritten[0]
            target.record(kept, at)
            self._unwritten.pop(0)


def _plain(record: Record) -> dict[str, Any] | str:
    try:
        return record_to_plain(cast(Any, record))
    except (TypeError, ValueError):
        return repr(record)
