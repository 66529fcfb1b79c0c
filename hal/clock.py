"""Time as an injected dependency, so a whole game can run in simulated time.

Everything that waits or timestamps takes a Clock. On the robot it is the
monotonic clock and asyncio's sleep; in tests and fast simulations it is a
virtual clock that jumps ahead instead of waiting.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Iterator
from typing import Protocol


class Clock(Protocol):
    """Where the HAL and the game read the time and wait; injected, never global."""

    def now(self) -> float:
        """Monotonic seconds; only differences are meaningful."""
        ...

    async def sleep(self, seconds: float) -> None:
        """Wait `seconds` of this clock's time; on a virtual clock no real time passes."""
        ...


class MonotonicClock:
    """The real clock: time.monotonic and asyncio.sleep."""

    def now(self) -> float:
        """time.monotonic(): seconds since an arbitrary start."""
        return time.monotonic()

    async def sleep(self, seconds: float) -> None:
        """asyncio.sleep: real seconds."""
        await asyncio.sleep(seconds)


class LoopClock:
    """The running event loop's clock: real on the robot, simulated under kasparctl.sim.simtime."""

    def now(self) -> float:
        """loop.time(): seconds, jumping ahead when the loop is simulated."""
        return asyncio.get_running_loop().time()

    async def sleep(self, seconds: float) -> None:
        """asyncio.sleep on the loop: real seconds, or simulated ones under simtime."""
        await asyncio.sleep(seconds)


@contextlib.contextmanager
def thread_work(loop: asyncio.AbstractEventLoop) -> Iterator[None]:
    """Mark a wait for a thread's real I/O: a simulated clock stands still meanwhile.

    On the robot's loop this does nothing. Under kasparctl.sim.simtime's virtual
    clock the loop would otherwise jump to its next timer while a bus thread
    waits for a servo's reply, so a 20 ms serial timeout would cost whole
    simulated seconds and an emulated servo would seem to move instantly.
    """
    hold = getattr(loop, "hold_clock", None)
    if hold is None:
        yield
        return
    with hold():
        yield
