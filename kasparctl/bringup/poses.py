"""Kaspar's poses, shown by hand and kept in the poses file the configuration names.

Its "happy" and "sad" poses are the game's expressions, "rest" the joints' rest
positions, and a pose named like a pilot location is where Kaspar points for it
(kasparctl.config). Recording turns torque off for the chosen joints only (the
rest hold); the engineer moves them into the pose and presses green or Enter
(red cancels). A pose outside any joint's safe range is refused, naming the
joint, and nothing is written.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from hal.clock import MonotonicClock
from hal.servos.sim import SimServos
from kasparctl.bringup.engineer import (
    BringUpError,
    Ending,
    Engineer,
    hold_others,
    open_servos,
    select_joints,
    start_servos,
    write_atomically,
)
from kasparctl.bringup.toml_patch import set_table
from kasparctl.config import (
    HAPPY_POSE,
    LISTENING_POSE,
    REST_POSE,
    SAD_POSE,
    Config,
    ConfigError,
    check_pose,
    load_config,
    read_poses,
)

POSES_HEADER = (
    "# Kaspar's poses, joint = degrees, recorded with `kasparctl pose record NAME`.\n"
    '# "happy" and "sad" are the game\'s expressions, "rest" the joints\' rest positions,\n'
    "# and a pose named like a pilot location is where Kaspar points for it.\n"
)


def poses_config(path: str) -> Config:
    """The configuration at `path`, which must name its poses file (BringUpError otherwise)."""
    config = load_config(path, poses=False)
    if config.poses_file is None:
        raise BringUpError(
            f"{path}: poses_file is not set; "
            'add poses_file = "poses.toml" (a path relative to the configuration)'
        )
    return config


def recorded(config: Config) -> dict[str, dict[str, float]]:
    """The poses in the poses file (none before the first is recorded)."""
    assert config.poses_file is not None
    return read_poses(config.poses_file) if Path(config.poses_file).exists() else {}


async def record(
    config: Config,
    name: str,
    joints: Sequence[str] | None,
    group: str | None,
    *,
    seconds: float | None,
    quiet: bool,
    hands: Sequence[tuple[str, float]],
    out: TextIO,
) -> dict[str, float] | None:
    """Limp the joints, let the engineer pose them, check and save the pose; None if cancelled.

    `hands`: on simulated servos, a hand puts each joint at its degrees (scripts, tests).
    """
    clock = MonotonicClock()
    servos = open_servos(config, clock)
    chosen = select_joints(servos, joints, group)
    settings = {j.name: j for j in config.servos.joints}
    blind = [joint for joint in chosen if settings[joint].servo.off_reading is not None]
    chosen = [joint for joint in chosen if joint not in blind]
    if not chosen:
        raise BringUpError(f"no joint with position feedback to pose (left out: {blind})")
    placed = _hands(hands, servos, chosen)
    engineer = Engineer(config, clock, seconds=seconds, quiet=quiet, out=out)
    await start_servos(servos)
    try:
        await engineer.start()
        left_limp = await hold_others(servos, chosen)
        for joint in chosen:
            await servos.set_compliant(joint, True)
        for joint, degrees in placed.items():
            assert isinstance(servos, SimServos)
            servos.push(joint, degrees)
        if blind:
            engineer.say(f"Without position feedback, not in the pose: {', '.join(blind)}.")
        if left_limp:
            engineer.say(f"Also limp, outside their safe range: {', '.join(left_limp)}.")
        what = group or ", ".join(joint.replace("_", " ") for joint in chosen)
        engineer.say(
            f"Recording pose {name.replace('_', ' ')}. Move the {what} into the pose, "
            "then press the green button, or Enter. The red button cancels."
        )

        async def check_faults() -> None:
            await servos.read_positions()  # a silent servo or a latched fault stops it here

        ending = await engineer.demonstrate(check_faults, 0.1)
        if ending is Ending.CANCELLED:
            engineer.say("Pose not saved.")
            return None
        positions = await servos.read_positions()
        pose = {joint: round(positions[joint], 1) for joint in chosen if joint in positions}
        assert config.poses_file is not None
        check_pose(pose, name, config.servos, config.poses_file)
        path = Path(config.poses_file)
        text = path.read_text(encoding="utf-8") if path.exists() else POSES_HEADER
        edited = set_table(text, name, pose)
        if path.exists():
            write_atomically(path, edited)
        else:
            path.write_text(edited, encoding="utf-8")
        # Hold the pose just recorded: it is inside every range, so nothing jumps.
        for joint in chosen:
            await servos.set_compliant(joint, False)
        engineer.say(f"Pose {name.replace('_', ' ')} saved.")
        return pose
    finally:
        await engineer.close()
        await servos.close()


def _hands(
    hands: Sequence[tuple[str, float]], servos: object, chosen: list[str]
) -> dict[str, float]:
    if not hands:
        return {}
    if not isinstance(servos, SimServos):
        raise BringUpError("--sim-hand moves simulated servos: servos.backend is 'real'")
    for joint, degrees in hands:
        if joint not in chosen:
            raise BringUpError(
                f"--sim-hand '{joint}={degrees:g}': {joint!r} is not a joint being posed"
            )
    return dict(hands)


async def play(
    config: Config, name: str, duration: float | None, speed: float | None
) -> dict[str, float]:
    """Turn the pose's joints on (holding), then move them to the pose at their limits."""
    poses = recorded(config)
    if name not in poses:
        raise BringUpError(
            f"no pose {name!r} in {config.poses_file} (poses: {', '.join(poses) or 'none yet'})"
        )
    pose = poses[name]
    assert config.poses_file is not None
    check_pose(pose, name, config.servos, config.poses_file)
    servos = open_servos(config, MonotonicClock())
    await start_servos(servos)
    try:
        for joint in pose:
            await servos.set_compliant(joint, False)
        await servos.move(pose, duration=duration, speed=speed)
        positions = await servos.read_positions()
        return {joint: positions[joint] for joint in pose if joint in positions}
    finally:
        await servos.close()


def listing(config: Config) -> list[dict[str, Any]]:
    """Every recorded pose: its role in the game, its joints, and what breaks a range (or None)."""
    assert config.poses_file is not None
    rows: list[dict[str, Any]] = []
    for name, pose in recorded(config).items():
        try:
            check_pose(pose, name, config.servos, config.poses_file)
            problem = None
        except ConfigError as error:
            problem = error.message
        rows.append({"pose": name, "role": role(name, config), "joints": pose, "problem": problem})
    return rows


def role(name: str, config: Config) -> str:
    """What the game uses a pose for ("-": nothing)."""
    if name == HAPPY_POSE:
        return "game: happy face"
    if name == SAD_POSE:
        return "game: sad face"
    if name == LISTENING_POSE:
        return "game: listening"
    if name == REST_POSE:
        return "rest positions"
    if name in config.game.locations:
        return "game: pilot location"
    return "-"
