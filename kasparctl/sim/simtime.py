"""Event loops whose clock is simulated, so a whole game runs faster than real time.

The game waits only through asyncio (sleep, timeouts) and reads time from the
loop, so the same code runs on the robot and in simulated time:

- `VirtualTimeLoop`: when nothing is ready to run, the clock jumps straight to
  the next timer instead of waiting. Hundreds of games a second.
- `ScaledTimeLoop(speed)`: the clock runs `speed` times faster than the wall
  clock, so a person can watch a game at 10x.

I/O is still polled for real (with a zero timeout), so threads that wake the
loop with call_soon_threadsafe keep working. A wait marked with
hal.clock.thread_work (a serial bus thread talking to a pty emulator) holds
the virtual clock: the loop waits for the thread for real instead of jumping,
so real drivers run in simulated time with their real timeouts.
"""

from __future__ import annotations

import asyncio
import contextlib
import selectors
import time
from collections.abc import Coroutine, Iterator
from typing import Any, TypeVar

T = TypeVar("T")

# While the clock is held, the loop waits for a thread this long (real seconds) per
# turn; the thread's call_soon_threadsafe wakes it sooner.
HELD_WAIT_S = 0.05


class _JumpingSelector(selectors.DefaultSelector):
    """Polls without blocking, then tells the loop how long it would have slept."""

    def __init__(self) -> None:
        super().__init__()
        self.on_idle: Any = None
        self.held = 0  # waits on threads in flight (hal.clock.thread_work)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        events = super().select(0)
        if events or timeout == 0:
            return events
        if timeout is None:
            # Nothing scheduled: only another thread can wake us, so wait for real.
            return super().select(None)
        if self.held:
            # A thread is doing real I/O for the loop: jumping now would let simulated
            # time race past it. Wait for it for real; the clock stands still.
            return super().select(min(timeout, HELD_WAIT_S))
        # Nothing was ready, so jumping to the timer is all there is to do this turn.
        self.on_idle(timeout)
        return []


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """The clock advances only by jumping to the next timer when the loop is idle."""

    def __init__(self) -> None:
        """A loop whose clock starts at 0 and stands still while anything is ready."""
        selector = _JumpingSelector()
        super().__init__(selector)
        self._jumping = selector
        self._virtual_now = 0.0
        selector.on_idle = self._advance

    def time(self) -> float:
        """Seconds of simulated time since the loop was made."""
        return self._virtual_now

    @contextlib.contextmanager
    def hold_clock(self) -> Iterator[None]:
        """The clock stands still until this ends (see hal.clock.thread_work)."""
        self._jumping.held += 1
        try:
            yield
        finally:
            self._jumping.held -= 1

    def _advance(self, seconds: float) -> None:
        self._virtual_now += seconds


class ScaledTimeLoop(asyncio.SelectorEventLoop):
    """The clock runs `speed` times faster than the wall clock."""

    def __init__(self, speed: float) -> None:
        """A loop `speed` (> 0) times faster than real time; ValueError otherwise."""
        selector = _JumpingSelector()
        super().__init__(selector)
        if not speed > 0.0:
            self.close()
            raise ValueError(f"speed: expected a number > 0, found {speed!r}")
        self._speed = speed
        self._start = time.monotonic()
        self._skipped = 0.0
        selector.on_idle = self._sleep_scaled

    def time(self) -> float:
        """Scaled seconds since the loop was made."""
        return (time.monotonic() - self._start) * self._speed + self._skipped

    def _sleep_scaled(self, seconds: float) -> None:
        time.sleep(seconds / self._speed)


def run(main: Coroutine[Any, Any, T], speed: float | None = None, virtual: bool = False) -> T:
    """asyncio.run on a real, scaled or virtual clock.

    In virtual time a thread's work takes no simulated time: a wait marked with
    hal.clock.thread_work holds the clock until the thread answers; other thread
    work (run_in_executor) is not waited for, which the simulated hardware never needs.
    """
    factory: Any = None
    if virtual:
        factory = VirtualTimeLoop
    elif speed is not None and speed != 1.0:
        factory = lambda: ScaledTimeLoop(speed)  # noqa: E731
    with asyncio.Runner(loop_factory=factory) as runner:
        return runner.run(main)
