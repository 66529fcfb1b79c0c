"""Virtual joints and couplings: the settings' rules, and the joints layer moving them."""

from __future__ import annotations

import asyncio

import msgspec
import pytest
from servo_fixtures import FakeClock

from hal.errors import SettingsError, UnknownJoint, UnsafeCommand
from hal.servos.settings import ServoSettings
from hal.servos.sim import SimServos

EYES = {
    "backend": "sim",
    "buses": [{"name": "eyes", "port": "/dev/eyes", "protocol": "maestro"}],
    "joints": [
        {"name": "right_eye_pitch", "bus": "eyes", "id": 7, "model": "hs-82mg",
         "range_deg": [-18.0, 18.0], "max_speed_dps": 90.0, "group": "eyes"},
        {"name": "right_eyelid", "bus": "eyes", "id": 8, "model": "hs-82mg",
         "range_deg": [0.0, 30.0], "max_speed_dps": 300.0, "group": "eyes"},
        {"name": "left_eye_pitch", "bus": "eyes", "id": 10, "model": "hs-82mg", "direction": -1,
         "range_deg": [-18.0, 18.0], "max_speed_dps": 90.0, "group": "eyes"},
        {"name": "left_eyelid", "bus": "eyes", "id": 11, "model": "hs-82mg", "direction": -1,
         "range_deg": [0.0, 30.0], "max_speed_dps": 300.0, "group": "eyes"},
    ],
    "virtual_joints": [
        {"name": "eyes_pitch", "drives": {"right_eye_pitch": 1.0, "left_eye_pitch": 1.0}},
        {"name": "eyelids", "drives": {"right_eyelid": 1.0, "left_eyelid": 1.0}},
    ],
    "couplings": [
        {"joint": "right_eyelid", "follows": "right_eye_pitch", "ratio": -1.0},
        {"joint": "left_eyelid", "follows": "left_eye_pitch", "ratio": -1.0},
    ],
}


def settings(**changes) -> ServoSettings:
    return msgspec.convert({**EYES, **changes}, ServoSettings)


def test_realise_expands_virtual_joints_and_moves_followers_with_their_leaders():
    servos = settings()
    assert servos.realise({"eyelids": 10.0}) == {"right_eyelid": 10.0, "left_eyelid": 10.0}
    # The eyes 6 down: each lid follows its eyeball (ratio -1) from where it is.
    assert servos.realise({"eyes_pitch": 6.0}, {"right_eyelid": 10.0, "left_eyelid": 8.0}) == {
        "right_eye_pitch": 6.0, "left_eye_pitch": 6.0, "right_eyelid": 4.0, "left_eyelid": 2.0}
    assert servos.realise({"eyes_pitch": -6.0, "eyelids": 2.0}) == {
        "right_eye_pitch": -6.0, "left_eye_pitch": -6.0, "right_eyelid": 8.0, "left_eyelid": 8.0}
    with pytest.raises(SettingsError, match="joint 'right_eyelid' is set twice: by eyelids and "
                                            "by right_eyelid"):
        servos.realise({"eyelids": 2.0, "right_eyelid": 3.0})


@pytest.mark.parametrize(("changes", "message"), [
    ({"virtual_joints": [{"name": "eyes", "drives": {"right_eye_pitch": 1.0}}]},
     "virtual_joints[0] (eyes): name 'eyes' is already a joint, group or virtual joint"),
    ({"virtual_joints": [{"name": "gaze", "drives": {"rigth_eye_pitch": 1.0}}]},
     "virtual_joints[0] (gaze): drives.rigth_eye_pitch: expected a configured real joint"),
    ({"virtual_joints": [{"name": "gaze", "drives": {"right_eye_pitch": 0.0}}]},
     "drives.right_eye_pitch: expected a ratio other than 0"),
    ({"virtual_joints": [{"name": "gaze", "drives": {}}]},
     "drives: expected at least one real joint"),
    ({"couplings": [{"joint": "right_eyelid", "follows": "eyelids", "ratio": 1.0}]},
     "couplings[0] (right_eyelid): follows: expected a configured real joint"),
    ({"couplings": [{"joint": "right_eyelid", "follows": "right_eye_pitch", "ratio": 1.0},
                    {"joint": "right_eyelid", "follows": "left_eye_pitch", "ratio": 1.0}]},
     "couplings[1] (right_eyelid): joint: 'right_eyelid' already follows a joint"),
    ({"couplings": [{"joint": "right_eyelid", "follows": "right_eye_pitch", "ratio": 1.0},
                    {"joint": "left_eyelid", "follows": "right_eyelid", "ratio": 1.0}]},
     "couplings[0] (right_eyelid): joint: 'right_eyelid' is itself followed: no chains"),
    ({"couplings": [{"joint": "right_eyelid", "follows": "right_eyelid", "ratio": 1.0}]},
     "a joint cannot follow itself"),
])
def test_virtual_joints_and_couplings_are_strict(changes, message):
    with pytest.raises(msgspec.ValidationError) as caught:
        settings(**changes)
    assert message in str(caught.value)


