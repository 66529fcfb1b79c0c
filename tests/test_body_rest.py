"""A body that rests: goals only when they change a servo's count, ticks slept through when
none would, and the same goals at the same (simulated) times as the loop that ticks."""

from __future__ import annotations

import asyncio
import random
from collections.abc import Callable

import msgspec
import pytest
from servo_fixtures import FakeClock

from hal.clock import LoopClock
from hal.servos.sim import SimServos
from hal.voice.envelope import FRAME_S, syllable_envelope
from kasparctl.body.api import Gaze, GazeKind
from kasparctl.body.behaviours import load_library
from kasparctl.body.engine import LiveBody
from kasparctl.sim import simtime
from kasparctl.sim.demo import demo_config

CONFIG = demo_config()
JOINTS = {j.name: j for j in CONFIG.servos.joints}
BY_ID = {(j.bus, j.id): j for j in CONFIG.servos.joints}
PERIOD = 0.02

Writes = list[tuple[float, str, int]]


async def powered(clock: FakeClock | LoopClock) -> SimServos:
    servos = SimServos(CONFIG.servos, clock)
    await servos.start(poll=False)
    for group in servos.groups:
        await servos.set_compliant(group, False)
    for driver in servos.drivers.values():
        driver.writes.clear()
    return servos


def raw_writes(servos: SimServos) -> Writes:
    """Every goal a simulated servo received: (time, joint, raw count), in time order."""
    rows = []
    for bus, driver in servos.drivers.items():
        for write in driver.writes:
            for servo_id, raw in write.goals.items():
                rows.append((round(write.time, 6), BY_ID[(bus, servo_id)].name, raw))
    return sorted(rows)


# --- the joints layer: a goal within the servo's count is taken, not sent ----------------


async def test_a_goal_within_the_servos_count_is_taken_and_not_sent():
    clock = FakeClock()
    servos = await powered(clock)
    unit = JOINTS["head_yaw"].servo.degrees_per_unit  # a HerkuleX count: 0.325 degrees
    assert unit == pytest.approx(0.325)
    start = servos.commanded()["head_yaw"]
    clock.t += PERIOD
    taken = await servos.stream({"head_yaw": start + 0.1}, PERIOD)
    # Taken (the next step goes on from it) but no packet: the servo's count is unchanged.
    assert taken == {"head_yaw": pytest.approx(start + 0.1)}
    assert servos.commanded()["head_yaw"] == pytest.approx(start + 0.1)
    assert raw_writes(servos) == []
    assert not servos.moves_servo({"head_yaw": start + 0.1})
    assert servos.moves_servo({"head_yaw": start + unit})
    clock.t += PERIOD
    await servos.stream({"head_yaw": start + unit}, PERIOD)
    [(_, joint, raw)] = raw_writes(servos)
    assert joint == "head_yaw" and raw == JOINTS["head_yaw"].servo.to_raw(start + unit, 1, 0.0)


async def test_slow_steps_finer_than_a_count_still_arrive():
    # 0.1 degree a step, a third of a count: the goals are taken, and a packet goes out each
    # time the count changes, so the servo follows the slow move to its end.
    clock = FakeClock()
    servos = await powered(clock)
    start = servos.commanded()["head_yaw"]
    for step in range(1, 31):
        clock.t += PERIOD
        await servos.stream({"head_yaw": start + 0.1 * step}, PERIOD)
    writes = raw_writes(servos)
    joint = JOINTS["head_yaw"]
    assert len(writes) == joint.servo.to_raw(start + 3.0, 1, 0.0) - joint.servo.to_raw(
        start, 1, 0.0)
    assert writes[-1][2] == joint.servo.to_raw(start + 3.0, 1, 0.0)
    assert servos.true_position("head_yaw") == pytest.approx(start + 3.0, abs=0.33)


async def test_a_limp_joint_gets_its_goal_again_when_torque_comes_back():
    clock = FakeClock()
    servos = await powered(clock)
    at = servos.commanded()["head_pitch"]
    await servos.set_compliant("head", True)
    await servos.set_compliant("head", False)
    for driver in servos.drivers.values():
        driver.writes.clear()
    clock.t += PERIOD
    await servos.stream({"head_pitch": at + 1.0}, PERIOD)
    assert [joint for _, joint, _ in raw_writes(servos)] == ["head_pitch"]


