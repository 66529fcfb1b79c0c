"""One arbiter of motion: a move claims only its joints, streams go on for the others.

The joints layer over the real HerkuleX driver and bus, talking to the emulator on a
pty, in simulated time (the bus thread's waits hold the clock): what the emulated
servos receive is what a robot's would.
"""

from __future__ import annotations

import asyncio
import itertools
import math
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest
from emulators.herkulex import HerkulexEmulator
from servo_fixtures import eventually, make_driver

from hal.clock import LoopClock
from hal.servos import herkulex as hx
from hal.servos.api import Goal
from hal.servos.joints import Joints
from hal.servos.settings import BusSettings, JointSettings, ServoSettings
from hal.servos.sim import SimServos
from kasparctl.body.behaviours import parse
from kasparctl.body.engine import LiveBody
from kasparctl.config import BodySettings
from kasparctl.sim import simtime

PERIOD = 0.02  # the body's loop, and the joints' control step (control_hz 50)
JOINTS = (
    JointSettings(name="right_shoulder", bus="body", id=1, model="drs-0101",
                  range_deg=(-90.0, 60.0), max_speed_dps=60.0, rest_deg=-5.0, group="right_arm"),
    JointSettings(name="right_elbow", bus="body", id=2, model="drs-0101",
                  range_deg=(-5.0, 90.0), max_speed_dps=60.0, rest_deg=5.0, group="right_arm"),
    JointSettings(name="mouth_open", bus="body", id=3, model="drs-0101",
                  range_deg=(-15.0, 15.0), max_speed_dps=120.0, group="face"),
    JointSettings(name="left_eyelid", bus="body", id=4, model="drs-0101",
                  range_deg=(-15.0, 15.0), max_speed_dps=90.0, group="eyes"),
)
BY_ID = {joint.id: joint for joint in JOINTS}
BY_NAME = {joint.name: joint for joint in JOINTS}
ARM = {"right_shoulder": -60.0, "right_elbow": 60.0}


class Wire:
    """The emulated bus with its servos, and every goal they took: (time, joint, degrees)."""

    def __init__(self, emulator: HerkulexEmulator, clock: Callable[[], float]) -> None:
        self.taken: list[tuple[float, str, float]] = []
        jog = emulator._jog

        def tapped(command: int, data: bytes) -> None:
            entries = ([data[i:i + 4] for i in range(1, len(data) - 3, 4)]
                       if command == hx.Command.S_JOG else
                       [data[i:i + 4] for i in range(0, len(data) - 4, 5)])
            for entry in entries:
                joint = BY_ID.get(entry[3])
                if joint is not None and not entry[2] & hx.JogSet.STOP:
                    raw = hx.u16(entry) & 0x7FFF
                    self.taken.append((clock(), joint.name, joint.servo.to_degrees(raw, 1, 0.0)))
            jog(command, data)

        emulator._jog = tapped  # type: ignore[method-assign]

    def of(self, joint: str) -> list[tuple[float, float]]:
        return [(time, degrees) for time, name, degrees in self.taken if name == joint]

    async def landed(self, goals: list[Goal]) -> None:
        """Until every goal written has been read by the emulator's thread."""
        await eventually(lambda: len(self.taken) >= len(goals))
        assert len(self.taken) == len(goals)


def on_the_wire(
    tmp_path: Path, scenario: Callable[[Joints, Wire, list[Goal]], Coroutine[Any, Any, None]]
) -> None:
    """Run `scenario` in simulated time on joints over an emulated HerkuleX bus, powered."""

    async def main() -> None:
        loop = asyncio.get_running_loop()
        with HerkulexEmulator(tmp_path / "ttyHX", ids=list(BY_ID), clock=loop.time) as emulator:
            settings = ServoSettings(
                backend="real", joints=JOINTS, control_hz=1.0 / PERIOD,
                buses=(BusSettings(name="body", port=str(emulator.path), protocol="herkulex",
                                   baud=115200),),
            )
            joints = Joints(settings, {"body": make_driver("herkulex", emulator.path, 115200)},
                            LoopClock())
            wire = Wire(emulator, loop.time)
            goals: list[Goal] = []
            joints.on_goals(goals.append)
            await joints.start(poll=False)
            try:
                for group in joints.groups:
                    await joints.set_compliant(group, False)
                await wire.landed(goals)  # the holds written as torque went on
                goals.clear()
                wire.taken.clear()
                await scenario(joints, wire, goals)
            finally:
                await joints.close()

    simtime.run(main(), virtual=True)


