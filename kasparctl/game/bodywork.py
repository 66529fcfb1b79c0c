"""What the game asks of Kaspar's body, and how its uncertainty shapes a point.

The game says what Kaspar attends to and feels through kasparctl.body.api.Body; this
module is the game's side of it: the session plan's switches (`alive`: gaze and life;
the uncertainty mode: whether the body shows how sure Kaspar is), the arithmetic that
turns the learner's entropy into the thinking behaviour's strength and the way Kaspar
points, and the news of each ask for the game's listeners (the demo's transcript).

The mapping from uncertainty to the body (docs/body.md):

- strength h = entropy / log2(candidates), from 0 (sure) to 1 (no idea); one candidate
  left is 0. The thinking behaviour is performed with strength h before the point.
- the point's move takes POINT_FAST_S + (POINT_SLOW_S - POINT_FAST_S) * h seconds
  (0.6 s sure, 1.8 s unsure); from h = HESITANT_FROM it stops HESITATE_AT of the way
  for HESITATE_MAX_S * h seconds before going on; up to h = SURE_UP_TO Kaspar nods as
  it asks. Where the body shows nothing (modes "spoken" and "none") the point is the
  one it has always been: straight there in POINT_S.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hal.servos.api import ServoApi
from kasparctl.body.api import Body, Gaze, GazeKind, StillBody
from kasparctl.config import SessionPlan

# The point where the body shows nothing: as it has always been.
POINT_S = 1.0
# The point's duration runs from quick (sure) to slow (unsure) with the strength.
POINT_FAST_S = 0.6
POINT_SLOW_S = 1.8
# From this strength the point hesitates: stops this far along the way, for up to this long.
HESITANT_FROM = 0.5
HESITATE_AT = 0.6
HESITATE_MAX_S = 0.5
# Up to this strength Kaspar is sure: a quick, direct point and a nod as it asks.
SURE_UP_TO = 0.25
# How a point's goals are named in the joints layer's record (`demo --motion`).
POINT_SOURCE = "point"

# The behaviours the game asks for (the body's files name them).
THINKING = "thinking"
NOD = "nod"
HAPPY = "happy"
SAD = "sad"
GREETING = "greeting"
FAREWELL = "farewell"

# Told to the game's listeners for every ask: kind "look" (gaze, index, name), "perform"
# (behaviour, strength) or "alive" (alive).
Tell = Callable[[dict[str, Any]], None]


def normalised_entropy(entropy_bits: float, candidates: int) -> float:
    """The learner's entropy as a share of its most (log2 of the candidates), 0 to 1."""
    if candidates < 2 or not math.isfinite(entropy_bits):
        return 0.0
    return min(1.0, max(0.0, entropy_bits / math.log2(candidates)))


@dataclass(frozen=True, slots=True)
class PointStyle:
    """How Kaspar points: the move's seconds, where it hesitates and how long, a nod."""

    duration_s: float = POINT_S
    # The share of the way it stops at (None: straight there) and for how long.
    pause_at: float | None = None
    pause_s: float = 0.0
    nod: bool = False

    @property
    def words(self) -> str:
        """The style in a few words, for a transcript ("" for the plain point)."""
        if self.pause_at is not None:
            return "slowly, hesitating"
        if self.nod:
            return "quickly"
        return ""


PLAIN_POINT = PointStyle()


def point_style(strength: float | None) -> PointStyle:
    """The point for a guess of `strength` (normalised entropy); None: the body shows nothing."""
    if strength is None:
        return PLAIN_POINT
    h = min(1.0, max(0.0, strength))
    duration = POINT_FAST_S + (POINT_SLOW_S - POINT_FAST_S) * h
    if h >= HESITANT_FROM:
        return PointStyle(duration, HESITATE_AT, HESITATE_MAX_S * h)
    return PointStyle(duration, nod=h <= SURE_UP_TO)


async def point(servos: ServoApi, pose: dict[str, float], style: PointStyle) -> None:
    """Move to `pose` as `style` says: straight there, or stopping part of the way first.

    Each move claims only the pointing joints (ServoApi's arbitration): the body's mouth,
    eyes and eyelids go on meanwhile. Its goals are the source POINT_SOURCE.
    """
    if style.pause_at is None:
        await servos.move(pose, duration=style.duration_s, source=POINT_SOURCE)
        return
    before = await servos.read_positions()
    share = style.pause_at
    part = {
        joint: before[joint] + share * (degrees - before[joint]) if joint in before else degrees
        for joint, degrees in pose.items()
    }
    await servos.move(part, duration=style.duration_s * share, source=POINT_SOURCE)
    await asyncio.sleep(style.pause_s)
    await servos.move(pose, duration=style.duration_s * (1.0 - share), source=POINT_SOURCE)


class BodyWork:
    """The game's hold on Kaspar's body: asks it, within the session plan's switches."""

    def __init__(
        self, body: Body | None, plan: Callable[[], SessionPlan | None], tell: Tell
    ) -> None:
        """Drive `body` (a StillBody when None) for the session `plan()` returns, telling
        `tell` of each ask."""
        self.body: Body = body if body is not None else StillBody()
        self._plan = plan
        self._tell = tell
        self._alive: tuple[bool, bool] | None = None  # (alive, blinking) as last asked
        # A cancel stilled the body: the next set_alive reaches it whatever it says.
        self._stilled = False

    @property
    def fallback(self) -> bool:
        """No body is configured: the game's own poses show happy and sad."""
        return isinstance(self.body, StillBody)

    @property
    def lively(self) -> bool:
        """Gaze and life are allowed this session (the plan's `alive`; no plan: yes)."""
        plan = self._plan()
        return plan is None or plan.alive is not False

    def strength(self, entropy_bits: float, candidates: int) -> float | None:
        """The thinking behaviour's strength for a guess, or None where the plan's
        uncertainty mode does not show it with the body."""
        plan = self._plan()
        if plan is None or not plan.shows_uncertainty:
            return None
        return normalised_entropy(entropy_bits, candidates)

    def set_alive(self, alive: bool, *, blinking: bool = False) -> None:
        """Allow or forbid blinks, idle movements and gaze (never while the plan says no);
        `blinking` keeps the blinks of a body otherwise still (Body.set_alive)."""
        wanted = (alive and self.lively, (alive or blinking) and self.lively)
        if wanted == self._alive and not self._stilled:
            return
        self._stilled = False
        self.body.set_alive(wanted[0], blinking=wanted[1])
        if self._alive is None or wanted[0] != self._alive[0]:
            self._tell({"kind": "alive", "alive": wanted[0]})
        self._alive = wanted

    def look_at(self, kind: GazeKind, index: int = 0, name: str = "") -> None:
        """Turn to `kind` (its `index`, called `name` in the transcript), where gaze is on."""
        if not self.lively:
            return
        self.body.look_at(Gaze(kind, index))
        self._tell({"kind": "look", "gaze": kind.value, "index": index, "name": name})

    async def perform(self, behaviour: str, strength: float = 1.0) -> None:
        """Play `behaviour` at `strength` to its end (at once, for a StillBody)."""
        self._tell({"kind": "perform", "behaviour": behaviour, "strength": strength})
        await self.body.perform(behaviour, strength)

    def cancel(self) -> None:
        """End every behaviour at once (a pause, a fault, a stop).

        A cancelled body is still until asked again (kasparctl.body.api.Body.cancel): the
        next set_alive reaches it, whatever was asked before the cancel.
        """
        self.body.cancel()
        self._stilled = True
