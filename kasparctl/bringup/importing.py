"""A lab's published Kaspar content (poses, sequences, keymaps, sounds) as kasparctl's own.

`kasparctl import SOURCE --robot kaspar-1c|kaspar-3 --config PROFILE --out DIR` reads
SOURCE's `pos/*.pose`, `seq/` or `seqs/*.seq`, `keyMaps/*.skm` and `sounds/*` in the
published formats (kasparctl.bringup.legacy) and writes, into DIR (new or empty):

- `poses.toml`: each pose in the profile's degrees (a poses file: `poses_file`);
- `behaviours/imported.toml`: each sequence as a behaviour (`body.behaviours_dir`), its
  timing kept: every step reached as the published robot reached it (each joint at its
  pose's speed, the slowest setting the time), then held for the step's delay;
- `sounds/`: the WAV files, which a behaviour cannot carry: `[voice.clips]` can, per
  phrase key;
- `report.md`: what was carried over, and what was not and why.

Every imported pose is checked against the profile: a value outside a joint's safe
range refuses the pose (and every sequence using it), named with its published value,
its raw position and the range; nothing is clamped. A step the profile's speed limits
would slow is slowed and said so. Conversions go through each servo's raw position:
a Kaspar-1c's scaled value is MIN + (MAX - MIN) * s / 1000 of its robot.xml limits
(SOURCE/robot.xml), a Kaspar 3's degrees are (raw - CENTER) * 0.352 on a HerkuleX and
(us - CENTER) * 0.18 on an HS-82MG, CENTER being the profile's centre_raw (so a robot's
own centres file is honoured).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from hal.errors import SettingsError
from hal.servos.settings import JointSettings, ServoSettings
from kasparctl.body.behaviours import MAX_DURATION_S, MINIMUM_JERK_PEAK, NAME, parse
from kasparctl.body.check import problems
from kasparctl.bringup import legacy
from kasparctl.bringup.engineer import BringUpError
from kasparctl.config import Config, check_pose, read_poses
from kasparctl.game import storage

Robot = Literal["kaspar-1c", "kaspar-3"]
ROBOTS: tuple[Robot, ...] = ("kaspar-1c", "kaspar-3")

# Published joint names -> the shipped profiles' joints (legacyImporter.py's own names
# for Kaspar-1c's, robot.xml's for Kaspar 3's).
KASPAR_1C_JOINTS = {
    "EYES_LR": "eyes_yaw", "EYELIDS": "eyelids", "EYES_UD": "eyes_pitch",
    "MOUTH_OPEN": "mouth_open", "MOUTH_SMILE": "smile", "HEAD_TLT": "head_roll",
    "HEAD_VERT": "head_pitch", "HEAD_ROT": "head_yaw", "TORSO": "torso_yaw",
    "ARM_R_1": "right_shoulder_roll", "ARM_R_2": "right_shoulder_pitch",
    "ARM_R_3": "right_upper_arm_roll", "ARM_R_4": "right_elbow",
    "ARM_L_1": "left_shoulder_roll", "ARM_L_2": "left_shoulder_pitch",
    "ARM_L_3": "left_upper_arm_roll", "ARM_L_4": "left_elbow",
}
KASPAR_3_JOINTS = {
    "TORSO_YAW": "torso_yaw", "HEAD_YAW": "head_yaw", "HEAD_PITCH": "head_pitch",
    "HEAD_ROLL": "head_roll", "MOUTH_OPEN": "mouth_open", "MOUTH_SMILE": "smile",
    "L_SHOULDER_ROLL_UPPER": "left_shoulder_roll", "L_SHOULDER_PITCH": "left_shoulder_pitch",
    "L_SHOULDER_ROLL_LOWER": "left_upper_arm_roll", "L_ELBOW": "left_elbow",
    "L_WRIST_ROLL": "left_wrist",
    "R_SHOULDER_ROLL_UPPER": "right_shoulder_roll", "R_SHOULDER_PITCH": "right_shoulder_pitch",
    "R_SHOULDER_ROLL_LOWER": "right_upper_arm_roll", "R_ELBOW": "right_elbow",
    "R_WRIST_ROLL": "right_wrist",
    "EYE_R_YAW": "right_eye_yaw", "EYEBALL_R_PITCH": "right_eye_pitch",
    "EYE_R_PITCH": "right_eye_pitch",  # virtual there: the eyeball, its lid following
    "EYE_R_LID": "right_eyelid", "EYE_L_YAW": "left_eye_yaw",
    "EYEBALL_L_PITCH": "left_eye_pitch", "EYE_L_PITCH": "left_eye_pitch",
    "EYE_L_LID": "left_eyelid",
}
# Kaspar 3's virtual joints: published name -> (the profile's virtual joint, its MASTER).
KASPAR_3_VIRTUAL = {
    "EYELIDS": ("eyelids", "EYE_R_LID"),
    "EYES_YAW": ("eyes_yaw", "EYE_R_YAW"),
    "EYES_PITCH": ("eyes_pitch", "EYEBALL_R_PITCH"),
}
# The published robots' degrees per raw unit (robot.xml SCALING POS): 360/1023 per
# HerkuleX count, 0.18 per microsecond of an HS-82MG (a Maestro unit is a quarter).
PUBLISHED_DEG_PER_RAW = {"herkulex": 0.352, "maestro": 0.18 / 4}
SERVOS_OF = {"kaspar-1c": ("dynamixel1",), "kaspar-3": ("herkulex", "maestro")}
# An AX-12A moving speed unit: 0.111 rpm.
AX12_DPS_PER_UNIT = 0.666


class ImportFailed(BringUpError):
    """The content cannot be imported at all (no such directory, a profile of another robot)."""


@dataclass
class Converted:
    """One pose in the profile's terms: joint -> degrees, joint -> speed (None: the limit)."""

    degrees: dict[str, float]
    speeds: dict[str, float | None]


