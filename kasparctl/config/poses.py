"""The poses file: poses recorded by demonstration (`kasparctl pose record`), read and checked.

`[name]` tables of joint = degrees beside kaspar.toml (its `poses_file`). Its
"happy", "sad" and "listening" poses are the game's expressions, a pose named
like a pilot location is where Kaspar points for it, and "rest" gives the
joints' rest positions. Only poses_file reaches here; check_pose is also the
rule every pose written inline in kaspar.toml is held to.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import msgspec

from hal.errors import SettingsError
from hal.servos.settings import ServoSettings
from kasparctl.config.errors import ConfigError, read_toml
from kasparctl.config.schema import Config

# The poses the game takes from the poses file, besides the pilot's locations.
REST_POSE = "rest"
HAPPY_POSE = "happy"
SAD_POSE = "sad"
LISTENING_POSE = "listening"


def read_poses(path: str | Path) -> dict[str, dict[str, float]]:
    """The poses of a poses file: `[name]` tables of joint = degrees.

    ConfigError names the file, and the pose and joint at fault, for a file that
    cannot be read or parsed and for a value that is not a finite number.
    """
    source = str(path)
    raw = read_toml(path)
    poses: dict[str, dict[str, float]] = {}
    for name, table in raw.items():
        if not isinstance(table, dict):
            found = type(table).__name__
            raise ConfigError(source, name, f"expected a [{name}] table of joint = degrees, "
                              f"found a {found}")
        pose = {}
        for joint, degrees in table.items():
            if isinstance(degrees, bool) or not isinstance(degrees, int | float) or not (
                math.isfinite(degrees)
            ):
                raise ConfigError(source, f"{name}.{joint}",
                                  f"expected a finite number of degrees, found {degrees!r}")
            pose[joint] = float(degrees)
        poses[name] = pose
    return poses


def check_pose(
    pose: dict[str, float], name: str, servos: ServoSettings, source: str
) -> None:
    """Refuse a pose with an unknown joint or one outside its safe range, naming both.

    A pose may name virtual joints (eyes_yaw); it is checked as the real joints'
    goals it makes, with each coupled joint (a lid) where its leader puts it.
    """
    joints = {joint.name: joint for joint in servos.joints}
    virtual = servos.virtual
    for joint_name in pose:
        if joint_name not in joints and joint_name not in virtual:
            known = ", ".join([*joints, *virtual]) or "none configured"
            raise ConfigError(source, f"{name}.{joint_name}",
                              f"not a configured joint (joints: {known})")
    try:
        goals = servos.realise(pose)
    except SettingsError as error:
        raise ConfigError(source, name, str(error)) from None
    for joint_name, degrees in goals.items():
        joint = joints[joint_name]
        low, high = joint.range_deg
        if not low - 1e-9 <= degrees <= high + 1e-9:
            movers = [joint_name] if joint_name in pose else _through(joint_name, pose, servos)
            via = "" if joint_name in pose else f" (through {', '.join(movers)})"
            raise ConfigError(
                source, f"{name}.{movers[0]}",
                f"pose {name!r} puts joint {joint_name!r}{via} at {degrees} deg, outside its "
                f"safe range [{low}, {high}]",
            )


def _through(joint: str, pose: dict[str, float], servos: ServoSettings) -> list[str]:
    """The names of `pose` that move `joint`: virtual joints driving it, leaders it follows."""
    names = [v for v, drives in servos.virtual.items() if v in pose and joint in drives]
    names += [c.follows for c in servos.couplings if c.joint == joint and c.follows in pose]
    names += [v for v, drives in servos.virtual.items() if v in pose
              and any(c.joint == joint and c.follows in drives for c in servos.couplings)]
    names += [n for n in pose if any(c.joint == joint for c in servos.couplings)]
    return list(dict.fromkeys(names))


def apply_poses_file(config: Config, config_source: str) -> Config:
    """The configuration with the poses file's poses in the game and the joints' rest.

    Every pose is checked against the joints' ranges. "happy", "sad" and "listening"
    become game.happy_pose, game.sad_pose and game.listening_pose, a pose named like a
    pilot location game.poses[location], and "rest" the rest_deg of the joints it names. A pose
    also written inline in [game] is refused, as is a pilot whose locations are
    only partly posed. Errors name the poses file, the pose and the joint.
    """
    assert config.poses_file is not None
    source = config.poses_file
    poses = read_poses(source)
    for name, pose in poses.items():
        check_pose(pose, name, config.servos, source)
    game = config.game
    changes: dict[str, Any] = {}
    named = ((HAPPY_POSE, "happy_pose"), (SAD_POSE, "sad_pose"), (LISTENING_POSE, "listening_pose"))
    for name, field in named:
        if name in poses:
            if getattr(game, field):
                raise ConfigError(config_source, f"game.{field}",
                                  f"also given as pose {name!r} in {source}: keep one")
            changes[field] = poses[name]
    located = {location: poses[location] for location in game.locations if location in poses}
    if located:
        if game.poses:
            raise ConfigError(config_source, "game.poses",
                              f"also given as poses in {source}: keep one")
        missing = [location for location in game.locations if location not in located]
        if missing:
            raise ConfigError(source, "(poses)",
                              f"no pose for pilot location {', '.join(map(repr, missing))}: "
                              "record one per location, or none")
        changes["poses"] = located
    servos = config.servos
    if REST_POSE in poses:
        rest = poses[REST_POSE]
        servos = msgspec.structs.replace(servos, joints=tuple(
            msgspec.structs.replace(j, rest_deg=rest[j.name]) if j.name in rest else j
            for j in servos.joints
        ))
    return msgspec.structs.replace(
        config, game=msgspec.structs.replace(game, **changes), servos=servos
    )
