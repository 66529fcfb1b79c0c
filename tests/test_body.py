"""Kaspar's body language: behaviour files, the joints layer's stream, the layers, cancellation."""

from __future__ import annotations

import itertools
import random
import re
from pathlib import Path

import msgspec
import pytest
import structlog
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from servo_fixtures import FakeClock

from hal.errors import ServoFaultError
from hal.servos.api import FaultKind
from hal.servos.sim import SimServos
from kasparctl.body.api import Gaze, GazeKind, StillBody
from kasparctl.body.behaviours import (
    Behaviour,
    BehaviourError,
    load_library,
    minimum_jerk,
    mirror_joint,
    parse,
)
from kasparctl.body.build import make_body
from kasparctl.body.check import problems
from kasparctl.body.engine import LiveBody
from kasparctl.config import BodySettings, ConfigError, load_config, parse_config
from kasparctl.sim.demo import demo_config

CONFIG = demo_config()
JOINTS = {j.name: j for j in CONFIG.servos.joints}
PERIOD = 0.02


# --- the file format --------------------------------------------------------------------


KASPAR_3 = Path(__file__).resolve().parent.parent / "systemd" / "kaspar-3.toml"


def test_every_shipped_behaviour_fits_kaspar_3_and_the_demo_face():
    library = load_library()
    assert {"greeting", "happy", "sad", "thinking", "wave", "nod", "shake", "farewell",
            "blink", "idle"} <= set(library)
    assert problems(library, load_config(KASPAR_3, poses=False).servos) == []
    # The demo robot has Kaspar 3's head and face, and only the pointing arm's three joints.
    missing = {line.split("joint ")[1].split(":")[0] for line in problems(library, CONFIG.servos)}
    assert missing == {"left_shoulder_roll", "left_elbow"}


def test_an_unknown_key_in_a_keyframe_names_file_behaviour_keyframe_and_key():
    text = "[nod]\nkeyframes = [{ time = 0.3, pose = { head_pitch = 5.0 } },\n" \
           "  { time = 0.6, pose = { head_pitch = 0.0 }, ease = 'in' }]\n"
    with pytest.raises(BehaviourError) as caught:
        parse(text, "nod.toml")
    message = str(caught.value)
    assert message.startswith("nod.toml: behaviour 'nod', keyframe 2, key ease: expected one of "
                              "time, pose, found an unknown key ('in')")


def test_a_wrong_type_says_what_was_expected_and_found():
    with pytest.raises(BehaviourError, match=r"nod.toml: behaviour 'nod', keyframe 1, key "
                                             r"pose.head_pitch: expected a number, found 'up'"):
        parse("[nod]\nkeyframes = [{ time = 0.3, pose = { head_pitch = 'up' } }]\n", "nod.toml")
    with pytest.raises(BehaviourError, match=r"behaviour 'nod', key mirorr: expected one of"):
        parse("[nod]\nmirorr = true\nkeyframes = [{ time = 0.3, pose = { a = 1.0 } }]\n", "x")


def test_times_must_rise_and_like_must_name_a_behaviour_of_the_file():
    with pytest.raises(BehaviourError, match=r"keyframe 2, key time: expected a time after "
                                             r"0.5 s \(the keyframes in order\), found 0.4"):
        parse("[a]\nkeyframes = [{ time = 0.5, pose = { x = 1.0 } }, "
              "{ time = 0.4, pose = { x = 0.0 } }]\n", "a.toml")
    with pytest.raises(BehaviourError, match=r"key like: expected a behaviour of this file"):
        parse("[b]\nlike = 'a'\nmirror = true\n", "b.toml")


def test_mirroring_swaps_sides_and_negates_the_midline_and_eye_yaw_and_roll():
    assert mirror_joint("left_shoulder_roll") == ("right_shoulder_roll", 1.0)
    assert mirror_joint("right_elbow") == ("left_elbow", 1.0)
    assert mirror_joint("head_yaw") == ("head_yaw", -1.0)
    assert mirror_joint("head_roll") == ("head_roll", -1.0)
    assert mirror_joint("head_pitch") == ("head_pitch", 1.0)
    assert mirror_joint("left_eye_yaw") == ("right_eye_yaw", -1.0)
    library = load_library()
    assert library["thinking_left"].keyframes[0][1]["head_yaw"] == pytest.approx(
        -library["thinking"].keyframes[0][1]["head_yaw"])
    assert "left_elbow" in library["wave_left"].joints and "right_elbow" not in (
        library["wave_left"].joints)


