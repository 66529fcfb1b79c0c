"""What the run loop takes, one at a time, from one queue, and the readers that fill it.

The children's keyfob (gestures, lost and back), the researcher's own device
(wrapped in FromResearcher, for the routing to tell its keys from the children's),
a step that ended, and a fault (the servos latch them; a record the disk refused
queues one). The readers are tasks of the game's: started as it runs, cancelled as
the session ends, so that what comes later stays queued in the keyfob for the next
game.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from hal.keyfob.api import InputEvent, KeyfobInput, KeyfobLost
from hal.keyfob.gestures import Gesture
from kasparctl.game.faults import HardwareFault
from kasparctl.game.researcher import gesture_name


@dataclass(frozen=True, slots=True)
class StepEnded:
    """A step's task ended: by itself (error None), or by failing with `error`."""

    step: str
    error: BaseException | None


@dataclass(frozen=True, slots=True)
class FromResearcher:
    """An event of the researcher's own device (a command key, or the device lost or back)."""

    event: InputEvent


# What the run loop takes, one at a time.
GameInput = InputEvent | StepEnded | HardwareFault | FromResearcher


def describe(event: GameInput) -> str:
    """What the run loop was handling, in words, for a fault's detail."""
    if isinstance(event, Gesture):
        return f"handling {gesture_name(event)}"
    if isinstance(event, StepEnded):
        return f"ending the step {event.step}"
    if isinstance(event, HardwareFault):
        return f"handling a {event.kind.value} fault"
    return f"handling the keyfob {'lost' if isinstance(event, KeyfobLost) else 'back'}"


class Inputs:
    """The run loop's queue, and the readers of the keyfob and the researcher's device."""

    def __init__(self) -> None:
        """An empty queue; nothing read until `read` starts the readers."""
        self._queue: asyncio.Queue[GameInput] = asyncio.Queue()
        self._readers: list[asyncio.Task[None]] = []

    def put(self, event: GameInput) -> None:
        """Queue `event` for the run loop (from a callback, a step's end, a refused record)."""
        self._queue.put_nowait(event)

    async def get(self) -> GameInput:
        """The next input, waiting for one."""
        return await self._queue.get()

    def pending(self) -> GameInput | None:
        """The next input already queued, or None when there is none."""
        return None if self._queue.empty() else self._queue.get_nowait()

    def read(self, keyfob: KeyfobInput, researcher: KeyfobInput | None) -> None:
        """Start reading `keyfob`, and `researcher`'s own device when given."""
        self._readers.append(asyncio.create_task(self._read(keyfob), name="keyfob reader"))
        if researcher is not None:
            reader = self._read(researcher, from_researcher=True)
            self._readers.append(asyncio.create_task(reader, name="researcher reader"))

    async def stop_reading(self) -> None:
        """Cancel the readers and wait for them: events not taken stay in the devices."""
        readers, self._readers = self._readers, []
        for task in readers:
            task.cancel()
        await asyncio.gather(*readers, return_exceptions=True)

    async def _read(self, device: KeyfobInput, from_researcher: bool = False) -> None:
        while True:
            event = await device.next_event()
            await self._queue.put(FromResearcher(event) if from_researcher else event)
