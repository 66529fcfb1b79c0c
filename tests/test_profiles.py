"""The shipped robots: the published Kaspar 3 and Kaspar-1c, and the demo robot.

- docs/servos.md's tables are the profiles' (tests/profile_table.py writes them);
- the profiles' raw ranges are the published limits, written here from the published
  files themselves (robot.xml), not from the profiles;
- `kasparctl check` passes on each profile with its buses on the emulators;
- every shipped behaviour and pose, played on each profile through the emulators over a
  pty, keeps every goal the servos receive inside the published range and every joint
  within its speed limit, with nothing clamped;
- one robot's centres file: the ten published ones load, and a bad one is refused,
  naming the file and the key.
"""

from __future__ import annotations

import asyncio
import shutil
from pathlib import Path

import msgspec
import pytest
import structlog
from emulators.dynamixel import Dynamixel1Emulator
from emulators.herkulex import HerkulexEmulator
from emulators.maestro import MaestroEmulator
from profile_table import DOC, current, tables
from servo_fixtures import FakeClock, make_driver

from hal.servos import dynamixel1 as dx1
from hal.servos.joints import Joints
from kasparctl.body.behaviours import load_library
from kasparctl.body.check import problems
from kasparctl.body.engine import LiveBody
from kasparctl.cli import main
from kasparctl.config import ConfigError, load_config
from kasparctl.config.poses import read_poses

SYSTEMD = Path(__file__).resolve().parent.parent / "systemd"
PROFILES = ("kaspar-3.toml", "kaspar-1c.toml", "kaspar.toml")

# Kaspar 3, robot.xml: id -> raw limits, CENTER + LIMITS POS / 0.352 (360/1023), rounded,
# within the DRS-0101's 21..1002 (kaspar-hardware.md gives the head's and face's).
KASPAR_3_RAW = {
    1: (435, 589), 2: (367, 657), 3: (469, 583), 4: (427, 597), 5: (614, 651), 6: (444, 526),
    16: (21, 682), 17: (128, 640), 18: (427, 924), 19: (484, 896), 20: (256, 640),
    32: (342, 1002), 33: (384, 896), 34: (100, 597), 35: (128, 540), 36: (384, 768),
}
# The eyes, channel -> microseconds: CENTER 1500 + LIMITS / 0.18 (EYELIDS' 0..60 for the lids).
KASPAR_3_EYES_US = {6: (1300, 1700), 7: (1300, 1700), 8: (1500, 1833.3), 9: (1300, 1700),
                    10: (1300, 1700), 11: (1166.7, 1500)}
# Kaspar-1c, robot.xml: id -> LIMITS pos MIN, MAX (ARM_R_3's MAX 1100 is past the AX-12A's 1023).
KASPAR_1C_RAW = {
    1: (360, 600), 2: (305, 0), 3: (494, 240), 4: (186, 586), 5: (457, 757), 6: (769, 601),
    7: (381, 556), 8: (180, 709), 9: (100, 867), 10: (164, 587), 11: (324, 1023),
    12: (837, 449), 13: (241, 858), 14: (611, 188), 15: (0, 696), 16: (497, 885),
    17: (590, 240),
}


def test_the_doc_tables_are_the_profiles():
    assert current(DOC.read_text(encoding="utf-8")) == tables(), (
        "docs/servos.md's tables differ from the profiles: run .venv/bin/python "
        "tests/profile_table.py")


def _raw_ends(joint) -> tuple[int, int]:
    low, high = joint.range_deg
    ends = sorted(joint.servo.to_raw(end, joint.direction, joint.offset_deg) for end in (low, high))
    return ends[0], ends[1]


