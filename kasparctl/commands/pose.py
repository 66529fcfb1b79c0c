"""`kasparctl pose record/play/list`: Kaspar's poses, shown by hand and kept in a poses file.

The poses file is the one kaspar.toml names (`poses_file`). Its "happy" and "sad"
poses are the game's expressions, "rest" the joints' rest positions, and a pose
named like a pilot location is where Kaspar points for it (kasparctl.config).
Recording turns torque off for the group only (the rest hold); the engineer moves
it into the pose and presses green or Enter (red cancels). A pose outside any
joint's safe range is refused, naming the joint, and nothing is written.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from pathlib import Path
from typing import Any, TextIO

from hal.clock import MonotonicClock
from hal.errors import HalError
from hal.servos.sim import SimServos
from kasparctl.commands.arguments import number
from kasparctl.commands.bringup import (
    BringUpError,
    Ending,
    Engineer,
    hold_others,
    open_servos,
    select_joints,
    start_servos,
    write_atomically,
)
from kasparctl.commands.toml_patch import BARE_KEY, TomlPatchError, set_table
from kasparctl.config import (
    HAPPY_POSE,
    LISTENING_POSE,
    REST_POSE,
    SAD_POSE,
    Config,
    ConfigError,
    check_pose,
    default_config_path,
    load_config,
    read_poses,
)
from kasparctl.log import configure_logging

POSES_HEADER = (
    "# Kaspar's poses, joint = degrees, recorded with `kasparctl pose record NAME`.\n"
    '# "happy" and "sad" are the game\'s expressions, "rest" the joints\' rest positions,\n'
    "# and a pose named like a pilot location is where Kaspar points for it.\n"
)


def register(subparsers: Any) -> None:
    """Add the `pose` command with its record, play and list actions."""
    parser = subparsers.add_parser("pose", help="record, play and list Kaspar's poses")
    actions = parser.add_subparsers(dest="pose_command", metavar="ACTION", required=True)

    def common(action: argparse.ArgumentParser) -> None:
        action.add_argument(
            "--config", default=None,
            help="kaspar.toml naming the poses file (default: $KASPAR_CONFIG or /etc/kaspar)",
        )
        action.add_argument("--json", action="store_true", help="print the result as JSON")

    record = actions.add_parser("record", help="move joints by hand into a pose and save it")
    record.add_argument(
        "name", type=_pose_name, help="the pose: happy, sad, rest, a pilot location, ..."
    )
    common(record)
    which = record.add_mutually_exclusive_group()
    which.add_argument("--group", help="the group to pose (default: every joint)")
    which.add_argument("--joints", type=lambda t: [n for n in t.split(",") if n],
                       help="joints to pose, e.g. smile,mouth_open")
    record.add_argument("--seconds", type=number(0, 3600, low_open=True, unit="s"), default=None,
                        help="save after N seconds instead of waiting for a press (scripts)")
    record.add_argument("--quiet", action="store_true", help="print the prompts, do not speak")
    record.add_argument(
        "--sim-hand", action="append", default=[], metavar="JOINT=DEG",
        help="simulated servos only: a hand puts JOINT at DEG degrees (repeatable)",
    )
    record.set_defaults(run=run_record)

    play = actions.add_parser("play", help="move to a recorded pose, within every limit")
    play.add_argument("name")
    common(play)
    play.add_argument("--speed", type=number(0, 720, low_open=True, unit="deg/s"), default=None,
                      help="deg/s, at most each limit")
    play.add_argument("--duration", type=number(0, 600, unit="s"), default=None,
                      help="seconds, at least")
    play.set_defaults(run=run_play)

    listing = actions.add_parser("list", help="the recorded poses and what the game uses them for")
    common(listing)
    listing.set_defaults(run=run_list)


def _pose_name(text: str) -> str:
    """A pose's name is a TOML key of the poses file: a usage error otherwise (exit 2)."""
    if not BARE_KEY.match(text):
        raise argparse.ArgumentTypeError(f"expected letters, digits, _ and -, found {text!r}")
    return text


def _config(arguments: argparse.Namespace) -> Config:
    config = load_config(arguments.config or default_config_path(), poses=False)
    if config.poses_file is None:
        raise BringUpError(
            f"{arguments.config or default_config_path()}: poses_file is not set; "
            'add poses_file = "poses.toml" (a path relative to the configuration)'
        )
    return config


def _poses(config: Config) -> dict[str, dict[str, float]]:
    assert config.poses_file is not None
    return read_poses(config.poses_file) if Path(config.poses_file).exists() else {}


def _fail(error: Exception) -> int:
    print(f"error: {error}", file=sys.stderr)
    return 1


# --- record -----------------------------------------------------------------------------


def run_record(arguments: argparse.Namespace) -> int:
    """Record one pose; exit 0 when saved, 1 when cancelled or refused."""
    configure_logging("warning", "console", stream=sys.stderr)
    out = sys.stderr if arguments.json else sys.stdout
    try:
        config = _config(arguments)
        saved = asyncio.run(record(config, arguments, out))
    except (ConfigError, BringUpError, HalError, TomlPatchError) as error:
        return _fail(error)
    if arguments.json:
        print(json.dumps({"pose": arguments.name, "saved": saved is not None, "joints": saved}))
    elif saved is None:
        print("cancelled: nothing saved", file=out)
    else:
        print(f"pose {arguments.name!r} saved in {config.poses_file}: "
              + ", ".join(f"{k} {v:.1f}" for k, v in saved.items()), file=out)
    return 0 if saved is not None else 1