async def stream_for(joints: Joints, seconds: float, pose: Callable[[float], dict[str, float]],
                     sources: dict[str, str]) -> None:
    """A body's loop: one stream step every PERIOD toward `pose(t)`, for `seconds`."""
    begin = asyncio.get_running_loop().time()
    for tick in range(1, round(seconds / PERIOD) + 1):
        await joints.stream(pose(tick * PERIOD), PERIOD, sources)
        await asyncio.sleep(max(0.0, begin + tick * PERIOD - asyncio.get_running_loop().time()))


def speaking(t: float) -> dict[str, float]:
    """A mouth opening and closing four times a second (past its range, to be clamped), an
    eyelid blinking, and a layer that wants the arm the other way."""
    return {
        "mouth_open": 40.0 * max(0.0, math.sin(2 * math.pi * 4 * t)),
        "left_eyelid": -12.0 * max(0.0, math.sin(2 * math.pi * 2 * t)),
        "right_shoulder": 50.0,
    }


SOURCES = {"mouth_open": "mouth", "left_eyelid": "blink", "right_shoulder": "gaze"}


def assert_within_limits(rows: list[tuple[float, float]], joint: str) -> None:
    """In range, and each goal within one control step at the speed limit of the last (the
    servo reaches each goal within its packet's play time), plus two raw units of rounding."""
    settings = BY_NAME[joint]
    unit = settings.servo.degrees_per_unit
    low, high = settings.range_deg
    assert all(low - unit <= degrees <= high + unit for _, degrees in rows), joint
    for (_, before), (_, after) in itertools.pairwise(rows):
        assert abs(after - before) <= settings.max_speed_dps * PERIOD + 2 * unit, joint


def test_the_mouth_streams_while_the_arm_points_and_the_arm_obeys_only_the_move(tmp_path):
    async def scenario(joints: Joints, wire: Wire, goals: list[Goal]) -> None:
        point = asyncio.create_task(joints.move(ARM, duration=1.6, source="point"))
        await asyncio.sleep(0)  # the point claims the arm before the first stream step
        assert joints.claimed() == {"right_shoulder", "right_elbow"}
        await stream_for(joints, 2.2, speaking, SOURCES)
        await point
        assert joints.claimed() == frozenset()

        pointing = [g for g in goals if g.source == "point"]
        begin, end = pointing[0].time, pointing[-1].time
        assert end - begin == pytest.approx(1.6 - PERIOD)
        during = [g for g in goals if begin <= g.time <= end]
        mouth = [g.degrees for g in during if g.joint == "mouth_open"]
        # The mouth moved all through the point (four openings a second), clamped: a goal
        # at most ticks of the 1.6 s (those that round to the count held are not sent).
        assert len(mouth) >= 60
        assert sum(abs(b - a) for a, b in itertools.pairwise(mouth)) > 150.0
        assert 10.0 < max(mouth) <= 15.0 and min(mouth) == pytest.approx(0.0, abs=0.5)
        assert {g.source for g in during if g.joint == "mouth_open"} == {"mouth"}
        # The eyelid moves half the time (a rectified sine): a goal at each count it changes.
        assert sum(g.joint == "left_eyelid" for g in during) >= 40
        # The arm's goals during the point are the point's alone: never the stream's.
        assert {g.source for g in during if g.joint in ARM} == {"point"}
        # On the wire, in the order the servo took them (a jog has no reply: the emulator's
        # times are when its thread read each packet), the shoulder went one way only while
        # pointing, toward -60, though a layer asked for +50 all along; then the stream
        # took it from where the point left it.
        await wire.landed(goals)
        shoulder = [g for g in goals if g.joint == "right_shoulder"]
        taken = [degrees for _, degrees in wire.of("right_shoulder")]
        unit = BY_NAME["right_shoulder"].servo.degrees_per_unit
        assert len(taken) == len(shoulder)
        assert all(abs(d - g.degrees) <= unit for d, g in zip(taken, shoulder, strict=True))
        points = sum(g.source == "point" for g in shoulder)
        assert [g.source for g in shoulder] == ["point"] * points + ["gaze"] * (
            len(shoulder) - points)
        assert all(b <= a for a, b in itertools.pairwise(taken[:points]))
        assert taken[points - 1] == pytest.approx(-60.0, abs=unit)
        assert taken[-1] > taken[points - 1] + 10.0
        for joint in BY_NAME:
            assert_within_limits(wire.of(joint), joint)

    on_the_wire(tmp_path, scenario)