def test_minimum_jerk_starts_and_ends_still_and_offsets_scale_with_strength():
    assert minimum_jerk(0.0) == 0.0 and minimum_jerk(1.0) == 1.0 and minimum_jerk(0.5) == 0.5
    (nod,) = parse("[nod]\nkeyframes = [{ time = 1.0, pose = { head_pitch = 10.0 } }]\n",
                   "n").values()
    assert nod.offsets(0.5)["head_pitch"] == pytest.approx(5.0)
    assert nod.offsets(0.5, 0.4)["head_pitch"] == pytest.approx(2.0)
    assert nod.offsets(9.0)["head_pitch"] == 10.0  # holds its last offset


def test_check_names_a_clamped_keyframe_and_a_too_fast_move():
    library = parse(
        "[big]\nkeyframes = [{ time = 2.0, pose = { head_roll = 40.0 } }]\n"
        "[quick]\nkeyframes = [{ time = 0.1, pose = { head_yaw = 20.0 } }]\n"
        "[odd]\nkeyframes = [{ time = 1.0, pose = { tail = 5.0 } }]\n", "mine.toml")
    found = problems(library, CONFIG.servos)
    assert found[0].startswith("mine.toml: behaviour 'big', keyframe 1 (at 2 s), joint head_roll: "
                               "would be clamped: rest 0 + offset 40 = 40 deg, outside")
    assert found[1].startswith("mine.toml: behaviour 'quick', keyframe 1 (at 0.1 s), joint "
                               "head_yaw: too fast: 20 deg in 0.1 s peaks at 375 deg/s")
    assert "joint tail: not a joint of this robot" in found[2]


def test_the_body_table_is_checked_against_the_joints():
    with pytest.raises(ConfigError, match=r"body.mouth_joint: expected a configured joint"):
        parse_config(_demo_toml("[body]\nenabled = true\nmouth_joint = 'jaw'\n"), "k.toml")
    with pytest.raises(ConfigError, match=r"body.gaze.children\[0\].head_yaw"):
        parse_config(_demo_toml("[body]\nenabled = true\n[body.gaze]\n"
                                "children = [{ head_yaw = 99.0 }]\n"), "k.toml")
    with pytest.raises(ConfigError, match=r"body.blink_interval_s: expected \[shortest, longest\]"):
        parse_config(_demo_toml("[body]\nblink_interval_s = [5.0, 2.0]\n"), "k.toml")


def _demo_toml(body: str) -> str:
    from importlib import resources

    text = resources.files("kasparctl.sim").joinpath("demo.toml").read_text(encoding="utf-8")
    return text[: text.index("[body]")] + body


def test_a_disabled_body_is_still():
    config = msgspec.structs.replace(CONFIG, body=BodySettings(enabled=False))
    assert isinstance(make_body(config, object()), StillBody)


# --- the joints layer's stream ----------------------------------------------------------


async def powered(clock: FakeClock) -> SimServos:
    servos = SimServos(CONFIG.servos, clock)
    await servos.start(poll=False)
    for group in servos.groups:
        await servos.set_compliant(group, False)
    for driver in servos.drivers.values():
        driver.writes.clear()
    return servos


async def test_stream_clamps_and_keeps_each_step_under_the_speed_limit():
    clock = FakeClock()
    servos = await powered(clock)
    with structlog.testing.capture_logs() as logs:
        clock.t += PERIOD
        sent = await servos.stream({"head_yaw": 90.0, "mouth_open": -3.0}, PERIOD)
    assert sent["head_yaw"] == pytest.approx(60.0 * PERIOD)  # 60 deg/s for 20 ms
    assert sent["mouth_open"] == pytest.approx(-2.4)  # 120 deg/s for 20 ms, not all 3 deg
    assert any(e["event"] == "joint target clamped to its safe range" for e in logs)
    clock.t += PERIOD / 2  # an early step may move only as far as its time allows
    sent = await servos.stream({"head_yaw": 90.0}, PERIOD)
    assert sent["head_yaw"] == pytest.approx(1.2 + 0.6)


