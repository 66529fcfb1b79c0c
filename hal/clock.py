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

import structlog

from hal.timerfd import MonotonicTimer, TimerUnavailable

log = structlog.get_logger("kaspar.clock")


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


class Alarm:
    """Waits until a moment of a clock, as close to it as the kernel allows.

    On the real clock of a real event loop a timerfd wakes the loop at the moment
    (hal.timerfd: asyncio's own timers are up to 1 ms late); on a simulated loop or
    any other clock, and where there is no timerfd, it is the clock's own sleep.
    interrupt() ends a wait early (the body's loop, woken by the game's news). Not for
    several tasks at once: one alarm per loop that waits on it.
    """

    def __init__(self, clock: Clock) -> None:
        """An alarm on `clock`; its timer is opened at the first wait."""
        self._clock = clock
        self._timer: MonotonicTimer | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._rung: asyncio.Future[bool] | None = None
        self._plain = not isinstance(clock, MonotonicClock | LoopClock)

    async def sleep_until(self, moment: float) -> bool:
        """Return at `moment` of the clock (at once when it has passed), or sooner when
        interrupt() is called; whether it was. Cancellable."""
        loop = asyncio.get_running_loop()
        timer = None if self._plain else self._timer_on(loop)
        self._rung = rung = loop.create_future()
        waiting: asyncio.TimerHandle | asyncio.Task[None] | None = None
        if timer is not None:
            # Arming resets the timer's count of expiries: an old one cannot ring this wait.
            timer.arm(moment)
        elif isinstance(self._clock, LoopClock):
            # The loop's own timer (a simulated loop jumps to it): one handle, no task.
            waiting = loop.call_at(moment, self._ring_plain)
        else:
            waiting = loop.create_task(self._clock.sleep(max(0.0, moment - self._clock.now())))
            waiting.add_done_callback(lambda _: self._ring_plain())
        try:
            return bool(await rung)
        finally:
            self._rung = None
            if waiting is not None:
                waiting.cancel()

    def interrupt(self) -> None:
        """End the wait in progress now (sleep_until returns True); nothing when none is."""
        if self._rung is not None and not self._rung.done():
            self._rung.set_result(True)

    def _ring_plain(self) -> None:
        if self._rung is not None and not self._rung.done():
            self._rung.set_result(False)

    def _ring(self) -> None:
        # Two syscalls a tick: the arm and this read. The reader stays registered
        # between waits; epoll may report an expiry that a re-arm has since reset.
        if self._timer is None or not self._timer.take():
            return
        if self._rung is not None and not self._rung.done():
            self._rung.set_result(False)

    def _timer_on(self, loop: asyncio.AbstractEventLoop) -> MonotonicTimer | None:
        if self._timer is not None and self._loop is loop:
            return self._timer
        self.close()
        # A loop with a time of its own (kasparctl.sim.simtime: virtual or scaled) is not on
        # the kernel's clock: its timers jump or run faster, they do not wait.
        if type(loop).time is not asyncio.BaseEventLoop.time:
            self._plain = True
            return None
        try:
            timer = MonotonicTimer()
        except TimerUnavailable as error:
            log.info("no high-resolution timer; waiting on the event loop", error=str(error))
            self._plain = True
            return None
        try:
            loop.add_reader(timer.fileno, self._ring)
        except NotImplementedError:  # a loop without readers (Windows' proactor)
            timer.close()
            self._plain = True
            return None
        self._timer, self._loop = timer, loop
        return timer

    def close(self) -> None:
        """Release the timer; a later sleep_until opens another."""
        timer, loop, self._timer, self._loop = self._timer, self._loop, None, None
        if timer is None:
            return
        if loop is not None and not loop.is_closed():
            loop.remove_reader(timer.fileno)
        timer.close()


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