def test_streaming_resumes_on_a_joint_no_faster_than_its_limit_after_the_move(tmp_path):
    async def scenario(joints: Joints, wire: Wire, goals: list[Goal]) -> None:
        # The stream wants the shoulder far beyond its range, and comes every 5 ms: early.
        async def eager() -> None:
            for _ in range(800):
                await joints.stream({"right_shoulder": 500.0}, PERIOD)
                await asyncio.sleep(0.005)

        # Beyond the range too: clamped to -90, and at the speed limit whatever the duration.
        point = asyncio.create_task(joints.move({"right_shoulder": -200.0}, duration=0.5))
        await asyncio.gather(point, eager())
        shoulder = [g for g in goals if g.joint == "right_shoulder"]
        handover = next(i for i, g in enumerate(shoulder) if g.source == "stream")
        last_of_move, first_of_stream = shoulder[handover - 1], shoulder[handover]
        assert last_of_move.source == "move" and last_of_move.degrees == pytest.approx(-90.0)
        assert shoulder[handover - 1].time - shoulder[0].time >= 1.5 * 85.0 / 60.0 - PERIOD
        assert shoulder[-1].degrees > last_of_move.degrees + 90.0  # the stream took it back
        limit = BY_NAME["right_shoulder"].max_speed_dps
        # From the move's last goal, by the time since it, as between any two stream steps.
        for before, after in itertools.pairwise(shoulder[handover - 1:]):
            assert after.degrees - before.degrees <= limit * (after.time - before.time) + 1e-9
        assert first_of_stream.degrees - last_of_move.degrees <= limit * (
            first_of_stream.time - last_of_move.time) + 1e-9
        await wire.landed(goals)
        assert_within_limits(wire.of("right_shoulder"), "right_shoulder")

    on_the_wire(tmp_path, scenario)


def test_a_cancel_ends_the_move_and_every_layer_of_the_body_at_once(tmp_path):
    (blink,) = parse("[blink]\nkeyframes = [{ time = 0.1, pose = { left_eyelid = -12.0 } },"
                     " { time = 0.2, pose = { left_eyelid = 0.0 } }]\n", "blink.toml").values()
    (nod,) = parse("[nod]\nkeyframes = [{ time = 0.5, pose = { mouth_open = 8.0 } }]\n",
                   "nod.toml").values()

    async def scenario(joints: Joints, wire: Wire, goals: list[Goal]) -> None:
        clock = LoopClock()
        body = LiveBody(joints, BodySettings(enabled=True, blink_interval_s=(0.1, 0.1)),
                        joints.settings, {"blink": blink, "nod": nod}, clock)
        await body.start()
        body.set_alive(True)
        syllables = ([0.3] * 12 + [0.0] * 12) * 12  # three seconds of speech, four a second
        body.mouth.on_envelope(clock.now(), 0.01, syllables)
        # The game's step: a point, and the body speaking and blinking meanwhile.
        step = asyncio.create_task(joints.move(ARM, duration=2.0, source="point"))
        await asyncio.sleep(0.6)
        recent = {g.joint for g in goals if g.time > clock.now() - 0.3}
        assert recent >= {"right_shoulder", "mouth_open"}  # the arm points, the mouth speaks
        # The game's cancel: the step's task and the body, at once (a pause, a fault, a stop).
        step.cancel()
        body.cancel()
        await asyncio.gather(step, return_exceptions=True)
        assert step.cancelled() and joints.claimed() == frozenset()
        count = len(goals)
        await asyncio.sleep(2.0)
        assert len(goals) == count  # nothing more, from anyone
        await wire.landed(goals)
        assert len(wire.taken) == count
        # The arm is free again: the next stream step moves it, from where the point stopped.
        held = joints.commanded()["right_shoulder"]
        sent = await joints.stream({"right_shoulder": held + 5.0}, PERIOD)
        assert sent["right_shoulder"] == pytest.approx(held + 60.0 * PERIOD)
        await body.close()

    on_the_wire(tmp_path, scenario)


