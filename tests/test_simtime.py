"""Simulated time: the same asyncio code, with a clock that jumps or runs faster."""

from __future__ import annotations

import asyncio
import time

import pytest

from hal.clock import LoopClock
from kasparctl.simtime import ScaledTimeLoop, run


async def waits_an_hour_and_a_timeout() -> float:
    clock = LoopClock()
    start = clock.now()
    await clock.sleep(3600)
    with pytest.raises(TimeoutError):
        async with asyncio.timeout(5):
            await asyncio.Event().wait()
    return clock.now() - start


def test_virtual_time_jumps_instead_of_waiting() -> None:
    wall = time.monotonic()
    assert run(waits_an_hour_and_a_timeout(), virtual=True) == pytest.approx(3605.0)
    assert time.monotonic() - wall < 60  # an hour and five seconds did not pass


def test_virtual_time_keeps_the_order_of_timers() -> None:
    async def main() -> list[str]:
        order: list[str] = []

        async def after(seconds: float, name: str) -> None:
            await asyncio.sleep(seconds)
            order.append(name)

        await asyncio.gather(after(3, "c"), after(1, "a"), after(2, "b"))
        return order

    assert run(main(), virtual=True) == ["a", "b", "c"]


def test_threads_still_wake_a_virtual_loop() -> None:
    async def main() -> str:
        return await asyncio.get_running_loop().run_in_executor(None, lambda: "done")

    assert run(main(), virtual=True) == "done"


def test_scaled_time_runs_faster_than_the_wall() -> None:
    async def main() -> float:
        clock = LoopClock()
        start = clock.now()
        await clock.sleep(2.0)
        return clock.now() - start

    assert run(main(), speed=50.0) >= 2.0


def test_scale_must_be_positive() -> None:
    with pytest.raises(ValueError, match="speed: expected a number > 0, found 0"):
        ScaledTimeLoop(0)