def test_kaspar_3_is_the_published_kaspar_3():
    servos = load_config(SYSTEMD / "kaspar-3.toml").servos
    body = {j.id: j for j in servos.joints if j.bus == "body"}
    assert {i: _raw_ends(j) for i, j in body.items()} == KASPAR_3_RAW
    assert {i: j.servo.protocol for i, j in body.items()} == dict.fromkeys(KASPAR_3_RAW, "herkulex")
    assert servos.bus("body").baud == 115200
    assert body[5].name == "mouth_open" and body[5].servo.raw_centre == 620
    assert [body[i].name for i in (1, 2, 3, 4, 6)] == [
        "torso_yaw", "head_yaw", "head_pitch", "head_roll", "smile"]
    assert all(body[i].group == "left_arm" for i in range(16, 21))
    assert all(body[i].group == "right_arm" for i in range(32, 37))
    eyes = {j.id: j for j in servos.joints if j.bus == "eyes"}
    assert set(eyes) == set(KASPAR_3_EYES_US)
    for channel, (low, high) in KASPAR_3_EYES_US.items():
        assert [r / 4 for r in _raw_ends(eyes[channel])] == pytest.approx([low, high], abs=0.3)
    assert [eyes[i].name for i in range(6, 12)] == [
        "right_eye_yaw", "right_eye_pitch", "right_eyelid",
        "left_eye_yaw", "left_eye_pitch", "left_eyelid"]
    assert servos.virtual == {
        "eyes_yaw": {"right_eye_yaw": 1.0, "left_eye_yaw": 1.0},
        "eyes_pitch": {"right_eye_pitch": 1.0, "left_eye_pitch": 1.0},
        "eyelids": {"right_eyelid": 1.0, "left_eyelid": 1.0},
    }
    assert {(c.joint, c.follows, c.ratio) for c in servos.couplings} == {
        ("right_eyelid", "right_eye_pitch", -1.0), ("left_eyelid", "left_eye_pitch", -1.0)}


def test_kaspar_1c_is_the_published_kaspar_1c():
    servos = load_config(SYSTEMD / "kaspar-1c.toml").servos
    joints = {j.id: j for j in servos.joints}
    assert {i: _raw_ends(j) for i, j in joints.items()} == {
        i: tuple(sorted(ends)) for i, ends in KASPAR_1C_RAW.items()}
    assert servos.bus("body").baud == 57600 and servos.bus("body").protocol == "dynamixel1"
    assert [joints[i].name for i in (6, 7, 8)] == ["head_roll", "head_pitch", "head_yaw"]
    assert {joints[i].group for i in range(9, 13)} == {"right_arm"}
    assert {joints[i].group for i in range(13, 17)} == {"left_arm"}
    for i, joint in joints.items():
        rest = joint.servo.to_raw(joint.rest_deg, joint.direction, joint.offset_deg)
        low, high = _raw_ends(joint)
        assert low <= rest <= high, (i, joint.name)
    # robot.xml's DEFAULT POS (scaled from MIN to MAX): the eyelids 670 of 305..0 = raw 101.
    eyelids = joints[2]
    assert eyelids.servo.to_raw(eyelids.rest_deg, eyelids.direction, eyelids.offset_deg) == 101


def test_the_demo_robot_says_it_is_the_demo_robot():
    head = (SYSTEMD / "kaspar.toml").read_text(encoding="utf-8").split("\n[")[0]
    assert "DEMO robot" in head and "NOT a real robot's" in head


# --- one robot's centres ---------------------------------------------------------------------


def _copy(profile: str, tmp_path: Path) -> Path:
    for name in (profile, profile.replace(".toml", "-poses.toml")):
        if (SYSTEMD / name).exists():
            shutil.copy(SYSTEMD / name, tmp_path / name)
    return tmp_path / profile


def _with_centres(tmp_path: Path, text: str) -> Path:
    path = _copy("kaspar-3.toml", tmp_path)
    (tmp_path / "mine.toml").write_text(text)
    path.write_text('centres_file = "mine.toml"\n' + path.read_text())
    return path


@pytest.mark.parametrize("number", range(1, 11))
def test_each_published_kaspar_3_loads_with_its_own_centres(number, tmp_path):
    robots = SYSTEMD / "kaspar-3-robots"
    text = (robots / f"kaspar3-{number}.toml").read_text()
    config = load_config(_with_centres(tmp_path, text))
    joints = {j.name: j for j in config.servos.joints}
    for block in text.split("\n[")[1:]:
        name = block.split("]")[0]
        centre = int(block.split("centre_raw = ")[1].split()[0])
        assert joints[name].servo.raw_centre == centre
        # The range stays relative to the centre, as the published limits were.
        model = joints[name].servo
        assert model.to_raw(0.0, joints[name].direction, 0.0) == centre


