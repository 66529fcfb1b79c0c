"""Simulated time: the same asyncio code, with a clock that jumps or runs faster."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from hal.clock import LoopClock
from kasparctl.sim.simtime import ScaledTimeLoop, run


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


# --- real drivers in simulated time ---------------------------------------------------------

from emulators.herkulex import HerkulexEmulator  # noqa: E402
from servo_fixtures import make_driver  # noqa: E402

from hal.errors import ServoSilent  # noqa: E402


def test_virtual_clock_stands_still_while_a_bus_thread_waits_for_a_reply(tmp_path: Path) -> None:
    """A silent servo costs real time (the bus's retries) but no simulated time, and a
    simulated timer due meanwhile does not fire early; the emulated shaft moves on
    the simulated clock, so a one-second move takes one simulated second."""

    async def main() -> dict[str, float]:
        loop = asyncio.get_running_loop()
        with HerkulexEmulator(tmp_path / "ttyHX", ids=[1], clock=loop.time) as emulator:
            driver = make_driver("herkulex", emulator.path, baud=115200)
            await driver.start()
            fired: list[float] = []
            loop.call_later(0.001, lambda: fired.append(loop.time()))
            emulator.faults.silent.add(1)
            before, wall = loop.time(), time.monotonic()
            with pytest.raises(ServoSilent):
                await driver.read_positions([1])
            silent_virtual, silent_wall = loop.time() - before, time.monotonic() - wall
            fired_during_read = bool(fired)
            emulator.faults.silent.clear()
            await driver.set_torque([1], True)
            start = (await driver.read_positions([1]))[1]
            await driver.write_goals({1: (start + 300, 100.0)}, 0.02)
            # A goal write has no reply: a read behind it on the same port is how we
            # know the emulator has taken it (no simulated time passes meanwhile).
            at_once = (await driver.read_positions([1]))[1]
            await asyncio.sleep(0.5)
            halfway = (await driver.read_positions([1]))[1]
            await driver.close()
            return {
                "silent_virtual": silent_virtual,
                "silent_wall": silent_wall,
                "fired_during_read": float(fired_during_read),
                "halfway_moved": halfway - start,
                "at_once_moved": at_once - start,
            }

    result = run(main(), virtual=True)
    # Three attempts of (wire time + 0.1 s margin) for real, none of it simulated.
    assert result["silent_wall"] >= 0.3
    assert result["silent_virtual"] == 0.0
    # A timer due 1 ms later did not fire while the bus thread waited (without the
    # hold the loop would have jumped to it at once).
    assert result["fired_during_read"] == 0.0
    # 1100 units/s on the emulator clock: half a simulated second moves it all 300 units
    # (not zero, as with a real-time shaft, and not 300 at once, as without a clock).
    assert result["at_once_moved"] == 0
    assert result["halfway_moved"] == 300