async def record(
    config: Config, arguments: argparse.Namespace, out: TextIO
) -> dict[str, float] | None:
    """Limp the group, let the engineer pose it, check and save it; None when cancelled."""
    clock = MonotonicClock()
    servos = open_servos(config, clock)
    chosen = select_joints(servos, arguments.joints, arguments.group)
    settings = {j.name: j for j in config.servos.joints}
    blind = [name for name in chosen if settings[name].servo.off_reading is not None]
    chosen = [name for name in chosen if name not in blind]
    if not chosen:
        raise BringUpError(f"no joint with position feedback to pose (left out: {blind})")
    hands = _hands(arguments.sim_hand, servos, chosen)
    engineer = Engineer(config, clock, seconds=arguments.seconds, quiet=arguments.quiet, out=out)
    await start_servos(servos)
    try:
        await engineer.start()
        left_limp = await hold_others(servos, chosen)
        for name in chosen:
            await servos.set_compliant(name, True)
        for name, degrees in hands.items():
            assert isinstance(servos, SimServos)
            servos.push(name, degrees)
        if blind:
            engineer.say(f"Without position feedback, not in the pose: {', '.join(blind)}.")
        if left_limp:
            engineer.say(f"Also limp, outside their safe range: {', '.join(left_limp)}.")
        what = arguments.group or ", ".join(n.replace("_", " ") for n in chosen)
        engineer.say(
            f"Recording pose {arguments.name.replace('_', ' ')}. Move the {what} into the pose, "
            "then press the green button, or Enter. The red button cancels."
        )

        async def check_faults() -> None:
            await servos.read_positions()  # a silent servo or a latched fault stops it here

        ending = await engineer.demonstrate(check_faults, 0.1)
        if ending is Ending.CANCELLED:
            engineer.say("Pose not saved.")
            return None
        positions = await servos.read_positions()
        pose = {name: round(positions[name], 1) for name in chosen if name in positions}
        assert config.poses_file is not None
        check_pose(pose, arguments.name, config.servos, config.poses_file)
        path = Path(config.poses_file)
        text = path.read_text(encoding="utf-8") if path.exists() else POSES_HEADER
        edited = set_table(text, arguments.name, pose)
        if path.exists():
            write_atomically(path, edited)
        else:
            path.write_text(edited, encoding="utf-8")
        # Hold the pose just recorded: it is inside every range, so nothing jumps.
        for name in chosen:
            await servos.set_compliant(name, False)
        engineer.say(f"Pose {arguments.name.replace('_', ' ')} saved.")
        return pose
    finally:
        await engineer.close()
        await servos.close()


def _hands(texts: list[str], servos: object, chosen: list[str]) -> dict[str, float]:
    if not texts:
        return {}
    if not isinstance(servos, SimServos):
        raise BringUpError("--sim-hand moves simulated servos: servos.backend is 'real'")
    hands = {}
    for text in texts:
        name, _, degrees = text.partition("=")
        if name not in chosen:
            raise BringUpError(f"--sim-hand {text!r}: {name!r} is not a joint being posed")
        try:
            hands[name] = float(degrees)
        except ValueError:
            raise BringUpError(f"--sim-hand {text!r}: expected JOINT=DEGREES") from None
    return hands


# --- play -------------------------------------------------------------------------------


def run_play(arguments: argparse.Namespace) -> int:
    """Move to a recorded pose within every limit; exit 1 if it cannot be played."""
    configure_logging("warning", "console", stream=sys.stderr)
    try:
        config = _config(arguments)
        reached = asyncio.run(play(config, arguments))
    except (ConfigError, BringUpError, HalError) as error:
        return _fail(error)
    if arguments.json:
        print(json.dumps({"pose": arguments.name, "reached": reached}))
    else:
        print(f"pose {arguments.name!r}: " + ", ".join(f"{k} {v:.1f}" for k, v in reached.items()))
    return 0


async def play(config: Config, arguments: argparse.Namespace) -> dict[str, float]:
    """Turn the pose's joints on (holding), then move them to the pose at their limits."""
    poses = _poses(config)
    if arguments.name not in poses:
        raise BringUpError(
            f"no pose {arguments.name!r} in {config.poses_file} "
            f"(poses: {', '.join(poses) or 'none yet'})"
        )
    pose = poses[arguments.name]
    assert config.poses_file is not None
    check_pose(pose, arguments.name, config.servos, config.poses_file)
    servos = open_servos(config, MonotonicClock())
    await start_servos(servos)
    try:
        for name in pose:
            await servos.set_compliant(name, False)
        await servos.move(pose, duration=arguments.duration, speed=arguments.speed)
        positions = await servos.read_positions()
        return {name: positions[name] for name in pose if name in positions}
    finally:
        await servos.close()


# --- list -------------------------------------------------------------------------------


def run_list(arguments: argparse.Namespace) -> int:
    """Print every recorded pose, its role in the game and whether it fits the ranges."""
    try:
        config = _config(arguments)
        poses = _poses(config)
    except (ConfigError, BringUpError) as error:
        return _fail(error)
    rows: list[dict[str, Any]] = []
    for name, pose in poses.items():
        assert config.poses_file is not None
        try:
            check_pose(pose, name, config.servos, config.poses_file)
            problem = None
        except ConfigError as error:
            problem = error.message
        rows.append({"pose": name, "role": _role(name, config), "joints": pose, "problem": problem})
    if arguments.json:
        print(json.dumps(rows))
    else:
        if not rows:
            print(f"no poses in {config.poses_file} yet")
        for row in rows:
            values = ", ".join(f"{k} {v:.1f}" for k, v in row["joints"].items())
            status = row["problem"] or "ok"
            print(f"{row['pose']:<16} {row['role']:<22} {status:<4}  {values}")
    return 0 if all(row["problem"] is None for row in rows) else 1


def _role(name: str, config: Config) -> str:
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
