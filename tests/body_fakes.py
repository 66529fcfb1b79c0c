"""A recording Body for the game's tests: every call kept, behaviours that take time and end
early when cancelled (as kasparctl.body.api.Body promises)."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

from kasparctl.body.api import Gaze

# How long each behaviour lasts on the fake, in (simulated) seconds.
DURATION_S = {"thinking": 0.8, "nod": 0.4, "happy": 0.6, "sad": 0.6, "greeting": 1.0, "farewell": 1.0}


@dataclass
class Call:
    """One call on the body: its name, its arguments, the loop time it came."""

    name: str
    args: tuple[Any, ...]
    at: float
    # For perform: how it ended ("done", "cancelled" by cancel(), "task cancelled").
    ended: str | None = None


@dataclass
class RecordingBody:
    """A Body that records every call; `cancel` ends every running behaviour at once."""

    calls: list[Call] = field(default_factory=list)
    alive: bool | None = None
    # Seconds per behaviour, over DURATION_S.
    durations: dict[str, float] = field(default_factory=dict)
    _running: set[asyncio.Event] = field(default_factory=set)

    def _now(self) -> float:
        return asyncio.get_running_loop().time()

    def _note(self, name: str, *args: Any) -> Call:
        call = Call(name, args, self._now())
        self.calls.append(call)
        return call

    async def start(self) -> None:
        self._note("start")

    async def close(self) -> None:
        self._note("close")
        self.cancel()

    def set_alive(self, alive: bool, *, blinking: bool = False) -> None:
        self._note("set_alive", alive)
        self.alive = alive
        self.blinking = alive or blinking

    def look_at(self, gaze: Gaze) -> None:
        self._note("look_at", gaze)

    async def perform(self, behaviour: str, strength: float = 1.0) -> None:
        call = self._note("perform", behaviour, strength)
        stop = asyncio.Event()
        self._running.add(stop)
        try:
            seconds = self.durations.get(behaviour, DURATION_S.get(behaviour, 0.5))
            async with asyncio.timeout(seconds):
                await stop.wait()
            call.ended = "cancelled"
        except TimeoutError:
            call.ended = "done"
        except asyncio.CancelledError:
            call.ended = "task cancelled"
            raise
        finally:
            self._running.discard(stop)

    def cancel(self) -> None:
        self._note("cancel")
        for stop in self._running:
            stop.set()

    def named(self, name: str) -> list[Call]:
        """The calls of one method, in order."""
        return [call for call in self.calls if call.name == name]

    def performed(self, behaviour: str | None = None) -> list[Call]:
        """The behaviours performed (of one name), in order."""
        return [c for c in self.named("perform") if behaviour is None or c.args[0] == behaviour]
