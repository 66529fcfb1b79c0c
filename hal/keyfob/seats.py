"""One keyfob per child ([[keyfob.children]]): the seats' keyfobs as one stream.

Each seat's keyfob is read as any keyfob (the evdev reader, or a simulated one);
every gesture and every lost or back event it gives comes out tagged with its
seat (its place in [[keyfob.children]], from 0), so the game knows who pressed.
The seats together are connected while any one of them is: a seat whose keyfob
is away is the game's to skip (kasparctl.game.rotation), not a reason to stop.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Sequence

import structlog

from hal.keyfob.api import InputEvent, KeyfobInput, KeyfobLost
from hal.keyfob.gestures import GestureNeeds

log = structlog.get_logger("hal.keyfob.seats")


class Seats:
    """The seats' keyfobs, each event tagged with its seat; satisfies KeyfobInput."""

    def __init__(self, keyfobs: Sequence[KeyfobInput], devices: Sequence[str]) -> None:
        """`keyfobs[i]` is seat i's, opened from `devices[i]` (as the records name it)."""
        if not keyfobs or len(keyfobs) != len(devices):
            raise ValueError("expected one device name per seat, and at least one seat")
        self.keyfobs = tuple(keyfobs)
        self.devices = tuple(devices)
        self._events: asyncio.Queue[InputEvent] = asyncio.Queue()
        self._readers: list[asyncio.Task[None]] = []

    async def start(self) -> None:
        """Open every seat's keyfob and read each into the one stream."""
        for seat, keyfob in enumerate(self.keyfobs):
            await keyfob.start()
            loop = asyncio.get_running_loop()
            self._readers.append(loop.create_task(self._read(seat, keyfob), name=f"seat {seat}"))

    async def _read(self, seat: int, keyfob: KeyfobInput) -> None:
        try:
            while True:
                event = await keyfob.next_event()
                self._events.put_nowait(dataclasses.replace(event, seat=seat))
        except Exception as error:
            # A seat that can no longer be read is a seat away, never a silent one.
            log.error("a seat's keyfob cannot be read", seat=seat + 1, exc_info=error)
            at = asyncio.get_running_loop().time()
            self._events.put_nowait(KeyfobLost(at=at, reason=f"cannot be read: {error}", seat=seat))

    async def next_event(self) -> InputEvent:
        """The next event of any seat, tagged with its seat."""
        return await self._events.get()

    def set_needs(self, needs: GestureNeeds) -> None:
        """Every seat listens for the same gestures."""
        for keyfob in self.keyfobs:
            keyfob.set_needs(needs)

    @property
    def connected(self) -> bool:
        """True while any seat's keyfob is read."""
        return any(keyfob.connected for keyfob in self.keyfobs)

    def seat_connected(self, seat: int) -> bool:
        """Whether seat `seat`'s keyfob is read."""
        return self.keyfobs[seat].connected

    async def close(self) -> None:
        """Stop reading and close every seat's keyfob; idempotent."""
        readers, self._readers = self._readers, []
        for task in readers:
            task.cancel()
        await asyncio.gather(*readers, return_exceptions=True)
        for keyfob in self.keyfobs:
            await keyfob.close()