async def test_still_band_is_the_targets_that_round_to_the_count_sent():
    clock = FakeClock()
    servos = await powered(clock)
    joint = JOINTS["head_yaw"]
    start = servos.commanded()["head_yaw"]
    clock.t += PERIOD
    await servos.stream({"head_yaw": start + 1.0}, PERIOD)
    low, high = servos.still_band("head_yaw")
    assert high - low == pytest.approx(joint.servo.degrees_per_unit, abs=1e-4)
    sent = joint.servo.to_raw(start + 1.0, 1, 0.0)
    for degrees in (low + 1e-6, high - 1e-6):
        assert joint.servo.to_raw(degrees, 1, 0.0) == sent
        assert not servos.moves_servo({"head_yaw": degrees})
    for degrees in (low - 0.01, high + 0.01):
        assert servos.moves_servo({"head_yaw": degrees})
    # A limp joint takes no stream goal: any target sends nothing.
    await servos.set_compliant("head", True)
    assert servos.still_band("head_yaw") == (float("-inf"), float("inf"))
    # A virtual joint's band is not known: empty, so a caller never sleeps on it.
    low, high = servos.still_band("eyelids")
    assert low > high


# --- the loop sleeps through ticks that change nothing -------------------------------------


def play_scene(skipping: bool, seconds: float = 24.0) -> tuple[Writes, int]:
    """A body alive for `seconds` of simulated time: blinks and idle movements, a gaze, a
    gesture, a line spoken; the goals the servos received and the number of ticks run."""

    async def scene() -> tuple[Writes, int]:
        clock = LoopClock()
        servos = await powered(clock)
        body = LiveBody(servos, CONFIG.body, CONFIG.servos, load_library(), clock,
                        rng=random.Random(7), skipping=skipping)
        steps = 0
        real_step = body.step

        async def counted(now: float) -> dict[str, float]:
            nonlocal steps
            steps += 1
            return await real_step(now)

        body.step = counted  # type: ignore[method-assign]
        await body.start()
        body.set_alive(True)
        await asyncio.sleep(3.013)
        body.look_at(Gaze(GazeKind.CHILD, 0))
        await asyncio.sleep(2.0)
        await body.perform("nod")
        await asyncio.sleep(1.507)
        text = "Hello children. I am Kaspar, and I like the lion."
        body.mouth.on_envelope(clock.now(), FRAME_S, syllable_envelope(text, 2.5))
        await asyncio.sleep(4.0)
        body.look_at(Gaze(GazeKind.AHEAD))
        await asyncio.sleep(seconds - 10.52)
        await body.close()
        return raw_writes(servos), steps

    return simtime.run(scene(), virtual=True)


def count_at(writes: Writes, joint: str) -> Callable[[float], int | None]:
    mine = [(time, raw) for time, name, raw in writes if name == joint]

    def at(moment: float) -> int | None:
        last = None
        for time, raw in mine:
            if time > moment + 1e-9:
                break
            last = raw
        return last

    return at


def test_the_resting_loop_sends_what_the_ticking_loop_sends_at_the_same_times():
    ticking, ticks = play_scene(skipping=False)
    resting, steps = play_scene(skipping=True)
    assert {joint for _, joint, _ in ticking} >= {"head_yaw", "mouth_open", "left_eyelid"}
    # Every servo holds the same count (within one) at every moment either loop wrote.
    moments = sorted({time for time, _, _ in ticking + resting})
    for joint in {name for _, name, _ in ticking + resting}:
        a, b = count_at(ticking, joint), count_at(resting, joint)
        for moment in moments:
            ca, cb = a(moment), b(moment)
            assert (ca is not None and cb is not None) or ca == cb, (joint, moment, ca, cb)
            if ca is not None and cb is not None:
                assert abs(ca - cb) <= 1, (joint, moment, ca, cb)
    # Nearly every goal at the very same moment, and the same final count on every servo.
    assert len(set(resting) ^ set(ticking)) <= 0.02 * len(ticking)
    assert {j: count_at(ticking, j)(1e9) for j in JOINTS} == {
        j: count_at(resting, j)(1e9) for j in JOINTS}
    # ... for far fewer turns of the loop.
    assert steps < 0.6 * ticks, (steps, ticks)


def test_idle_life_wakes_the_loop_only_when_a_count_changes():
    still = msgspec.structs.replace(CONFIG.body, blink_interval_s=(50.0, 60.0))

    async def scene() -> tuple[int, int]:
        clock = LoopClock()
        servos = await powered(clock)
        body = LiveBody(servos, still, CONFIG.servos, load_library(), clock,
                        rng=random.Random(1))
        steps = 0
        real_step = body.step

        async def counted(now: float) -> dict[str, float]:
            nonlocal steps
            steps += 1
            return await real_step(now)

        body.step = counted  # type: ignore[method-assign]
        await body.start()
        body.set_alive(True)
        await asyncio.sleep(40.0)
        await body.close()
        return steps, len(raw_writes(servos))

    steps, packets = simtime.run(scene(), virtual=True)
    # Idle movements only (blinks 50 s apart): a few degrees over seconds, a count now and
    # then; the loop turns about as often as a packet goes out, not 50 times a second.
    assert packets > 10
    assert steps <= 3 * packets + 20, (steps, packets)