async def test_stream_leaves_limp_joints_alone_and_refuses_while_faulted():
    clock = FakeClock()
    servos = await powered(clock)
    await servos.set_compliant("right_arm", True)
    clock.t += PERIOD
    sent = await servos.stream({"right_elbow": 30.0, "head_pitch": 5.0}, PERIOD)
    assert set(sent) == {"head_pitch"}
    servos.inject_fault("head_pitch", FaultKind.OVERHEATING)
    await servos.poll_health()
    with pytest.raises(ServoFaultError):
        await servos.stream({"head_yaw": 5.0}, PERIOD)


# --- the layers, through the real joints layer ------------------------------------------


def make_live(servos: SimServos, clock: FakeClock, library=None, **body) -> LiveBody:
    settings = msgspec.structs.replace(CONFIG.body, **body)
    return LiveBody(servos, settings, CONFIG.servos, library or load_library(), clock,
                    rng=random.Random(3))


async def run_ticks(body: LiveBody, clock: FakeClock, seconds: float) -> None:
    for _ in range(round(seconds / body.period)):
        clock.t += body.period
        await body.step(clock.now())


def goals(servos: SimServos) -> list[tuple[float, str, float]]:
    names = {(j.bus, j.id): j for j in CONFIG.servos.joints}
    rows = []
    for bus, driver in servos.drivers.items():
        for write in driver.writes:
            for servo_id, raw in write.goals.items():
                joint = names[(bus, servo_id)]
                rows.append((write.time, joint.name,
                             joint.servo.to_degrees(raw, joint.direction, joint.offset_deg)))
    return rows


def assert_safe(rows: list[tuple[float, str, float]], start: dict[str, float]) -> None:
    """Every goal in range; between goals no faster than the limit (one raw unit of rounding)."""
    last = {name: (None, value) for name, value in start.items()}
    for time, name, degrees in sorted(rows):
        joint = JOINTS[name]
        unit = joint.servo.degrees_per_unit
        low, high = joint.range_deg
        assert low - unit <= degrees <= high + unit, (name, degrees)
        before, previous = last[name]
        if before is not None:
            allowed = joint.max_speed_dps * (time - before) + 2 * unit + 1e-9
            assert abs(degrees - previous) <= allowed, (name, time, degrees, previous)
        last[name] = (time, degrees)


async def test_layers_blend_gaze_idle_blink_mouth_and_gesture_by_priority():
    clock = FakeClock()
    servos = await powered(clock)
    body = make_live(servos, clock, blink_interval_s=(0.8, 0.8), idle_interval_s=(0.5, 0.5))
    body.set_alive(True)
    body.look_at(Gaze(GazeKind.CHILD, 2))
    await run_ticks(body, clock, 1.0)
    held = servos.commanded()
    assert held["head_yaw"] != 0.0 and held["left_eyelid"] != 0.0  # looking, mid-blink
    body.mouth.on_envelope(clock.now(), 0.01, [0.3] * 50)
    await run_ticks(body, clock, 0.3)
    assert servos.commanded()["mouth_open"] == pytest.approx(10.0)  # open with the sound
    body.play(load_library()["nod"])
    await run_ticks(body, clock, 0.4)
    assert servos.commanded()["head_pitch"] > 5.0  # the gesture owns the head's pitch
    await run_ticks(body, clock, 1.5)
    assert servos.commanded()["mouth_open"] == 0.0  # closed at the end of the sound
    await body.close()


async def test_cancel_ends_everything_and_nothing_is_sent_after_it():
    clock = FakeClock()
    servos = await powered(clock)
    body = make_live(servos, clock, blink_interval_s=(0.2, 0.2))
    body.set_alive(True)
    body.look_at(Gaze(GazeKind.BAG, 0))
    body.mouth.on_envelope(clock.now(), 0.01, [0.3] * 300)
    playback = body.play(load_library()["wave"])
    await run_ticks(body, clock, 0.5)
    body.cancel()
    assert playback.done is not None and playback.done.done()
    count = len(goals(servos))
    await run_ticks(body, clock, 3.0)
    assert len(goals(servos)) == count
    await body.close()