@dataclass
class Imported:
    """What an import carried over, and its report's lines."""

    source: Path
    robot: Robot
    profile: str
    poses: dict[str, tuple[str, dict[str, float]]] = field(default_factory=dict)
    behaviours: dict[str, tuple[str, list[tuple[float, dict[str, float]]]]] = field(
        default_factory=dict)
    sounds: dict[str, Path] = field(default_factory=dict)
    carried: list[str] = field(default_factory=list)
    not_carried: list[str] = field(default_factory=list)


def kasparctl_name(name: str, taken: Mapping[str, object], prefix: str) -> str:
    """A published name as a kasparctl one: lower case, digits and _, unique in `taken`."""
    base = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_") or prefix
    if not base[0].isalpha():
        base = f"{prefix}_{base}"
    candidate, number = base, 2
    while candidate in taken:
        candidate, number = f"{base}_{number}", number + 1
    assert NAME.match(candidate)
    return candidate


def _folder(source: Path, *names: str) -> list[Path]:
    """SOURCE's files in the first of `names` (any case) that exists, else none."""
    children = {child.name.lower(): child for child in source.iterdir() if child.is_dir()}
    for name in names:
        folder = children.get(name.lower())
        if folder is not None:
            return sorted(p for p in folder.iterdir() if p.is_file())
    return []