def test_kaspar_3_no_8s_torso_centre_moves_its_published_limits(tmp_path):
    text = (SYSTEMD / "kaspar-3-robots" / "kaspar3-8.toml").read_text()
    torso = next(j for j in load_config(_with_centres(tmp_path, text)).servos.joints
                 if j.name == "torso_yaw")
    assert _raw_ends(torso) == (457, 611)  # 534 -/+ 27 / 0.352


@pytest.mark.parametrize(("text", "key", "says"), [
    ("[rigth_eyelid]\ncentre_raw = 6000\n", "rigth_eyelid",
     "expected a joint of the profile (torso_yaw, "),
    ("[right_eyelid]\ncenter_raw = 6000\n", "right_eyelid.center_raw",
     "expected one of centre_raw, found an unknown key"),
    ("[right_eyelid]\ncentre_raw = 1350.0\n", "right_eyelid.centre_raw",
     "expected a whole number of the servo's raw units, found 1350.0"),
    ("[right_eyelid]\ncentre_raw = 1350\n", "right_eyelid.centre_raw",
     "centre_raw 1350 is outside what a hs-82mg can take, 3968 to 8000 (quarter-microseconds"),
])
def test_a_bad_centres_file_is_refused_naming_the_file_and_the_key(text, key, says, tmp_path):
    with pytest.raises(ConfigError) as caught:
        load_config(_with_centres(tmp_path, text))
    assert caught.value.source == str(tmp_path / "mine.toml")
    assert caught.value.key == key
    assert says in str(caught.value)


# --- the profiles on the emulators ----------------------------------------------------------


class _Recording:
    """Every goal each emulated servo took, as the emulator decoded it (raw, at the wire)."""

    def start_recording(self) -> None:
        self.goals: list[tuple[int, float]] = []
        self._seen: dict[int, float] = {}

    def handle(self, packet: bytes):
        replies = super().handle(packet)  # type: ignore[misc]
        for servo_id, goal in self.goal_state().items():
            if self._seen.get(servo_id) != goal:
                self._seen[servo_id] = goal
                self.goals.append((servo_id, goal))
        return replies


class RecordingHerkulex(_Recording, HerkulexEmulator):
    def goal_state(self) -> dict[int, float]:
        return {i: s.axis.goal for i, s in self.servos.items() if s.torque_on}


class RecordingMaestro(_Recording, MaestroEmulator):
    def goal_state(self) -> dict[int, float]:
        return {ch: float(t) for ch, t in enumerate(self.targets) if t}


class RecordingDynamixel(_Recording, Dynamixel1Emulator):
    def goal_state(self) -> dict[int, float]:
        return {i: float(dx1.u16(t, dx1.AX12.GOAL_POSITION)) for i, t in self.tables.items()
                if t[dx1.AX12.TORQUE_ENABLE]}


def _emulators(servos, tmp_path: Path):
    """An emulator per bus, every servo at its rest; the settings' ports pointed at them."""
    emulators, buses = {}, []
    for bus in servos.buses:
        path = tmp_path / f"tty-{bus.name}"
        members = [j for j in servos.joints if j.bus == bus.name]
        rests = {j.id: j.servo.to_raw(j.rest_deg, j.direction, j.offset_deg) for j in members}
        if bus.protocol == "herkulex":
            emulator = RecordingHerkulex(path, ids=sorted(rests), positions=rests)
        elif bus.protocol == "maestro":
            emulator = RecordingMaestro(path, channels=18)
        else:
            emulator = RecordingDynamixel(path, ids=sorted(rests))
            for servo_id, raw in rests.items():
                emulator.set_present(servo_id, raw)
        emulator.start_recording()
        emulators[bus.name] = emulator
        buses.append(msgspec.structs.replace(bus, port=str(path)))
    return emulators, msgspec.structs.replace(servos, buses=tuple(buses))


