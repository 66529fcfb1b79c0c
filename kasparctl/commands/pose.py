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
from typing import Any

from kasparctl.bringup import poses
from kasparctl.commands.arguments import assignment, key, names, number, path
from kasparctl.config import Config, default_config_path
from kasparctl.log import configure_logging


def register(subparsers: Any) -> None:
    """Add the `pose` command with its record, play and list actions."""
    parser = subparsers.add_parser("pose", help="record, play and list Kaspar's poses")
    actions = parser.add_subparsers(dest="pose_command", metavar="ACTION", required=True)

    def common(action: argparse.ArgumentParser) -> None:
        action.add_argument(
            "--config", default=None, type=path,
            help="kaspar.toml naming the poses file (default: $KASPAR_CONFIG or /etc/kaspar)",
        )
        action.add_argument("--json", action="store_true", help="print the result as JSON")

    record = actions.add_parser("record", help="move joints by hand into a pose and save it")
    record.add_argument("name", type=key, help="the pose: happy, sad, rest, a pilot location, ...")
    common(record)
    which = record.add_mutually_exclusive_group()
    which.add_argument("--group", help="the group to pose (default: every joint)")
    which.add_argument("--joints", type=names, help="joints to pose, e.g. smile,mouth_open")
    record.add_argument("--seconds", type=number(0, 3600, low_open=True, unit="s"), default=None,
                        help="save after N seconds instead of waiting for a press (scripts)")
    record.add_argument("--quiet", action="store_true", help="print the prompts, do not speak")
    record.add_argument(
        "--sim-hand", action="append", default=[], metavar="JOINT=DEG",
        type=assignment(number(-360, 360, unit="deg"), form="JOINT=DEG"),
        help="simulated servos only: a hand puts JOINT at DEG degrees (repeatable)",
    )
    record.set_defaults(run=run_record)

    play = actions.add_parser("play", help="move to a recorded pose, within every limit")
    play.add_argument("name", type=key)
    common(play)
    play.add_argument("--speed", type=number(0, 720, low_open=True, unit="deg/s"), default=None,
                      help="deg/s, at most each limit")
    play.add_argument("--duration", type=number(0, 600, unit="s"), default=None,
                      help="seconds, at least")
    play.set_defaults(run=run_play)

    listing = actions.add_parser("list", help="the recorded poses and what the game uses them for")
    common(listing)
    listing.set_defaults(run=run_list)  # fmt: skip


def _config(arguments: argparse.Namespace) -> Config:
    return poses.poses_config(arguments.config or default_config_path())


def run_record(arguments: argparse.Namespace) -> int:
    """Record one pose; exit 0 when saved, 1 when cancelled or refused."""
    configure_logging("warning", "console", stream=sys.stderr)
    out = sys.stderr if arguments.json else sys.stdout
    config = _config(arguments)
    saved = asyncio.run(poses.record(
        config, arguments.name, arguments.joints, arguments.group, seconds=arguments.seconds,
        quiet=arguments.quiet, hands=arguments.sim_hand, out=out,
    ))  # fmt: skip
    if arguments.json:
        print(json.dumps({"pose": arguments.name, "saved": saved is not None, "joints": saved}))
    elif saved is None:
        print("cancelled: nothing saved", file=out)
    else:
        print(f"pose {arguments.name!r} saved in {config.poses_file}: "
              + ", ".join(f"{k} {v:.1f}" for k, v in saved.items()), file=out)
    return 0 if saved is not None else 1


def run_play(arguments: argparse.Namespace) -> int:
    """Move to a recorded pose within every limit; exit 1 if it cannot be played."""
    configure_logging("warning", "console", stream=sys.stderr)
    config = _config(arguments)
    reached = asyncio.run(
        poses.play(config, arguments.name, arguments.duration, arguments.speed)
    )
    if arguments.json:
        print(json.dumps({"pose": arguments.name, "reached": reached}))
    else:
        print(f"pose {arguments.name!r}: " + ", ".join(f"{k} {v:.1f}" for k, v in reached.items()))
    return 0


def run_list(arguments: argparse.Namespace) -> int:
    """Print every recorded pose, its role in the game and whether it fits the ranges."""
    config = _config(arguments)
    rows = poses.listing(config)
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