class _Converter:
    """Published values of one robot kind into the profile's degrees, each checked."""

    def __init__(self, robot: Robot, servos: ServoSettings, source: Path) -> None:
        self.robot = robot
        self.servos = servos
        self.joints = {j.name: j for j in servos.joints}
        self.names = KASPAR_1C_JOINTS if robot == "kaspar-1c" else KASPAR_3_JOINTS
        self.limits: dict[str, tuple[int, int]] = {}
        if robot == "kaspar-1c":
            xml = source / "robot.xml"
            if not xml.is_file():
                raise ImportFailed(
                    f"{xml}: missing: a Kaspar-1c pose's scaled positions run from each "
                    "servo's MIN to MAX in its robot.xml; copy the robot's own beside its poses")
            self.limits = legacy.read_limits_1c(xml)
        wrong = [j for j in servos.joints if j.name in self.names.values()
                 and j.servo.protocol not in SERVOS_OF[robot]]
        if wrong:
            joint = wrong[0]
            raise ImportFailed(
                f"the profile's {joint.name} is a {joint.model}, not a {robot}'s servo: import "
                f"{robot} content with a {robot} profile")

    def convert(self, pose: legacy.LegacyPose, where: str, notes: list[str]) -> Converted | None:
        """The pose in the profile's degrees; None (reasons in `notes`) if out of range."""
        degrees: dict[str, float] = {}
        speeds: dict[str, float | None] = {}
        raws: dict[str, str] = {}
        for line in pose.joints:
            converted = self._joint(line, where, notes)
            if converted is None:
                continue
            name, value, speed, raw = converted
            degrees[name], speeds[name], raws[name] = value, speed, raw
        if not degrees:
            notes.append(f"{where}: no joint of this profile: not imported")
            return None
        rests = {j.name: j.rest_deg for j in self.servos.joints}
        try:
            goals = self.servos.realise(degrees, rests)
        except SettingsError as error:
            notes.append(f"{where}: {error}: not imported")
            return None
        outside = []
        for name, value in goals.items():
            joint = self.joints[name]
            low, high = joint.range_deg
            # Within half a count of an end is that end: the same servo position (the
            # profile's degrees are rounded to the thousandth).
            half = joint.servo.degrees_per_unit / 2
            if name in degrees and low - half <= degrees[name] < low:
                degrees[name] = value = low
            elif name in degrees and high < degrees[name] <= high + half:
                degrees[name] = value = high
            if not low - 1e-6 <= value <= high + 1e-6:
                origin = ", ".join(raws[n] for n in self._movers(name, degrees)) or name
                outside.append(f"{origin} puts {name} at {value:.2f} deg, outside its safe "
                               f"range [{low:g}, {high:g}]")
        if outside:
            notes.append(f"{where}: not imported (never clamped): " + "; ".join(outside))
            return None
        return Converted({n: round(v, 3) for n, v in degrees.items()}, speeds)

    def _movers(self, joint: str, pose: Mapping[str, float]) -> list[str]:
        """The names of `pose` that move `joint`: itself, a virtual joint, its leader's."""
        virtual = self.servos.virtual
        leaders = {c.follows for c in self.servos.couplings if c.joint == joint}
        return [n for n in pose if n == joint or n in leaders
                or joint in virtual.get(n, {}) or leaders & set(virtual.get(n, {}))]

    def _joint(
        self, line: legacy.PoseLine, where: str, notes: list[str]
    ) -> tuple[str, float, float | None, str] | None:
        if self.robot == "kaspar-3" and line.joint in KASPAR_3_VIRTUAL:
            virtual, master = KASPAR_3_VIRTUAL[line.joint]
            drives = self.servos.virtual.get(virtual)
            joint = self.joints.get(self.names[master])
            if drives is None or joint is None or joint.name not in drives:
                notes.append(f"{where}: {line.joint}: the profile has no virtual joint "
                             f"{virtual} driving {self.names[master]}: left out")
                return None
            raw = self._raw_3(joint, line.value)
            value = joint.servo.to_degrees(raw, joint.direction, joint.offset_deg)
            return virtual, value / drives[joint.name], None, self._said(line, raw, joint)
        name = self.names.get(line.joint)
        joint = self.joints.get(name) if name else None
        if joint is None:
            notes.append(f"{where}: {line.joint}: not a joint of this profile: left out")
            return None
        if self.robot == "kaspar-1c":
            if line.joint not in self.limits:
                notes.append(f"{where}: {line.joint}: not in robot.xml: left out")
                return None
            low, high = self.limits[line.joint]
            raw = low + (high - low) * line.value / 1000
            speed = line.speed * AX12_DPS_PER_UNIT if line.speed > 0 else None
        else:
            raw = self._raw_3(joint, line.value)
            speed = None  # robot.xml's speed is a share of play time, not a rate
        value = joint.servo.to_degrees(raw, joint.direction, joint.offset_deg)
        return joint.name, value, speed, self._said(line, raw, joint)

    @staticmethod
    def _raw_3(joint: JointSettings, value: float) -> float:
        return joint.servo.raw_centre + value / PUBLISHED_DEG_PER_RAW[joint.servo.protocol]

    @staticmethod
    def _said(line: legacy.PoseLine, raw: float, joint: JointSettings) -> str:
        unit = f" = {raw / 4:.0f} us" if joint.servo.protocol == "maestro" else ""
        return f"{line.joint} {line.value:g} (raw {raw:.0f}{unit})"