def test_torque_changes_wait_for_the_move_and_exclude_the_stream(tmp_path):
    async def scenario(joints: Joints, wire: Wire, goals: list[Goal]) -> None:
        point = asyncio.create_task(joints.move(ARM, duration=0.6, source="point"))
        await asyncio.sleep(0.1)
        limp = asyncio.create_task(joints.set_compliant("right_arm", True))
        await asyncio.sleep(0.1)
        assert not limp.done()  # it waits for the point to end
        await asyncio.gather(point, limp)
        last = [g for g in goals if g.source == "point"][-1]
        assert last.degrees == pytest.approx(ARM[last.joint])  # the point ran to its end
        await wire.landed(goals)
        count = len(wire.taken)
        sent = await joints.stream({"right_shoulder": 0.0, "mouth_open": 3.0}, PERIOD)
        assert set(sent) == {"mouth_open"}  # a limp arm is left alone
        await wire.landed(goals)
        assert {name for _, name, _ in wire.taken[count:]} == {"mouth_open"}

    on_the_wire(tmp_path, scenario)


# --- the order of moves, on the simulated twin (the same joints layer) ---------------------


def test_moves_sharing_a_joint_run_in_the_order_asked_and_the_others_side_by_side():
    async def main() -> None:
        settings = ServoSettings(backend="sim", joints=JOINTS, control_hz=1.0 / PERIOD,
                                 buses=(BusSettings(name="body", port="/dev/null",
                                                    protocol="herkulex", baud=115200),))
        servos = SimServos(settings, LoopClock())
        await servos.start(poll=False)
        for group in servos.groups:
            await servos.set_compliant(group, False)
        goals: list[Goal] = []
        servos.on_goals(goals.append)
        first = asyncio.create_task(servos.move({"right_shoulder": -40.0}, 1.0, source="first"))
        second = asyncio.create_task(
            servos.move({"right_shoulder": 20.0, "right_elbow": 30.0}, 1.0, source="second"))
        face = asyncio.create_task(servos.move({"mouth_open": 10.0}, 1.0, source="face"))
        await asyncio.gather(first, second, face)

        def span(source: str) -> tuple[int, int]:
            """Where a move's goals begin and end in the order they were written."""
            mine = [i for i, g in enumerate(goals) if g.source == source]
            return mine[0], mine[-1]

        # No joint in common: side by side, from the same moment.
        assert goals[span("face")[0]].time == goals[span("first")[0]].time
        assert span("face")[0] < span("first")[1]
        # The shoulder's second move waits for the first to end; so does its elbow: a move
        # claims all its joints at once, or waits.
        assert span("second")[0] > span("first")[1]
        elbow = [i for i, g in enumerate(goals) if g.joint == "right_elbow"]
        assert elbow and elbow[0] > span("first")[1]
        assert goals[span("second")[0]].time >= goals[span("first")[1]].time
        shoulder = [g.source for g in goals if g.joint == "right_shoulder"]
        assert shoulder == sorted(shoulder)  # "first" goals, then "second": never mixed
        assert servos.true_position("right_shoulder") == pytest.approx(20.0, abs=0.4)

    simtime.run(main(), virtual=True)


def test_a_move_cancelled_while_it_waits_for_its_joints_never_moves_them():
    async def main() -> None:
        settings = ServoSettings(backend="sim", joints=JOINTS, control_hz=1.0 / PERIOD,
                                 buses=(BusSettings(name="body", port="/dev/null",
                                                    protocol="herkulex", baud=115200),))
        servos = SimServos(settings, LoopClock())
        await servos.start(poll=False)
        for group in servos.groups:
            await servos.set_compliant(group, False)
        goals: list[Goal] = []
        servos.on_goals(goals.append)
        first = asyncio.create_task(servos.move({"right_shoulder": -40.0}, 1.0, source="first"))
        waiting = asyncio.create_task(servos.move({"right_shoulder": 20.0}, 1.0, source="gone"))
        after = asyncio.create_task(servos.move({"right_shoulder": 0.0}, 1.0, source="after"))
        await asyncio.sleep(0.3)
        waiting.cancel()
        await asyncio.gather(first, after, waiting, return_exceptions=True)
        assert [g for g in goals if g.source == "gone"] == []
        assert [g.source for g in goals][-1] == "after"
        assert servos.claimed() == frozenset()

    simtime.run(main(), virtual=True)
