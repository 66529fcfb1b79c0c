"""Faults: what failed, which stages it stops, and what is not working now.

A HardwareFault is one failure the run loop takes: a part (a servo, the bus, the
keyfob, the voice, the disk) or a bug (an error in a step, or in handling an
input: `step_fault`, `error_fault`). STOPPED_BY says which stages each kind stops
(into the fault stage); in the others it is recorded and said, and the stage stays.

Problems is what is not working now, by part: one board for the daemon's life,
handed to each game, which sets an entry as a part fails and clears it as the part
comes back; the daemon's STATUS= shows it. When a game ends (`game_ended`) what
outlives it stays (the keyfob or the researcher's device still away, the voice or
the disk until a line is heard or a record written); a servo or a bug belongs to
the fault stage of its game, and the next game begins without it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import structlog

from hal.errors import HalError
from hal.servos.api import Fault
from kasparctl.game.records import FaultSource
from kasparctl.game.speech import VoiceFailed
from kasparctl.game.stages import FAULTABLE
from kasparctl.game.storage import StorageFailed

log = structlog.get_logger(__name__)

# The stages each kind of fault stops (into the fault stage); in the others it is
# recorded and said, and the stage stays. A lost keyfob stops a running step only.
STOPPED_BY: dict[FaultSource, tuple[str, ...]] = {
    kind: ("idle", *FAULTABLE, "paused") if kind is not FaultSource.KEYFOB else FAULTABLE
    for kind in FaultSource
}
# The researcher's own device going away stops nothing: their commands go to the
# children's keyfob as holds meanwhile.
STOPPED_BY[FaultSource.RESEARCHER] = ()
# Nor a keyfob that seems silent (its battery?): a press clears it.
STOPPED_BY[FaultSource.KEYFOB_SILENT] = ()
# What Kaspar says of each kind: words for the children; the joint, the bus and the
# reason are in the record, the journal and STATUS=.
FAULT_LINES: Mapping[FaultSource, str] = {
    FaultSource.SERVO: "fault.servo",
    FaultSource.KEYFOB: "fault.keyfob_lost",
    FaultSource.STORAGE: "fault.storage",
}
FAULT_LINE = "fault.problem"
# Not over with the game that saw them: the keyfob or the researcher's device still
# away (their reports were that game's), the voice or the disk until a line is heard
# or a record written.
OUTLIVE_A_GAME = frozenset(
    {FaultSource.KEYFOB, FaultSource.RESEARCHER, FaultSource.VOICE, FaultSource.STORAGE}
)


@dataclass(frozen=True, slots=True)
class HardwareFault:
    """A part failed (or a bug showed): the game stops (the fault stage) and Kaspar says so."""

    kind: FaultSource
    detail: str
    joint: str | None = None
    # What was raised, when it was (a storage fault's StorageFailed names the file).
    error: Exception | None = None

    @property
    def problem(self) -> str:
        """The fault as the problem it leaves: the joint first, where there is one."""
        return f"{self.joint}: {self.detail}" if self.joint else self.detail

    @property
    def line(self) -> str:
        """The phrase key Kaspar says of it."""
        return FAULT_LINES.get(self.kind, FAULT_LINE)


def servo_fault(fault: Fault) -> HardwareFault:
    """A fault the servos latched, as the run loop takes it."""
    return HardwareFault(FaultSource.SERVO, f"{fault.kind.value}: {fault.detail}", fault.joint)


def storage_fault(error: StorageFailed) -> HardwareFault:
    """A record, snapshot or directory the disk refused."""
    return HardwareFault(FaultSource.STORAGE, str(error), error=error)


def part_fault(error: BaseException) -> HardwareFault | None:
    """The part that `error` says failed (the voice, the disk, the servos); None for a bug."""
    if isinstance(error, VoiceFailed):
        return HardwareFault(FaultSource.VOICE, str(error))
    if isinstance(error, StorageFailed):
        return storage_fault(error)
    if isinstance(error, HalError):
        return HardwareFault(FaultSource.SERVO, str(error))
    return None


def step_fault(step: str, error: BaseException) -> HardwareFault:
    """What a step that failed with `error` tells of: the part that failed, or a bug (logged)."""
    fault = part_fault(error)
    if fault is not None:
        return fault
    log.error("step failed", step=step, exc_info=error)
    return HardwareFault(FaultSource.SOFTWARE, f"{step}: {error!r}")


def error_fault(error: Exception, doing: str) -> HardwareFault:
    """An error that escaped the run loop while `doing` something: the part that failed (a
    motion refused while a servo fault is latched is the servo's), or a bug (logged)."""
    fault = part_fault(error)
    if fault is not None:
        return fault
    log.error("software error", doing=doing, exc_info=error)
    return HardwareFault(FaultSource.SOFTWARE, f"{type(error).__name__}: {error} (while {doing})")


class Problems(Mapping[FaultSource, str]):
    """What is not working now, by part (why), for the daemon's life; read as a mapping.

    The game playing now is told of every change (`follow`): it tells its listeners.
    """

    def __init__(self) -> None:
        """All well, and nobody told yet."""
        self._now: dict[FaultSource, str] = {}
        self._on_change: Callable[[dict[FaultSource, str]], None] = lambda problems: None
        # Where the disk failed last: the event log (writing works again once it takes a
        # record) or a session's files (only they show it: sessions/ can be broken while
        # the event log is not).
        self.storage_in_event_log = False

    def __getitem__(self, kind: FaultSource) -> str:
        """Why `kind` is not working; KeyError when it works."""
        return self._now[kind]

    def __iter__(self) -> Iterator[FaultSource]:
        """The parts not working now."""
        return iter(self._now)

    def __len__(self) -> int:
        """How many parts are not working now."""
        return len(self._now)

    def follow(self, on_change: Callable[[dict[FaultSource, str]], None]) -> None:
        """From now on `on_change` is told every change (the game playing now)."""
        self._on_change = on_change

    def set(self, kind: FaultSource, detail: str | None, logged: bool = False) -> None:
        """`kind` is not working (`detail` says why), or works again (None); the game is told.

        A new problem is logged (at warning for the keyfob, error for the rest) unless
        the caller logs it (`logged`); one that clears is logged at info.
        """
        before = self._now.get(kind)
        if detail == before:
            return
        if detail is None:
            del self._now[kind]
            log.info("working again", part=kind.value)
        else:
            self._now[kind] = detail
            if before is None and not logged:
                say = log.warning if kind is FaultSource.KEYFOB else log.error
                say("not working", part=kind.value, detail=detail)
        self._on_change(dict(self._now))

    def storage_failed(self, error: StorageFailed) -> None:
        """A write failed (logged by the writer): the disk is a problem, where it failed."""
        self.storage_in_event_log = error.in_event_log
        self.set(FaultSource.STORAGE, str(error), logged=True)

    def game_ended(self) -> None:
        """The game is over: what outlives it stays (nobody is told: no game plays now).

        Where the disk failed is forgotten, as each game begins: a storage problem kept
        clears once a session's files take a record again.
        """
        self._now = {kind: why for kind, why in self._now.items() if kind in OUTLIVE_A_GAME}
        self.storage_in_event_log = False
        self._on_change = lambda problems: None
