"""The published Kaspar software's content files, read (pure): poses, sequences, keymaps, limits.

The formats, as the University of Hertfordshire's software (scheunemann/KASPAR) writes
them, one item a line, fields split by commas (Windows line ends and a Latin-1 file
read as well as UTF-8):

- Kaspar-1c pose (`pos/*.pose`): its name, the number of joints, then
  `JOINT,scaled,speed,false`: a position scaled 0-1000 from the servo's MIN to MAX in
  robot.xml, an AX-12A moving speed (0.111 rpm a unit; 0 is "as fast as it can").
- Kaspar 3 pose (`pos/*.pose`): its name, then `JOINT,degrees,speed`: the robot's own
  degrees ((raw - CENTER) * 0.352 on a HerkuleX, (us - CENTER) * 0.18 on an HS-82MG).
- Kaspar-1c sequence (`seqs/*.seq`): its name, the number of steps, then
  `display name,pose file,delay ms` (the delay after the pose is reached), and
  optionally a last line naming a .wav in `sounds/`.
- Kaspar 3 sequence (`seq/*.seq`): its name, then a pose name a line.
- Keymap (`keyMaps/*.skm`): `sequence,key[,key...]`; keys are keypad keys (0-9 + - *
  / . = ENTER BACKSPACE DEL, any case) or letters A-Z standing for touch sensors; a
  line of a name alone binds nothing.
- Kaspar-1c robot.xml: `SERVOLIST/SERVO` with `NAME` and `LIMITS type="pos"` MIN and
  MAX (MIN > MAX: a reversed joint, whose scale runs backwards).

Each reader returns what it found; LegacyError names the file, the line and what was
expected and found.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

from hal.errors import KasparError

KEYPAD_KEYS = frozenset(
    [*"0123456789", "+", "-", "*", "/", ".", "=", "ENTER", "BACKSPACE", "DEL"]
)


class LegacyError(KasparError):
    """A published-format file that cannot be read; names the file, the line and why."""


@dataclass(frozen=True)
class PoseLine:
    """One joint of a published pose: its published name, value and speed."""

    joint: str
    value: float
    speed: float


@dataclass(frozen=True)
class LegacyPose:
    """A published pose: its name, the file it came from and its joints."""

    name: str
    file: str
    joints: tuple[PoseLine, ...]


@dataclass(frozen=True)
class Step:
    """One step of a sequence: the pose it names (display name, file) and the delay after."""

    name: str
    file: str | None
    delay_ms: int


@dataclass(frozen=True)
class LegacySequence:
    """A published sequence: its steps and the sound it plays, if any."""

    name: str
    file: str
    steps: tuple[Step, ...]
    sounds: tuple[str, ...]


@dataclass(frozen=True)
class Binding:
    """One keymap line: a sequence and the keys that play it."""

    sequence: str
    keys: tuple[str, ...]
    line: int


def text_lines(path: Path) -> list[str]:
    """The file's lines, stripped (UTF-8, else Latin-1, as the published files were)."""
    try:
        data = path.read_bytes()
    except OSError as error:
        raise LegacyError(f"{path}: cannot be read: {error.strerror}") from error
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return [line.strip() for line in text.splitlines()]