def import_content(source: Path, robot: Robot, config: Config, profile: str) -> Imported:
    """Read SOURCE's published content and convert it for `config`'s robot."""
    if not source.is_dir():
        raise ImportFailed(f"{source}: not a directory of published Kaspar content")
    servos = config.servos
    converter = _Converter(robot, servos, source)
    result = Imported(source, robot, profile)
    notes = result.not_carried
    read_pose = legacy.read_pose_1c if robot == "kaspar-1c" else legacy.read_pose_3
    read_sequence = legacy.read_sequence_1c if robot == "kaspar-1c" else legacy.read_sequence_3
    by_file: dict[str, tuple[str, Converted | None]] = {}
    by_name: dict[str, tuple[str, Converted | None]] = {}
    for path in _folder(source, "pos"):
        if path.suffix.lower() != ".pose":
            notes.append(f"pos/{path.name}: not a .pose file: left out")
            continue
        try:
            pose = read_pose(path)
        except legacy.LegacyError as error:
            notes.append(f"{error}: not imported")
            continue
        where = f"pose {pose.name!r} (pos/{path.name})"
        converted = converter.convert(pose, where, notes)
        name = kasparctl_name(pose.name, result.poses, "pose")
        if converted is not None:
            result.poses[name] = (where, converted.degrees)
            result.carried.append(f"{where} -> pose {name}: " + ", ".join(
                f"{j} {v:g}" for j, v in converted.degrees.items()))
        by_file[path.name] = by_name[pose.name] = (where, converted)
    if robot == "kaspar-3" and result.poses:
        notes.append("Kaspar 3 poses' speeds (robot.xml's share of play time) are not rates: "
                     "each step is timed at the joints' speed limits")
    for path in _folder(source, "seqs", "seq"):
        if path.suffix.lower() != ".seq":
            if path.suffix.lower() == ".skm":
                _keymap(path, result)
            else:
                notes.append(f"{path.parent.name}/{path.name}: not a .seq file: left out")
            continue
        try:
            sequence = read_sequence(path)
        except legacy.LegacyError as error:
            notes.append(f"{error}: not imported")
            continue
        _sequence(sequence, f"{path.parent.name}/{path.name}", by_file, by_name, servos, result)
    for path in _folder(source, "keyMaps", "keymaps"):
        _keymap(path, result)
    for path in _folder(source, "sounds"):
        _sound(path, result)
    return result


def _sequence(
    sequence: legacy.LegacySequence,
    file: str,
    by_file: Mapping[str, tuple[str, Converted | None]],
    by_name: Mapping[str, tuple[str, Converted | None]],
    servos: ServoSettings,
    result: Imported,
) -> None:
    where = f"sequence {sequence.name!r} ({file})"
    notes = result.not_carried
    steps: list[tuple[Converted, int]] = []
    for number, step in enumerate(sequence.steps, 1):
        found = (by_file.get(step.file) if step.file else None) or by_name.get(step.name)
        if found is None:
            notes.append(f"{where}: step {number} names pose {step.name!r} "
                         f"({step.file or 'no file'}), which is not among the poses: "
                         "not imported")
            return
        pose_where, converted = found
        if converted is None:
            notes.append(f"{where}: step {number} is {pose_where}, refused above: "
                         "not imported")
            return
        steps.append((converted, step.delay_ms))
    if not steps:
        notes.append(f"{where}: no steps: not imported")
        return
    keyframes, slowed = _timed(steps, servos)
    duration = keyframes[-1][0] if keyframes else 0.0
    if not keyframes:
        notes.append(f"{where}: no step moves a joint from rest: not imported")
        return
    if duration > MAX_DURATION_S:
        notes.append(f"{where}: lasts {duration:.1f} s, longer than a behaviour may "
                     f"({MAX_DURATION_S:g} s): not imported; split it into shorter sequences")
        return
    name = kasparctl_name(sequence.name, result.behaviours, "sequence")
    result.behaviours[name] = (where, keyframes)
    result.carried.append(f"{where} -> behaviour {name}: {len(sequence.steps)} steps, "
                          f"{duration:.2f} s")
    for number, published, needed in slowed:
        notes.append(f"{where}: step {number} takes {needed:.2f} s, not the published "
                     f"{published:.2f} s: the profile's speed limits (the behaviour is slowed, "
                     "never sped past them)")
    for sound in sequence.sounds:
        notes.append(f"{where}: sound {sound!r} not attached: a behaviour carries no sound; "
                     "it is in sounds/ (if SOURCE has it), for [voice.clips] to give a phrase")


