"""What the game sees of Kaspar's body language: one small interface, and a body that does nothing.

The game says what Kaspar attends to and feels; the body decides how that looks. A body
never raises into the game for a servo problem (the joints layer latches faults and the
game hears of them there), and `cancel` ends everything at once and safely: a pause, a
fault or a stop must not wait for a behaviour to finish.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Protocol


class GazeKind(StrEnum):
    """Where Kaspar can look."""

    AHEAD = "ahead"
    CHILD = "child"
    BAG = "bag"
    RESEARCHER = "researcher"


@dataclass(frozen=True, slots=True)
class Gaze:
    """A target for Kaspar's head and eyes: a child's seat or a bag by its index (from 0)."""

    kind: GazeKind
    index: int = 0


class Body(Protocol):
    """Kaspar's body language as the game uses it; every method runs on the event loop."""

    async def start(self) -> None:
        """Begin the body's own loop (blinks, idle, gaze, mouth)."""
        ...

    async def close(self) -> None:
        """Cancel every behaviour and stop the loop; idempotent."""
        ...

    def set_alive(self, alive: bool, *, blinking: bool = False) -> None:
        """Allow or forbid blinks, idle movements and gaze (forbidden while the arm is
        limp for teaching); `blinking` keeps the blinks of a body otherwise still (while
        pointing: the head stays on the bag, the eyelids go on)."""
        ...

    def look_at(self, gaze: Gaze) -> None:
        """Turn the head (and eyes) towards `gaze`, when alive; returns at once."""
        ...

    async def perform(self, behaviour: str, strength: float = 1.0) -> None:
        """Play the named behaviour (greeting, happy, sad, thinking, nod, ...) to its end.

        `strength` from 0 to 1 scales it (the thinking behaviour's from the learner's
        normalised entropy). Returns early, without raising, when cancelled.
        """
        ...

    def cancel(self) -> None:
        """End every behaviour at once and safely (pause, fault, stop)."""
        ...


class StillBody:
    """A body that shows nothing: behaviours switched off, or a robot without a face."""

    async def start(self) -> None:
        """Nothing to start."""

    async def close(self) -> None:
        """Nothing to close."""

    def set_alive(self, alive: bool, *, blinking: bool = False) -> None:
        """Nothing comes alive."""

    def look_at(self, gaze: Gaze) -> None:
        """Kaspar keeps looking where it looks."""

    async def perform(self, behaviour: str, strength: float = 1.0) -> None:
        """Nothing is shown."""

    def cancel(self) -> None:
        """Nothing to end."""
