"""The wall clock's state: whether it is synchronised, and when it jumps.

A Raspberry Pi has no real-time clock: after a power cut fake-hwclock puts
back its last save (up to an hour behind, or years where it never saved), and
without a network nothing corrects it, until a network appears and it jumps.
The records' order never depends on it (game.session.session_order, each
record's seq) and the ages the view shows are on the monotonic clock, but a
researcher reading a record's time must know whether to trust it: so each
session records the clock's state when it starts, and again whenever the wall
clock moves against the monotonic one by more than JUMP_S (docs/install.md
says how to give the robot a good clock).

Synchronised means systemd-timesyncd runs and timedatectl says
NTPSynchronized=yes; anything else (no timesyncd, no timedatectl, no answer)
is "unsynchronised". The commands, the wall clock and the monotonic clock are
injected, for tests.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from kasparctl.game.records import ClockRecord

# A jump smaller than this is NTP slewing or the scheduler, not a step of the clock.
JUMP_S = 2.0
# How long a probe command may take: timedatectl asks systemd over D-Bus.
PROBE_TIMEOUT_S = 2.0
BOOT_ID = "/proc/sys/kernel/random/boot_id"

SYNCHRONISED = "timesyncd"
UNSYNCHRONISED = "unsynchronised"

Runner = Callable[[Sequence[str]], str | None]


def run_quietly(command: Sequence[str]) -> str | None:
    """A command's standard output, stripped; None when it cannot run or fails."""
    try:
        done = subprocess.run(
            list(command),
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
            check=False,
            stdin=subprocess.DEVNULL,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


@dataclass(frozen=True, slots=True)
class ClockSource:
    """Where the wall clock's time comes from: `source` (SYNCHRONISED or UNSYNCHRONISED)."""

    source: str

    @property
    def synchronised(self) -> bool:
        """Whether the wall clock can be trusted."""
        return self.source == SYNCHRONISED


def clock_source(run: Runner = run_quietly) -> ClockSource:
    """timedatectl's NTPSynchronized where systemd-timesyncd runs, else unsynchronised."""
    if run(["systemctl", "is-active", "systemd-timesyncd"]) != "active":
        return ClockSource(UNSYNCHRONISED)
    answer = run(["timedatectl", "show", "--property=NTPSynchronized", "--value"])
    return ClockSource(SYNCHRONISED if answer == "yes" else UNSYNCHRONISED)


def boot_id(path: str = BOOT_ID) -> str:
    """This boot's id (the monotonic clock's reference: it starts anew at each boot)."""
    try:
        with open(path, encoding="ascii") as file:
            return file.read().strip()
    except OSError:
        return ""


@dataclass(frozen=True, slots=True)
class ClockReading:
    """The clock's state at one moment: its source, wall minus monotonic, and the step
    since the last reading (0.0 for the first)."""

    source: ClockSource
    offset: float
    step: float
    boot: str


class ClockWatch:
    """The wall clock watched against the monotonic one, for the daemon's life."""

    def __init__(
        self,
        run: Runner = run_quietly,
        wall: Callable[[], float] = time.time,
        monotonic: Callable[[], float] = time.monotonic,
        boot: Callable[[], str] = boot_id,
        jump_s: float = JUMP_S,
    ) -> None:
        """Probe with `run`; read the clocks with `wall` and `monotonic`."""
        self._run = run
        self._wall = wall
        self._monotonic = monotonic
        self._boot = boot
        self._jump_s = jump_s
        self._offset: float | None = None
        self.last: ClockReading | None = None

    def _offset_now(self) -> float:
        return self._wall() - self._monotonic()

    def read(self) -> ClockReading:
        """The clock's state now (probed again), as of the last jump noticed."""
        offset = self._offset_now()
        step = 0.0 if self._offset is None else offset - self._offset
        self._offset = offset
        source = clock_source(self._run)
        self.last = ClockReading(source, round(offset, 3), round(step, 3), self._boot())
        return self.last

    def jumped(self) -> ClockReading | None:
        """A new reading when the wall clock has stepped by more than the threshold since
        the last one, else None (nothing probed; a first call only takes the offset to
        measure from: a session's start reads the clock's state)."""
        if self._offset is None:
            self._offset = self._offset_now()
            return None
        if abs(self._offset_now() - self._offset) <= self._jump_s:
            return None
        return self.read()


def clock_record(reading: ClockReading) -> ClockRecord:
    """A reading as the record a session keeps of it."""
    return ClockRecord(
        synchronised=reading.source.synchronised,
        source=reading.source.source,
        offset=reading.offset,
        step=reading.step,
        boot=reading.boot,
    )
