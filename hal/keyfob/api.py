"""What the game sees of the keyfob: one stream of gestures and keyfob-lost/back events.

The real keyfob (hal.keyfob.reader.Keyfob) and its simulated twins
(hal.keyfob.sim) all satisfy KeyfobInput; the game imports only this module
and hal.keyfob.gestures.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from hal.keyfob.gestures import Gesture, GestureNeeds


@dataclass(frozen=True, slots=True)
class KeyfobLost:
    """The keyfob stopped answering (unplugged, battery, out of range); reopening goes on."""

    at: float
    reason: str
    # With one keyfob per child (hal.keyfob.seats): whose seat's keyfob.
    seat: int | None = None


@dataclass(frozen=True, slots=True)
class KeyfobBack:
    """The keyfob is read again; keys held while it was away are forgotten."""

    at: float
    device: str
    seat: int | None = None


InputEvent = Gesture | KeyfobLost | KeyfobBack


class KeyfobInput(Protocol):
    """A keyfob as a stream of InputEvent, in the order they became certain."""

    async def start(self) -> None:
        """Open the keyfob (or start watching for it); returns without waiting for it."""
        ...

    async def next_event(self) -> InputEvent:
        """The next gesture or lost/back event; waits as long as it takes."""
        ...

    def set_needs(self, needs: GestureNeeds) -> None:
        """Which gestures the game listens for; fewer needs deliver presses sooner."""
        ...

    @property
    def connected(self) -> bool:
        """True while the keyfob is open and read."""
        ...

    async def close(self) -> None:
        """Stop reading and release the device; idempotent."""
        ...