def _number(path: Path, number: int, field: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise LegacyError(f"{path}, line {number}: {field}: expected a number, "
                          f"found {text!r}") from None


def read_pose_1c(path: Path) -> LegacyPose:
    """A Kaspar-1c pose: name, count, then JOINT,scaled,speed,false lines."""
    lines = text_lines(path)
    if len(lines) < 2 or not lines[0]:
        raise LegacyError(f"{path}, line 1: expected the pose's name, then the number of "
                          "joints, found too few lines")
    count = _number(path, 2, "the number of joints", lines[1])
    joints = []
    for number, line in enumerate(lines[2:], 3):
        if not line:
            continue
        fields = [f.strip() for f in line.split(",")]
        if len(fields) != 4:
            raise LegacyError(f"{path}, line {number}: expected JOINT,scaled,speed,false, "
                              f"found {line!r}")
        joints.append(PoseLine(fields[0], _number(path, number, "scaled", fields[1]),
                               _number(path, number, "speed", fields[2])))
    if len(joints) != count:
        raise LegacyError(f"{path}, line 2: expected {count:g} joints as it says, found "
                          f"{len(joints)}")
    return LegacyPose(lines[0], path.name, tuple(joints))


def read_pose_3(path: Path) -> LegacyPose:
    """A Kaspar 3 pose: name, then JOINT,degrees,speed lines."""
    lines = text_lines(path)
    if not lines or not lines[0]:
        raise LegacyError(f"{path}, line 1: expected the pose's name, found nothing")
    joints = []
    for number, line in enumerate(lines[1:], 2):
        if not line:
            continue
        fields = [f.strip() for f in line.split(",")]
        if len(fields) != 3:
            raise LegacyError(f"{path}, line {number}: expected JOINT,degrees,speed, "
                              f"found {line!r}")
        joints.append(PoseLine(fields[0], _number(path, number, "degrees", fields[1]),
                               _number(path, number, "speed", fields[2])))
    return LegacyPose(lines[0], path.name, tuple(joints))


def read_sequence_1c(path: Path) -> LegacySequence:
    """A Kaspar-1c sequence: name, count, display,file,delay lines, a .wav line or more."""
    lines = [line for line in text_lines(path)]
    if len(lines) < 2:
        raise LegacyError(f"{path}, line 1: expected the sequence's name, then the number "
                          "of steps, found too few lines")
    count = _number(path, 2, "the number of steps", lines[1])
    steps: list[Step] = []
    sounds: list[str] = []
    for number, line in enumerate(lines[2:], 3):
        if not line:
            continue
        fields = [f.strip() for f in line.split(",")]
        if len(fields) == 1 and fields[0].lower().endswith(".wav"):
            sounds.append(fields[0])
        elif len(fields) == 3:
            delay = _number(path, number, "delay ms", fields[2])
            if delay < 0:
                raise LegacyError(f"{path}, line {number}: delay ms: expected 0 or more, "
                                  f"found {fields[2]}")
            steps.append(Step(fields[0], fields[1], int(delay)))
        else:
            raise LegacyError(f"{path}, line {number}: expected display name,pose file,"
                              f"delay ms or a .wav, found {line!r}")
    if len(steps) != count:
        raise LegacyError(f"{path}, line 2: expected {count:g} steps as it says, found "
                          f"{len(steps)}")
    return LegacySequence(lines[0] or path.stem, path.name, tuple(steps), tuple(sounds))


def read_sequence_3(path: Path) -> LegacySequence:
    """A Kaspar 3 sequence: name, then a pose name a line."""
    lines = [line for line in text_lines(path) if line]
    if not lines:
        raise LegacyError(f"{path}, line 1: expected the sequence's name, found nothing")
    return LegacySequence(lines[0], path.name, tuple(Step(n, None, 0) for n in lines[1:]), ())


def read_keymap(path: Path) -> tuple[list[Binding], list[str]]:
    """A keymap's bindings, and its lines that bind nothing or name an unknown key."""
    bindings: list[Binding] = []
    odd: list[str] = []
    for number, line in enumerate(text_lines(path), 1):
        if not line:
            continue
        fields = [f.strip() for f in line.split(",")]
        keys = tuple(k.upper() for k in fields[1:] if k)
        if not keys:
            odd.append(f"line {number}: {fields[0]!r} is bound to no key")
            continue
        unknown = [k for k in keys if k not in KEYPAD_KEYS and not re.fullmatch(r"[A-Z]", k)]
        if unknown:
            odd.append(f"line {number}: {fields[0]!r}: {', '.join(unknown)} is not a keypad "
                       "key (0-9 + - * / . = ENTER BACKSPACE DEL) or a touch sensor's letter")
            keys = tuple(k for k in keys if k not in unknown)
        if keys:
            bindings.append(Binding(fields[0], keys, number))
    return bindings, odd


def read_limits_1c(path: Path) -> dict[str, tuple[int, int]]:
    """Kaspar-1c robot.xml: servo NAME -> (MIN, MAX) raw, as written (MIN > MAX: reversed)."""
    try:
        root = ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError) as error:
        raise LegacyError(f"{path}: cannot be read as XML: {error}") from error
    limits: dict[str, tuple[int, int]] = {}
    for servo in root.iter("SERVO"):
        name = servo.findtext("NAME")
        low = servo.findtext("LIMITS[@type='pos']/MIN")
        high = servo.findtext("LIMITS[@type='pos']/MAX")
        if name is None or low is None or high is None:
            raise LegacyError(f"{path}: SERVO id={servo.get('id')}: expected NAME and LIMITS "
                              "type='pos' MIN and MAX")
        try:
            limits[name.strip()] = (int(low), int(high))
        except ValueError:
            raise LegacyError(f"{path}: SERVO {name}: LIMITS: expected whole numbers, found "
                              f"{low!r} and {high!r}") from None
    if not limits:
        raise LegacyError(f"{path}: expected SERVOLIST/SERVO entries, found none")
    return limits