def _timed(
    steps: list[tuple[Converted, int]], servos: ServoSettings
) -> tuple[list[tuple[float, dict[str, float]]], list[tuple[int, float, float]]]:
    """Keyframes (offsets from rest) reaching each step as published, then its delay."""
    joints = {j.name: j for j in servos.joints}
    virtual = servos.virtual

    def rest(name: str) -> float:
        if name in joints:
            return joints[name].rest_deg
        master, ratio = next(iter(virtual[name].items()))
        return joints[master].rest_deg / ratio

    def limit(name: str) -> float:
        if name in joints:
            return joints[name].max_speed_dps
        return min(joints[j].max_speed_dps / abs(r) for j, r in virtual[name].items())

    current: dict[str, float] = {}
    frames: dict[float, dict[str, float]] = {}
    slowed: list[tuple[int, float, float]] = []
    time = 0.0
    for number, (pose, delay_ms) in enumerate(steps, 1):
        published = needed = 0.0
        timed = False  # whether the published pose gives a speed (Kaspar-1c's do)
        for name, target in pose.degrees.items():
            distance = abs(target - current.get(name, rest(name)))
            speed = pose.speeds.get(name)
            timed = timed or speed is not None
            published = max(published, distance / (speed or limit(name)))
            needed = max(needed, MINIMUM_JERK_PEAK * distance / limit(name))
        took = max(published, needed)
        if timed and needed > published + 1e-3:
            slowed.append((number, published, needed))
        if took > 0:
            start = round(time, 3)
            if start > 0:
                hold = frames.setdefault(start, {})
                for name in pose.degrees:
                    hold[name] = round(current.get(name, rest(name)) - rest(name), 3)
            end = round(time + took + 1e-3, 3)  # ms steps, never shorter than needed
            reached = frames.setdefault(end, {})
            for name, value in pose.degrees.items():
                reached[name] = round(value - rest(name), 3)
                current[name] = value
            time = end
        time += delay_ms / 1000
    return sorted(frames.items()), slowed


def _keymap(path: Path, result: Imported) -> None:
    try:
        bindings, odd = legacy.read_keymap(path)
    except legacy.LegacyError as error:
        result.not_carried.append(f"{error}: not imported")
        return
    where = f"keymap {path.parent.name}/{path.name}"
    for line in odd:
        result.not_carried.append(f"{where}, {line}")
    for binding in bindings:
        pads = [k for k in binding.keys if k in legacy.KEYPAD_KEYS]
        touch = [k for k in binding.keys if k not in legacy.KEYPAD_KEYS]
        said = []
        if pads:
            said.append(f"keypad {' '.join(pads)}")
        if touch:
            said.append(f"touch sensor {' '.join(touch)}")
        result.not_carried.append(
            f"{where}, line {binding.line}: {binding.sequence!r} on {', '.join(said)}: not "
            "carried: kasparctl's keys are the game's commands ([keyfob]), and it reads no "
            "touch sensors; play it with `kasparctl behaviour play NAME`")


def _sound(path: Path, result: Imported) -> None:
    try:
        head = path.read_bytes()[:12]
    except OSError as error:
        result.not_carried.append(f"sounds/{path.name}: cannot be read: {error.strerror}")
        return
    if head[:4] != b"RIFF" or head[8:12] != b"WAVE":
        result.not_carried.append(f"sounds/{path.name}: not a WAV file: not carried (a clip "
                                  "is a WAV the player plays)")
        return
    result.sounds[path.name] = path
    result.carried.append(f"sounds/{path.name} -> sounds/{path.name} (a clip for "
                          "[voice.clips])")