async def _powered() -> tuple[SimServos, FakeClock]:
    clock = FakeClock()
    servos = SimServos(settings(), clock)
    await servos.start(poll=False)
    await servos.set_compliant("eyes", False)
    return servos, clock


async def test_a_move_on_a_virtual_joint_claims_clamps_and_moves_the_real_joints():
    servos, _clock = await _powered()
    seen: list[frozenset[str]] = []
    goals = []
    servos.on_goals(goals.append)

    async def watch() -> None:
        while True:
            seen.append(servos.claimed())
            await asyncio.sleep(0)

    watcher = asyncio.create_task(watch())
    await servos.move({"eyes_pitch": 40.0})  # past the range: each real joint clamped
    watcher.cancel()
    assert frozenset({"right_eye_pitch", "left_eye_pitch", "right_eyelid", "left_eyelid"}) in seen
    held = servos.commanded()
    assert held["right_eye_pitch"] == held["left_eye_pitch"] == 18.0
    # The lids followed their eyeballs down (ratio -1), clamped at their open end; their own
    # value stays where they were (0), so when the eyes come back up, so do the lids.
    last = {g.joint: g.degrees for g in goals}
    assert last["right_eyelid"] == last["left_eyelid"] == 0.0
    assert held["right_eyelid"] == held["left_eyelid"] == 0.0
    await servos.move({"eyelids": 10.0})
    await servos.move({"eyes_pitch": 0.0})
    last = {g.joint: g.degrees for g in goals}
    assert last["right_eyelid"] == pytest.approx(10.0)
    assert servos.commanded()["right_eyelid"] == pytest.approx(10.0)


async def test_a_stream_on_a_virtual_joint_moves_both_and_a_lid_with_its_eye():
    servos, clock = await _powered()
    for _ in range(50):
        clock.t += 0.02
        sent = await servos.stream({"eyelids": 20.0, "eyes_pitch": -6.0}, 0.02)
    assert sent == {}  # arrived: nothing left to send
    held = servos.commanded()
    assert held["right_eye_pitch"] == pytest.approx(-6.0)
    assert held["right_eyelid"] == pytest.approx(20.0)  # its own value, as asked
    raw = servos.servo("right_eyelid").goal
    lid = next(j for j in servos.settings.joints if j.name == "right_eyelid")
    # At the wire the lid is its own 20 plus its eye's share, 6: 26 degrees.
    assert lid.servo.to_degrees(raw, lid.direction, lid.offset_deg) == pytest.approx(26.0, abs=0.05)
    with pytest.raises(UnsafeCommand, match="set twice"):
        await servos.stream({"eyelids": 1.0, "left_eyelid": 2.0}, 0.02)
    with pytest.raises(UnknownJoint, match="eyelid"):
        await servos.stream({"eyelid": 1.0}, 0.02)


def test_behaviour_check_adds_a_leader_s_share_to_its_follower():
    from pathlib import Path

    from kasparctl.body.behaviours import parse
    from kasparctl.body.check import problems
    from kasparctl.config import load_config

    kaspar_3 = load_config(Path(__file__).resolve().parent.parent / "systemd" / "kaspar-3.toml")
    # The eyes 6 down open each lid 6 (ratio -1): closing it only 5 ends it past open.
    text = ("[sulk]\nkeyframes = [{ time = 0.8, pose = { eyes_pitch = 6.0, eyelids = 5.0 } }]\n"
            "[fine]\nkeyframes = [{ time = 0.8, pose = { eyes_pitch = 6.0, eyelids = 8.0 } }]\n"
            "[twice]\nkeyframes = [{ time = 0.8, pose = { eyelids = 6.0, left_eyelid = 1.0 } }]\n")
    found = problems(parse(text, "mine.toml"), kaspar_3.servos)
    assert [line.split(": ")[1].split(",")[0] for line in found] == [
        "behaviour 'sulk'", "behaviour 'sulk'", "behaviour 'twice'"]
    assert ("joint right_eyelid (following right_eye_pitch), at 0.80 s: would be clamped: "
            "-1 deg, outside its safe range [0, 30]") in found[0]
    assert "joint left_eyelid is set twice, by eyelids and by left_eyelid" in found[2]


async def test_gaze_may_name_a_virtual_joint_and_moves_both_eyes():
    import random

    from kasparctl.body.api import Gaze, GazeKind
    from kasparctl.body.behaviours import load_library
    from kasparctl.body.engine import LiveBody
    from kasparctl.config import BodySettings, GazeSettings

    servos, clock = await _powered()
    body = BodySettings(enabled=True, mouth_joint="", idle_amplitude=0.0,
                        blink_interval_s=(60.0, 60.0),
                        gaze=GazeSettings(children=({"eyes_pitch": 10.0},)))
    live = LiveBody(servos, body, servos.settings, load_library(), clock, rng=random.Random(1))
    live.set_alive(True)
    live.look_at(Gaze(GazeKind.CHILD, 0))
    for _ in range(100):
        clock.t += live.period
        await live.step(clock.now())
    held = servos.commanded()
    # Both at the pose's count (a last goal within the count already sent is not sent).
    for eye in ("right_eye_pitch", "left_eye_pitch"):
        assert servos.count_of(eye, held[eye]) == servos.count_of(eye, 10.0)