async def test_a_latched_fault_cancels_the_body():
    clock = FakeClock()
    servos = await powered(clock)
    body = make_live(servos, clock)
    playback = body.play(load_library()["shake"])
    await run_ticks(body, clock, 0.2)
    servos.inject_fault("head_yaw", FaultKind.OVERLOAD)
    await servos.poll_health()  # latches the fault: its listener cancels the body
    assert playback.done is not None and playback.done.done()
    await body.close()


async def test_a_joint_the_robot_lacks_is_skipped_with_one_note():
    clock = FakeClock()
    servos = await powered(clock)
    (odd,) = parse("[odd]\nkeyframes = [{ time = 0.2, pose = { tail = 5.0, head_yaw = 4.0 } }]\n",
                   "odd.toml").values()
    body = make_live(servos, clock)
    with structlog.testing.capture_logs() as logs:
        body.play(odd)
        body.play(odd)
    notes = [e for e in logs if e.get("joint") == "tail"]
    assert len(notes) == 1
    await run_ticks(body, clock, 0.2)
    assert servos.commanded()["head_yaw"] == pytest.approx(4.0, abs=0.5)
    # Its last keyframe is not held: the joint goes home (where the game left it).
    await run_ticks(body, clock, 1.5)
    assert servos.commanded()["head_yaw"] == pytest.approx(0.0, abs=0.06)
    await body.close()


async def test_a_gaze_asked_before_life_is_forbidden_turns_the_head_there_and_holds_it():
    # The game's point: look at the bag, then no life while the arm moves.
    clock = FakeClock()
    servos = await powered(clock)
    body = make_live(servos, clock, blink_interval_s=(0.1, 0.1), idle_interval_s=(0.1, 0.1))
    body.set_alive(True)
    body.look_at(Gaze(GazeKind.BAG, 0))
    body.set_alive(False)
    await run_ticks(body, clock, 1.0)
    bag = dict(CONFIG.body.gaze.bags[0])
    held = servos.commanded()
    # At the bag's pose as the servo has it: its count (the last goal within it is not sent).
    for joint in ("head_yaw", "head_pitch"):
        assert servos.count_of(joint, held[joint]) == servos.count_of(joint, bag[joint])
    assert held["left_eyelid"] == 0.0  # no blink, no idle movement
    body.look_at(Gaze(GazeKind.CHILD, 0))  # no new gaze while life is off
    await run_ticks(body, clock, 1.0)
    assert servos.commanded()["head_yaw"] == pytest.approx(bag["head_yaw"], abs=0.1)
    await body.close()


# --- properties -------------------------------------------------------------------------

joint_names = st.sampled_from(sorted(JOINTS))
keyframes = st.lists(
    st.tuples(st.floats(0.02, 1.5), st.dictionaries(joint_names, st.floats(-200, 200),
                                                    min_size=1, max_size=4)),
    min_size=1, max_size=5,
)


def behaviour_text(frames: list[tuple[float, dict[str, float]]], mirror: bool) -> str:
    lines, time = ["[any]", f"mirror = {'true' if mirror else 'false'}", "keyframes = ["], 0.0
    for gap, pose in frames:
        time += gap
        joints = ", ".join(f"{j} = {v!r}" for j, v in pose.items())
        lines.append(f"  {{ time = {time!r}, pose = {{ {joints} }} }},")
    return "\n".join([*lines, "]"]) + "\n"


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames=keyframes, mirror=st.booleans(), strength=st.floats(0, 1),
       alive=st.booleans(), gaze=st.integers(0, 5), speech=st.lists(st.floats(0, 1), max_size=80),
       cancel_at=st.integers(0, 120), gaze_again=st.booleans())