def _toml_key(name: str) -> str:
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)


def poses_text(imported: Imported) -> str:
    """The poses file of the imported poses."""
    lines = [f"# Poses imported by `kasparctl import` from {imported.source} ({imported.robot}),",
             f"# in the degrees of {imported.profile}. A poses file: name it as poses_file.", ""]
    for name, (where, pose) in imported.poses.items():
        lines.append(f"# {where}")
        lines.append(f"[{name}]")
        lines += [f"{_toml_key(joint)} = {value!r}" for joint, value in pose.items()]
        lines.append("")
    return "\n".join(lines)


def behaviours_text(imported: Imported) -> str:
    """The behaviour file of the imported sequences (offsets from rest, as behaviours are)."""
    lines = [f"# Sequences imported by `kasparctl import` from {imported.source} "
             f"({imported.robot}), for {imported.profile}.",
             "# Offsets from the rest pose: played from rest, each goes through its poses.", ""]
    for name, (where, keyframes) in imported.behaviours.items():
        lines += [f"[{name}]", f"description = {json.dumps('from ' + where)}", "keyframes = ["]
        for time, pose in keyframes:
            joints = ", ".join(f"{_toml_key(j)} = {v!r}" for j, v in pose.items())
            lines.append(f"  {{ time = {time!r}, pose = {{ {joints} }} }},")
        lines += ["]", ""]
    return "\n".join(lines)


def report_text(imported: Imported, written: list[str]) -> str:
    """The import's report: what was written, carried over, and not carried over and why."""
    lines = [f"# Import of {imported.source} ({imported.robot}) for {imported.profile}", "",
             "Written: " + (", ".join(written) or "nothing"), "",
             "Use: `poses_file` names poses.toml (its happy, sad, listening and rest poses, if",
             "any, become the game's); `body.behaviours_dir` names behaviours/, which then",
             "replaces the shipped behaviours (an imported blink or idle is the body's own);",
             "`kasparctl behaviour play NAME` plays one; `[voice.clips]` gives a phrase key a",
             "WAV of sounds/.", "", "## Carried over", ""]
    lines += [f"- {line}" for line in imported.carried] or ["- nothing"]
    lines += ["", "## Not carried over, and why", ""]
    lines += [f"- {line}" for line in imported.not_carried] or ["- nothing"]
    return "\n".join(lines) + "\n"


def write_imported(imported: Imported, out: Path, config: Config) -> str:
    """Write the import into `out` (new or empty) and return the report; nothing is overwritten.

    The written files are read back and checked as the robot will read them: the poses
    against the profile, the behaviours as `behaviour check` does.
    """
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ImportFailed(f"{out}: already holds files: name a new or empty directory")
    storage.make_directory(out, parents=True, exist_ok=True)
    written: list[str] = []
    if imported.poses:
        path = out / "poses.toml"
        storage.write_atomic(path, poses_text(imported).encode("utf-8"))
        for name, pose in read_poses(path).items():
            check_pose(pose, name, config.servos, str(path))
        written.append(f"{path} ({len(imported.poses)} poses)")
    if imported.behaviours:
        folder = out / "behaviours"
        storage.make_directory(folder)
        path = folder / "imported.toml"
        text = behaviours_text(imported)
        found = problems(parse(text, str(path)), config.servos)
        if found:
            raise ImportFailed("the imported behaviours do not fit (a bug of the importer): "
                               + "; ".join(found))
        storage.write_atomic(path, text.encode("utf-8"))
        written.append(f"{path} ({len(imported.behaviours)} behaviours)")
    if imported.sounds:
        folder = out / "sounds"
        storage.make_directory(folder)
        for name, source in imported.sounds.items():
            storage.write_atomic(folder / name, source.read_bytes())
        written.append(f"{folder} ({len(imported.sounds)} WAV files)")
    report = report_text(imported, [*written, str(out / "report.md")])
    storage.write_atomic(out / "report.md", report.encode("utf-8"))
    return report

