"""Behaviours as data: keyframed TOML files, strictly read, mirrored, sampled with minimum jerk.

A file holds a family of behaviours, one table each (docs/body.md):

    [nod]
    description = "yes: the head dips twice"
    keyframes = [
      { time = 0.25, pose = { head_pitch = 10.0 } },
      { time = 0.55, pose = { head_pitch = 0.0 } },
    ]

    [nod_left]
    like = "nod"        # the keyframes of another behaviour of the file ...
    mirror = true       # ... played as their mirror image

Each keyframe is a partial pose: degrees *added to* where each joint was when the
behaviour began (relative offsets, so a nod works wherever Kaspar looks), reached
at `time` seconds from the start. A joint moves from its previous keyframe naming
it (or from 0 at time 0) along a minimum-jerk curve, and holds its last offset to
the end. `strength` (0 to 1) scales every offset.

A behaviour may name a robot's virtual joints (eyes_yaw, eyes_pitch, eyelids:
`[[servos.virtual_joints]]`): `in_real_joints` plays each as the real joints it
drives, its offsets times their ratios (exact, since a virtual joint is linear).

Mirroring (`mirror = true`): left_* and right_* joints swap, and the yaw and roll
of the midline (head_yaw, head_roll, torso_yaw, ...) and of the eyes (*eye_yaw)
change sign, since those angles are measured in one frame for the whole robot. A
limb's own angles are not negated: the configuration mirrors each arm already
(the same range on either side, positive roll lifting either arm away from the body).
"""

from __future__ import annotations

import bisect
import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import msgspec

from hal.errors import KasparError
from hal.servos.settings import ServoSettings

# A behaviour longer than this is a mistake in its file (a time in ms, not s).
MAX_DURATION_S = 60.0
NAME = re.compile(r"^[a-z][a-z0-9_]*$")


class BehaviourError(KasparError):
    """A behaviour file that cannot be used; the message names the file, the behaviour,
    the keyframe and the key, with what was expected and what was found."""


