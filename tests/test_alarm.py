"""hal.clock.Alarm and hal.timerfd: the body loop's wake-up on the kernel's timer.

No timing is asserted (the machine is shared): only that a wait never ends before
its moment, that the timer is the kernel's where it should be and absent where
time is simulated, and that cancelling and closing leave nothing behind.
"""

from __future__ import annotations

import asyncio
import os
import select
import time

import pytest

from hal.clock import Alarm, LoopClock, MonotonicClock
from hal.timerfd import MonotonicTimer
from kasparctl.sim import simtime


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def test_the_timer_fires_at_a_past_moment_and_not_before_a_future_one() -> None:
    timer = MonotonicTimer()
    try:
        timer.arm(time.monotonic() + 3600)
        assert select.select([timer.fileno], [], [], 0.05)[0] == []
        assert not timer.take()
        timer.arm(time.monotonic() - 1)  # passed: fires at once
        assert select.select([timer.fileno], [], [], 5)[0] == [timer.fileno]
        assert timer.take() and not timer.take()  # read off once
        # An expiry not yet read is reset by arming again: it cannot ring the next wait.
        timer.arm(time.monotonic() - 1)
        select.select([timer.fileno], [], [], 5)
        timer.arm(time.monotonic() + 3600)
        assert not timer.take()
    finally:
        timer.close()


@pytest.mark.parametrize("clock", [MonotonicClock(), LoopClock()], ids=["monotonic", "loop"])
async def test_a_wait_ends_at_its_moment_never_before(clock) -> None:
    alarm = Alarm(clock)
    try:
        for step in (0.003, 0.011, 0.0, -0.5):
            moment = clock.now() + step
            await alarm.sleep_until(moment)
            assert clock.now() >= moment
        assert alarm._timer is not None  # the kernel's timer, not asyncio's millisecond grid
    finally:
        alarm.close()


async def test_a_cancelled_wait_leaves_the_alarm_usable_and_close_releases_the_timer() -> None:
    before = open_fds()
    clock = MonotonicClock()
    alarm = Alarm(clock)
    waiting = asyncio.ensure_future(alarm.sleep_until(clock.now() + 3600))
    await asyncio.sleep(0.01)
    waiting.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiting
    moment = clock.now() + 0.005
    await asyncio.wait_for(alarm.sleep_until(moment), 10)
    assert clock.now() >= moment
    assert open_fds() == before + 1
    alarm.close()
    assert open_fds() == before
    await alarm.sleep_until(clock.now())  # a closed alarm opens another timer
    alarm.close()
    assert open_fds() == before


@pytest.mark.parametrize("speed", [None, 1000.0], ids=["virtual", "scaled"])
def test_in_simulated_time_the_alarm_goes_with_the_loop(speed: float | None) -> None:
    async def wait_an_hour() -> tuple[float, float, bool]:
        alarm = Alarm(LoopClock())
        loop = asyncio.get_running_loop()
        start = loop.time()
        await alarm.sleep_until(start + 3600)  # on the kernel's timer: a real hour
        return start, loop.time(), alarm._timer is None

    start, end, no_timer = simtime.run(wait_an_hour(), speed=speed, virtual=speed is None)
    assert end - start >= 3600
    assert no_timer


def test_on_python_3_13_the_os_module_timer_is_called_as_documented(monkeypatch) -> None:
    # os.timerfd_create(clockid, /, *, flags=0), os.timerfd_settime(fd, /, *, flags=0,
    # initial=0.0, interval=0.0): keyword-only, which these stand-ins enforce.
    calls = []

    def timerfd_create(clockid, /, *, flags=0):
        calls.append(("create", clockid, flags))
        return os.dup(0)

    def timerfd_settime(fd, /, *, flags=0, initial=0.0, interval=0.0):
        calls.append(("settime", flags, initial, interval))
        return (0.0, 0.0)

    monkeypatch.setattr(os, "timerfd_create", timerfd_create, raising=False)
    monkeypatch.setattr(os, "timerfd_settime", timerfd_settime, raising=False)
    timer = MonotonicTimer()
    timer.arm(12.5)
    timer.close()
    assert calls == [("create", 1, os.O_NONBLOCK | os.O_CLOEXEC), ("settime", 1, 12.5, 0.0)]


@pytest.mark.parametrize("clock", [MonotonicClock(), LoopClock()], ids=["monotonic", "loop"])
async def test_an_interrupted_wait_says_so_and_its_timer_rings_no_later_wait(clock) -> None:
    # The body's loop sleeps to its next count change and is woken by the game's news; the
    # first wait's moment then passes during the next, which must still wait its own.
    alarm = Alarm(clock)
    try:
        loop = asyncio.get_running_loop()
        first = clock.now() + 0.05
        loop.call_later(0.01, alarm.interrupt)
        assert await alarm.sleep_until(first) is True
        assert clock.now() < first
        second = clock.now() + 0.3
        assert await alarm.sleep_until(second) is False
        assert clock.now() >= second
        alarm.interrupt()  # no wait in progress: nothing happens
        assert await alarm.sleep_until(clock.now()) is False
    finally:
        alarm.close()


def test_an_interrupt_in_simulated_time_ends_the_wait_at_its_own_moment() -> None:
    async def interrupted() -> tuple[bool, float]:
        alarm = Alarm(LoopClock())
        loop = asyncio.get_running_loop()
        start = loop.time()
        loop.call_later(2.0, alarm.interrupt)
        rung = await alarm.sleep_until(start + 3600)
        return rung, loop.time() - start

    rung, waited = simtime.run(interrupted(), virtual=True)
    assert rung is True and waited == pytest.approx(2.0)