@pytest.mark.parametrize("profile", PROFILES)
def test_check_passes_on_each_profile_with_its_buses_on_the_emulators(profile, tmp_path, capsys):
    path = _copy(profile, tmp_path)
    servos = load_config(path).servos
    emulators, _ = _emulators(servos, tmp_path)
    text = path.read_text()
    for bus in servos.buses:
        text = text.replace(f'port = "{bus.port}"', f'port = "{emulators[bus.name].path}"', 1)
    # The servos are what this checks: the input devices and the voice are simulated.
    if "\n[keyfob]\n" in text:
        text = text.replace("\n[keyfob]\n", "\n[keyfob]\nbackend = 'sim'\n", 1)
    else:
        text += "\n[keyfob]\nbackend = 'sim'\n"
    if "\n[voice]\n" not in text:
        text += "\n[voice]\nbackend = 'sim'\n"
    path.write_text(text)
    try:
        code = main(["check", "--config", str(path), "--quiet"])
    finally:
        for emulator in emulators.values():
            emulator.stop()
    out = capsys.readouterr().out
    assert code == 0, out
    assert f"all {len(servos.joints)} servos answered" in out


def _published_raw(profile: str, bus_protocol: str, servo_id: int, joint) -> tuple[float, float]:
    if profile == "kaspar-3.toml":
        if bus_protocol == "maestro":
            low, high = KASPAR_3_EYES_US[servo_id]
            return low * 4 - 1, high * 4 + 1
        return KASPAR_3_RAW[servo_id]
    if profile == "kaspar-1c.toml":
        low, high = sorted(KASPAR_1C_RAW[servo_id])
        return low, high
    return _raw_ends(joint)  # the demo robot: its own ranges, there being no published ones


async def _play_everything(profile: str, tmp_path: Path):
    config = load_config(SYSTEMD / profile)
    emulators, servos = _emulators(config.servos, tmp_path)
    clock = FakeClock()
    drivers = {bus.name: make_driver(bus.protocol, bus.port, bus.baud) for bus in servos.buses}
    joints = Joints(servos, drivers, clock)
    told: list = []
    joints.on_goals(told.append)
    try:
        await joints.start(poll=False)
        for group in joints.groups:
            await joints.set_compliant(group, False)
        await joints.rest()
        body = msgspec.structs.replace(config.body, enabled=True, idle_amplitude=0.0,
                                       blink_interval_s=(60.0, 60.0))
        library = load_library()
        live = LiveBody(joints, body, servos, library, clock)
        with structlog.testing.capture_logs() as logs:
            for behaviour in library.values():
                live.play(behaviour)
                for _ in range(round((behaviour.duration + 2.0) / live.period)):
                    clock.t += live.period
                    await live.step(clock.now())
            poses = read_poses(config.poses_file) if config.poses_file else {}
            for pose in poses.values():
                await joints.move(pose)
                await joints.rest()
    finally:
        await joints.close()
        for emulator in emulators.values():
            emulator.stop()
    return servos, emulators, told, logs


@pytest.mark.parametrize("profile", PROFILES)
def test_every_behaviour_and_pose_stays_in_the_published_range_and_speed(profile, tmp_path):
    servos, emulators, told, logs = asyncio.run(_play_everything(profile, tmp_path))
    # The body squashes a behaviour against a limit quietly: `behaviour check` says whether
    # any would be; the joints layer logs every goal it clamps.
    assert problems(load_library(), servos) == []
    clamped = [e for e in logs if "clamped" in e["event"]]
    assert clamped == []
    by_id = {(j.bus, j.id): j for j in servos.joints}
    received = 0
    for bus in servos.buses:
        for servo_id, goal in emulators[bus.name].goals:
            joint = by_id[(bus.name, servo_id)]
            low, high = _published_raw(profile, bus.protocol, servo_id, joint)
            assert low <= goal <= high, (joint.name, goal, (low, high))
            received += 1
    assert received > 100
    limits = {j.name: j.max_speed_dps for j in servos.joints}
    last: dict[str, tuple[float, float]] = {}
    moved = set()
    for goal in told:
        if goal.joint in last:
            time, degrees = last[goal.joint]
            if goal.time > time:
                speed = abs(goal.degrees - degrees) / (goal.time - time)
                assert speed <= limits[goal.joint] * 1.001 + 1e-6, (goal, degrees)
            if goal.degrees != degrees:
                moved.add(goal.joint)
        last[goal.joint] = (goal.time, goal.degrees)
    # Every behaviour played on something: the head, the face and both arms moved.
    assert {"head_pitch", "head_yaw", "smile", "right_elbow"} <= moved