class _Keyframe(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    time: float
    pose: dict[str, float]


class _Spec(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    description: str = ""
    mirror: bool = False
    like: str | None = None
    keyframes: tuple[_Keyframe, ...] = ()


def minimum_jerk(fraction: float) -> float:
    """Position along a minimum-jerk move (0 to 1) at `fraction` of its time: the smooth,
    bell-shaped speed of a human reach (Flash and Hogan 1985); peak speed 1.875 x mean."""
    if fraction <= 0.0:
        return 0.0
    if fraction >= 1.0:
        return 1.0
    f3 = fraction * fraction * fraction
    return f3 * (10.0 - 15.0 * fraction + 6.0 * fraction * fraction)


# The steepest slope of minimum_jerk relative to a constant-speed move.
MINIMUM_JERK_PEAK = 1.875


def mirror_joint(name: str) -> tuple[str, float]:
    """The joint a mirrored behaviour moves instead of `name`, and the sign of its offsets."""
    swapped = name
    if name.startswith("left_"):
        swapped = "right_" + name.removeprefix("left_")
    elif name.startswith("right_"):
        swapped = "left_" + name.removeprefix("right_")
    midline = swapped == name
    turns = name.endswith(("_yaw", "_roll"))
    negate = turns and (midline or name.endswith("eye_yaw"))
    return swapped, -1.0 if negate else 1.0


@dataclass(frozen=True)
class Behaviour:
    """One behaviour, ready to play: keyframes (already mirrored) and a track per joint."""

    name: str
    source: str  # the file it came from
    description: str
    keyframes: tuple[tuple[float, Mapping[str, float]], ...]
    _tracks: dict[str, tuple[list[float], list[float]]] = field(
        init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        """Build each joint's track: (times, offsets), from (0, 0)."""
        tracks: dict[str, tuple[list[float], list[float]]] = {}
        for time, pose in self.keyframes:
            for joint, offset in pose.items():
                times, values = tracks.setdefault(joint, ([0.0], [0.0]))
                times.append(time)
                values.append(offset)
        object.__setattr__(self, "_tracks", tracks)

    @property
    def duration(self) -> float:
        """Seconds from the start to the last keyframe."""
        return self.keyframes[-1][0] if self.keyframes else 0.0

    @property
    def joints(self) -> tuple[str, ...]:
        """Every joint the behaviour moves, in the order its keyframes name them."""
        return tuple(self._tracks)

    def offsets(self, elapsed: float, strength: float = 1.0) -> dict[str, float]:
        """Each joint's offset (degrees) at `elapsed` seconds, scaled by `strength` (0 to 1)."""
        scale = min(1.0, max(0.0, strength))
        result = {}
        for joint, (times, values) in self._tracks.items():
            index = bisect.bisect_right(times, elapsed)
            if index >= len(times):
                value = values[-1]
            else:
                t0, t1 = times[index - 1], times[index]
                v0, v1 = values[index - 1], values[index]
                value = v0 + (v1 - v0) * minimum_jerk((elapsed - t0) / (t1 - t0))
            result[joint] = value * scale
        return result

    def segments(self) -> Iterable[tuple[int, str, float, float, float, float]]:
        """(keyframe number from 1, joint, t0, offset0, t1, offset1) of every joint's move."""
        for joint, (times, values) in self._tracks.items():
            for index in range(1, len(times)):
                number = 1 + [t for t, _ in self.keyframes].index(times[index])
                yield number, joint, times[index - 1], values[index - 1], times[index], values[
                    index
                ]


def in_real_joints(behaviour: Behaviour, servos: ServoSettings) -> Behaviour:
    """`behaviour` with each virtual joint of `servos` replaced by the real joints it drives.

    Names that are neither stay (a joint the robot lacks is skipped when played).
    BehaviourError names the keyframe that sets a real joint twice (by its name and
    through a virtual joint).
    """
    virtual = servos.virtual
    if not virtual or not any(name in virtual for _, pose in behaviour.keyframes
                              for name in pose):
        return behaviour
    frames: list[tuple[float, Mapping[str, float]]] = []
    for number, (time, pose) in enumerate(behaviour.keyframes, 1):
        real: dict[str, float] = {}
        via: dict[str, str] = {}
        for name, offset in pose.items():
            for joint, ratio in virtual.get(name, {name: 1.0}).items():
                if joint in real:
                    raise BehaviourError(
                        f"{behaviour.source}: behaviour {behaviour.name!r}, keyframe {number}: "
                        f"joint {joint} is set twice, by {via[joint]} and by {name}"
                    )
                real[joint] = ratio * offset
                via[joint] = name
        frames.append((time, real))
    return Behaviour(behaviour.name, behaviour.source, behaviour.description, tuple(frames))


def shipped_dir() -> Path:
    """The behaviour files shipped with kasparctl (phrases/behaviours/)."""
    return Path(str(resources.files("phrases"))) / "behaviours"


def load_library(directory: str | Path | None = None) -> dict[str, Behaviour]:
    """Every behaviour of every *.toml file in `directory` (the shipped ones if None).

    BehaviourError names the file and what is wrong, including a behaviour name
    used in two files.
    """
    folder = Path(directory) if directory is not None else shipped_dir()
    files = sorted(folder.glob("*.toml"))
    if not files:
        raise BehaviourError(f"{folder}: no behaviour files (*.toml)")
    library: dict[str, Behaviour] = {}
    for path in files:
        for name, behaviour in read_file(path).items():
            if name in library:
                raise BehaviourError(
                    f"{path}: behaviour {name!r} is also in {library[name].source}: keep one"
                )
            library[name] = behaviour
    return library


def read_file(path: Path) -> dict[str, Behaviour]:
    """The behaviours of one file; BehaviourError names what is wrong and where."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise BehaviourError(f"{path}: cannot be read: {error}") from error
    return parse(text, str(path))


def parse(text: str, source: str) -> dict[str, Behaviour]:
    """The behaviours of a file's text; `source` names it in every error."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise BehaviourError(f"{source}: not valid TOML: {error}") from error
    specs: dict[str, _Spec] = {}
    for name, table in raw.items():
        where = f"{source}: behaviour {name!r}"
        if not NAME.match(name):
            raise BehaviourError(
                f"{where}: expected a name of lower-case letters, digits and _, found {name!r}"
            )
        if not isinstance(table, dict):
            raise BehaviourError(f"{where}: expected a table, found {_found(table)}")
        try:
            specs[name] = msgspec.convert(table, _Spec)
        except msgspec.ValidationError as error:
            raise BehaviourError(f"{where}, {_explain(str(error), table)}") from None
    behaviours = {}
    for name, spec in specs.items():
        behaviours[name] = _compile(name, spec, specs, source)
    return behaviours


def _compile(name: str, spec: _Spec, specs: Mapping[str, _Spec], source: str) -> Behaviour:
    where = f"{source}: behaviour {name!r}"
    keyframes = spec.keyframes
    if spec.like is not None:
        if keyframes:
            raise BehaviourError(f"{where}: key like: expected like or keyframes, found both")
        other = specs.get(spec.like)
        if other is None or other.like is not None:
            known = ", ".join(n for n, s in specs.items() if s.like is None and n != name)
            raise BehaviourError(
                f"{where}: key like: expected a behaviour of this file with keyframes "
                f"({known or 'none'}), found {spec.like!r}"
            )
        keyframes = other.keyframes
    if not keyframes:
        raise BehaviourError(f"{where}: key keyframes: expected at least 1 keyframe, found none")
    previous = 0.0
    frames: list[tuple[float, Mapping[str, float]]] = []
    for index, keyframe in enumerate(keyframes, 1):
        at = f"{where}, keyframe {index}"
        if not (math.isfinite(keyframe.time) and keyframe.time > previous):
            raise BehaviourError(
                f"{at}, key time: expected a time after {previous:g} s (the keyframes in "
                f"order), found {keyframe.time}"
            )
        if keyframe.time > MAX_DURATION_S:
            raise BehaviourError(
                f"{at}, key time: expected at most {MAX_DURATION_S:g} s, found {keyframe.time}"
            )
        if not keyframe.pose:
            raise BehaviourError(f"{at}, key pose: expected at least one joint, found none")
        for joint, degrees in keyframe.pose.items():
            if not math.isfinite(degrees) or abs(degrees) > 360.0:
                raise BehaviourError(
                    f"{at}, key pose.{joint}: expected degrees from -360 to 360, found {degrees}"
                )
        pose = dict(keyframe.pose)
        if spec.mirror:
            pose = {}
            for joint, degrees in keyframe.pose.items():
                mirrored, sign = mirror_joint(joint)
                pose[mirrored] = sign * degrees
        frames.append((keyframe.time, pose))
        previous = keyframe.time
    return Behaviour(name, source, spec.description, tuple(frames))


_UNKNOWN = re.compile(r"Object contains unknown field `(?P<key>[^`]+)`(?: - at `(?P<at>[^`]+)`)?")
_MISSING = re.compile(r"Object missing required field `(?P<key>[^`]+)`(?: - at `(?P<at>[^`]+)`)?")
_TYPE = re.compile(
    r"Expected `(?P<expected>[^`]+)`, got `(?P<got>[^`]+)`(?: - at `(?P<at>[^`]+)`)?"
)
_WORDS = {
    "float": "a number", "int": "a whole number", "str": "text", "bool": "true or false",
    "object": "a table", "array": "a list", "null": "nothing",
}


def _explain(message: str, table: Any) -> str:
    """msgspec's error as "keyframe N, key K: expected E, found F"."""
    for pattern, kind in ((_UNKNOWN, "unknown"), (_MISSING, "missing"), (_TYPE, "type")):
        match = pattern.match(message)
        if match is None:
            continue
        path = match.group("at") or "$"
        segments = re.findall(r"\.([^.\[]+)|\[(\d+|\.\.\.)\]", path.removeprefix("$"))
        words, value = [], table
        for key, index in segments:
            if index == "..." and isinstance(value, dict):
                # msgspec does not name a table's key: the first value not a number is it.
                key = next((k for k, v in value.items()
                            if isinstance(v, bool) or not isinstance(v, int | float)), "?")
                value = value.get(key)
                words.append(key)
            elif index:
                position = int(index)
                value = value[position] if isinstance(value, list) else None
                words.append(f"keyframe {position + 1}" if not words or words == ["keyframes"]
                             else f"[{position}]")
            else:
                value = value.get(key) if isinstance(value, dict) else None
                words.append(key)
        if words[:1] == ["keyframes"] and len(words) > 1:
            words = words[1:]
        place = [w for w in words if w.startswith("keyframe ")]
        keys = [w for w in words if not w.startswith("keyframe ")]
        if kind == "unknown":
            keys.append(match.group("key"))
            found = _found(value.get(match.group("key")) if isinstance(value, dict) else None)
            expected = "one of time, pose" if place else (
                "one of description, mirror, like, keyframes"
            )
            detail = f"expected {expected}, found an unknown key ({found})"
        elif kind == "missing":
            keys.append(match.group("key"))
            detail = "expected it, found nothing (a required key)"
        else:
            expected = _WORDS.get(match.group("expected"), match.group("expected"))
            detail = f"expected {expected}, found {_found(value)}"
        key = ".".join(keys) or "(table)"
        return ", ".join([*place, f"key {key}: {detail}"])
    return message


def _found(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    return str(value)