async def test_any_behaviour_any_blend_any_cancel_stays_in_range_and_under_the_limits(
    frames, mirror, strength, alive, gaze, speech, cancel_at, gaze_again
):
    library = {**load_library(), "any": parse(behaviour_text(frames, mirror), "any.toml")["any"]}
    clock = FakeClock()
    servos = await powered(clock)
    start = servos.commanded()
    body = make_live(servos, clock, library, blink_interval_s=(0.3, 1.0),
                     idle_interval_s=(0.3, 1.0))
    body.set_alive(alive)
    body.look_at(Gaze(GazeKind.BAG, gaze))
    body.mouth.on_envelope(clock.now(), 0.01, speech)
    body.play(library["any"], strength)
    for tick in range(150):
        if tick == cancel_at:
            body.cancel()
            count = len(goals(servos))
        if tick == cancel_at + 20 and gaze_again:
            body.set_alive(True)
            body.look_at(Gaze(GazeKind.CHILD, gaze % 3))
        clock.t += body.period
        await body.step(clock.now())
        if cancel_at <= tick < cancel_at + 20:
            assert len(goals(servos)) == count  # nothing after cancel until asked again
    await body.close()
    assert_safe(goals(servos), start)


async def test_a_behaviour_through_herkulex_servos_emulated_on_a_pty(tmp_path):
    """The same limits on the wire: the real driver, bus and joints layer, an emulated servo."""
    from emulators.herkulex import HerkulexEmulator
    from servo_fixtures import make_driver

    from hal.servos import herkulex as hx
    from hal.servos.joints import Joints
    from hal.servos.settings import BusSettings, JointSettings, ServoSettings

    joints = (
        JointSettings(name="head_yaw", bus="head", id=1, model="drs-0101",
                      range_deg=(-60.0, 60.0), max_speed_dps=60.0, group="head"),
        JointSettings(name="head_roll", bus="head", id=2, model="drs-0101",
                      range_deg=(-15.0, 15.0), max_speed_dps=45.0, group="head"),
    )
    clock = FakeClock()
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], clock=clock.now) as emulator:
        seen: list[tuple[float, int, int]] = []
        jog = emulator._jog

        def recording(command: int, data: bytes) -> None:
            entries = ([data[i:i + 4] for i in range(1, len(data) - 3, 4)]
                       if command == hx.Command.S_JOG else
                       [data[i:i + 4] for i in range(0, len(data) - 4, 5)])
            for entry in entries:
                seen.append((clock.now(), entry[3], hx.u16(entry) & 0x7FFF))
            jog(command, data)

        emulator._jog = recording
        settings_ = ServoSettings(backend="real", buses=(BusSettings(
            name="head", port=str(emulator.path), protocol="herkulex", baud=115200),),
            joints=joints)
        servos = Joints(settings_, {"head": make_driver("herkulex", emulator.path, baud=115200)},
                        clock)
        await servos.start(poll=False)
        try:
            await servos.set_compliant("head", False)
            start = servos.commanded()
            (wild,) = parse("[wild]\nkeyframes = [{ time = 0.1, pose = { head_yaw = 90.0, "
                            "head_roll = -40.0 } }, { time = 0.3, pose = { head_yaw = -90.0 } }]\n",
                            "wild.toml").values()
            body = LiveBody(servos, CONFIG.body, settings_, {"wild": wild}, clock)
            body.play(wild, 1.0)
            for _ in range(40):
                clock.t += body.period
                await body.step(clock.now())
            body.cancel()
            await body.close()
        finally:
            await servos.close()
    by_id = {1: joints[0], 2: joints[1]}
    rows = [(t, by_id[i].name, by_id[i].servo.to_degrees(raw, 1, 0.0)) for t, i, raw in seen
            if i in by_id]
    assert len({name for _, name, _ in rows}) == 2
    # The emulator stamps a packet when it reads it, which may be a tick late (a jog has no
    # reply to wait for): check by order. The body sends at most one goal per joint a tick.
    for joint in joints:
        values = [start[joint.name]] + [v for _, n, v in rows if n == joint.name]
        unit = joint.servo.degrees_per_unit
        steps = [abs(b - a) for a, b in itertools.pairwise(values)]
        assert max(steps) <= joint.max_speed_dps * PERIOD + 2 * unit + 1e-9, joint.name
        assert all(joint.range_deg[0] - unit <= v <= joint.range_deg[1] + unit for v in values)
    assert min(v for _, n, v in rows if n == "head_roll") >= -15.0 - 0.33  # clamped


def test_behaviour_is_a_frozen_value():
    with pytest.raises(AttributeError):
        Behaviour("x", "y", "", ()).name = "z"  # type: ignore[misc]


# --- behaviour record and the command line ----------------------------------------------


