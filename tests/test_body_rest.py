"""A body that rests: no packet that changes nothing, no tick that sends nothing, the same goals.

The live body looks ahead and sleeps through the ticks that would change no servo's
count (kasparctl.body.engine). Its reference is the same engine stepping every tick
(`rests = False`): every test here plays both and asks that the servos received the
same goals, at the same moments, from the same layers, while the resting one stepped
far fewer times. The joints layer's rule underneath (hal.servos.joints.stream): a goal
within the servo's last count is not sent, and a joint slower than a count a period
still moves, at its speed limit.
"""

from __future__ import annotations

import asyncio
import io
import itertools
import random
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import msgspec
import pytest

from hal.clock import LoopClock
from hal.servos.api import Goal
from hal.servos.sim import SimServos
from kasparctl.body.api import Gaze, GazeKind
from kasparctl.body.behaviours import load_library
from kasparctl.body.engine import LiveBody
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, build, demo_config, with_variant

pytestmark = pytest.mark.live_body
CONFIG = demo_config()
HEAD_UNIT = next(j for j in CONFIG.servos.joints if j.name == "head_yaw").servo.degrees_per_unit


def _goal_row(goal: Goal) -> tuple[float, str, float, str]:
    return (round(goal.time, 9), goal.joint, goal.degrees, goal.source)


def count_steps(body: LiveBody) -> Callable[[], int]:
    """Count `body`'s steps from here on, whole and light; the count so far."""
    steps = 0
    whole, light = body.step, body._light_step

    async def counted_whole(now: float) -> dict[str, float]:
        nonlocal steps
        steps += 1
        return await whole(now)

    async def counted_light(goals: dict[str, float]) -> dict[str, float]:
        nonlocal steps
        steps += 1
        return await light(goals)

    body.step = counted_whole  # type: ignore[method-assign]
    body._light_step = counted_light  # type: ignore[method-assign]
    return lambda: steps


def play_game(tmp_path: Path, variant: str, seed: int, rests: bool) -> tuple[list[tuple], int]:
    """Every goal the servos received in one whole demo game, and the body's steps."""
    goals: list[tuple] = []
    steps = 0

    async def main() -> None:
        nonlocal steps
        rig = build(with_variant(CONFIG, variant),
                    DemoOptions(state_dir=tmp_path / f"{rests}", seed=seed, out=io.StringIO()))
        body = rig.body
        assert isinstance(body, LiveBody)
        body.rests = rests
        counted = count_steps(body)
        rig.servos.on_goals(lambda goal: goals.append(_goal_row(goal)))
        result = await rig.run()
        assert result.finished
        steps = counted()

    simtime.run(main(), virtual=True)
    return goals, steps


@pytest.mark.parametrize(("variant", "seed"), [("names", 1), ("pilot", 2)])
def test_a_whole_game_sends_the_same_goals_at_the_same_moments_resting_or_ticking(
    tmp_path: Path, variant: str, seed: int
) -> None:
    ticking, ticks = play_game(tmp_path / "ticking", variant, seed, rests=False)
    resting, steps = play_game(tmp_path / "resting", variant, seed, rests=True)
    assert len(ticking) > 1000  # a game's worth of mouth, gaze, blinks, gestures and moves
    assert {source.split(":")[0] for *_, source in ticking} >= {
        "mouth", "gaze", "blink", "idle", "gesture", "point"}
    assert resting == ticking
    # Every step of the resting loop sends something or changes the body's state; the
    # ticking loop's are a third more (what the mouth's pauses and slow life cost it).
    assert steps < 0.8 * ticks


async def _alive_for(seconds: float, rests: bool) -> tuple[list[tuple], int]:
    clock = LoopClock()
    servos = SimServos(CONFIG.servos, clock)
    await servos.start()
    for group in CONFIG.servos.groups:
        await servos.set_compliant(group, False)
    body = LiveBody(servos, CONFIG.body, CONFIG.servos, load_library(), clock,
                    rng=random.Random(7))
    body.rests = rests
    goals: list[tuple] = []
    servos.on_goals(lambda goal: goals.append(_goal_row(goal)))
    counted = count_steps(body)
    await body.start()
    body.set_alive(True)
    await asyncio.sleep(seconds / 2)
    body.look_at(Gaze(GazeKind.CHILD, 2))
    await asyncio.sleep(seconds / 2)
    await body.close()
    await servos.close()
    return goals, counted()


def test_life_alone_rests_between_counts_and_sends_what_the_ticking_loop_sends() -> None:
    ticking, ticks = simtime.run(_alive_for(120.0, rests=False), virtual=True)
    resting, steps = simtime.run(_alive_for(120.0, rests=True), virtual=True)
    sources = {source for *_, source in ticking}
    assert {"blink", "idle", "gaze"} <= sources
    assert resting == ticking
    # Nobody there: blinks and slow idle movements, most of whose ticks change no count.
    assert steps < 0.5 * ticks


async def _one_joint(speed_dps: float, target: float, seconds: float) -> list[Goal]:
    clock = LoopClock()
    joint = next(j for j in CONFIG.servos.joints if j.name == "head_yaw")
    settings = msgspec.structs.replace(
        CONFIG.servos,
        joints=tuple(msgspec.structs.replace(j, max_speed_dps=speed_dps) if j is joint else j
                     for j in CONFIG.servos.joints))
    servos = SimServos(settings, clock)
    await servos.start()
    await servos.set_compliant("head_yaw", False)
    goals: list[Goal] = []
    servos.on_goals(goals.append)
    period = 0.02
    for _ in range(round(seconds / period)):
        await asyncio.sleep(period)
        await servos.stream({"head_yaw": target}, period)
    await servos.close()
    return goals


def test_a_joint_slower_than_a_count_a_tick_still_moves_at_its_limit() -> None:
    # 2 deg/s is 0.04 deg a 20 ms tick, far below the servo's count: the old rule sent a
    # goal the servo rounded away every tick; this one sends one count when it is due.
    goals = simtime.run(_one_joint(2.0, 10.0, 3.0), virtual=True)
    streamed = [g for g in goals if g.source == "stream"]
    unit = HEAD_UNIT
    assert streamed
    travelled = streamed[-1].degrees - goals[0].degrees
    assert travelled == pytest.approx(2.0 * (streamed[-1].time - goals[0].time), abs=unit)
    counts = [round(g.degrees / unit) for g in streamed]
    for before, after in itertools.pairwise(streamed):
        # Never faster than the limit, and every goal the next count.
        assert after.degrees - before.degrees <= 2.0 * (after.time - before.time) + 1e-9
    assert counts == list(range(counts[0], counts[0] + len(counts)))


def test_a_goal_within_the_servos_count_is_not_sent() -> None:
    unit = HEAD_UNIT
    goals = simtime.run(_one_joint(60.0, unit * 0.3, 1.0), virtual=True)
    assert [g for g in goals if g.source == "stream"] == []


def test_a_scaled_time_demo_ends_after_its_goodbye() -> None:
    # The first resting body never ended these: its way home stopped a count short.
    done = subprocess.run(
        [sys.executable, "-m", "kasparctl", "demo", "--speed", "1000", "--variant", "pilot",
         "--seed", "2"],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "finished" in done.stdout