async def test_a_behaviour_recorded_by_hand_is_saved_as_offsets_and_reads_back(tmp_path):
    import asyncio
    import io

    from kasparctl.bringup.behaviours import record
    from kasparctl.bringup.engineer import Engineer

    config = msgspec.structs.replace(
        CONFIG, body=msgspec.structs.replace(CONFIG.body, behaviours_dir=str(tmp_path)))
    class StillClock(FakeClock):
        """Time moves only when the test says (the health poll waits without moving it)."""

        async def sleep(self, seconds: float) -> None:
            await asyncio.sleep(0.001)

    clock = StillClock()
    servos = SimServos(config.servos, clock)
    engineer = Engineer(config, clock, seconds=1.0, quiet=True, out=io.StringIO())
    presses: asyncio.Queue[str] = asyncio.Queue()

    async def demonstrate() -> None:
        while not servos.commanded() or servos.servo("head_yaw").torque:
            await asyncio.sleep(0)
        for degrees in (10.0, -5.0):
            clock.t += 0.5
            servos.push("head_yaw", degrees)
            presses.put_nowait("key")
            await asyncio.sleep(0.01)
        presses.put_nowait("save")

    helper = asyncio.ensure_future(demonstrate())
    path = await record(config, servos, engineer, "look", ["head_yaw"], presses)
    await helper
    assert path == tmp_path / "look.toml"
    (look,) = load_library(tmp_path).values()
    assert [pose["head_yaw"] for _, pose in look.keyframes] == pytest.approx([10.0, -5.0], abs=0.4)
    assert [time for time, _ in look.keyframes] == pytest.approx([0.5, 1.0])


def test_behaviour_check_and_play_on_the_command_line(tmp_path, capsys):
    from kasparctl.cli import main

    assert main(["behaviour", "check", "--config", str(KASPAR_3)]) == 0
    assert "12 behaviours fit the robot's 22 joints" in capsys.readouterr().out
    config = tmp_path / "k.toml"
    config.write_text(_demo_toml("[body]\nenabled = true\n"), encoding="utf-8")
    motion = tmp_path / "nod.csv"
    assert main(["behaviour", "play", "nod", "--config", str(config), "--motion",
                 str(motion)]) == 0
    # The goals sent: from within a count of where it stood (the first and last goals that
    # round to the count already held are not sent) to the nod's depth.
    low, high = re.search(r"head_pitch \+([\d.]+)\.\.\+([\d.]+)", capsys.readouterr().out).groups()
    assert float(low) <= _unit("head_pitch") and float(high) == 9.0
    lines = motion.read_text(encoding="utf-8").splitlines()
    assert lines[0] == "time_s,joint,position_deg" and {ln.split(",")[1] for ln in lines[1:]} == {
        "head_pitch"}
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "x.toml").write_text("[quick]\nkeyframes = [{ time = 0.1, pose = { head_yaw = 30.0 }"
                                 " }]\n", encoding="utf-8")
    config.write_text(_demo_toml(f"[body]\nbehaviours_dir = '{mine}'\n"), encoding="utf-8")
    assert main(["behaviour", "check", "--config", str(config)]) == 1
    assert "behaviour 'quick', keyframe 1 (at 0.1 s), joint head_yaw: too fast" in (
        capsys.readouterr().out)


def test_say_motion_writes_the_mouth_from_time_zero(tmp_path, capsys):
    from kasparctl.cli import main

    motion, wav = tmp_path / "m.csv", tmp_path / "m.wav"
    assert main(["say", "Hello there, children.", "--wav", str(wav), "--motion", str(motion)]) == 0
    rows = [line.split(",") for line in motion.read_text(encoding="utf-8").splitlines()[1:]]
    assert {row[1] for row in rows} == {"mouth_open"}
    assert max(float(row[2]) for row in rows) > 5.0 and float(rows[-1][2]) == 0.0
    # Opening from closed at the first sample: its first goal is the first count above it.
    assert float(rows[0][0]) >= 0.0 and 0.0 < float(rows[0][2]) <= _unit("mouth_open") + 1e-9


def _unit(joint: str) -> float:
    """Degrees per count of `joint`'s servo on the demo robot."""
    return next(j for j in CONFIG.servos.joints if j.name == joint).servo.degrees_per_unit
