"""`kasparctl behaviour check/play/record`: behaviour files checked, played and recorded.

check: every behaviour file (the shipped phrases/behaviours/, or body.behaviours_dir)
against the configured joints: an unknown joint, a keyframe that would be clamped or
a move faster than a joint's limit is named with its file, behaviour and keyframe.
play: on simulated servos by default (in simulated time, at once), or with --real on
the configured servos as `pose play` does. record: by demonstration, as `pose record`:
the joints go limp, each green press (or Enter) takes a keyframe, a long green press
(or "s" and Enter) saves, red (or "q" and Enter) cancels.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from pathlib import Path
from typing import Any

from hal.clock import LoopClock, MonotonicClock
from kasparctl.body.behaviours import load_library
from kasparctl.body.check import problems
from kasparctl.bringup.behaviours import perform, play_real, record
from kasparctl.bringup.engineer import BringUpError, Engineer, open_servos, select_joints
from kasparctl.commands.arguments import key, names, number, path
from kasparctl.commands.motion import powered_sim, trajectory, write_csv
from kasparctl.config import Config, default_config_path, load_config
from kasparctl.log import configure_logging
from kasparctl.sim import simtime


def register(subparsers: Any) -> None:
    """Add the `behaviour` command with its check, play and record actions."""
    parser = subparsers.add_parser("behaviour", help="check, play and record Kaspar's behaviours")
    actions = parser.add_subparsers(dest="behaviour_command", metavar="ACTION", required=True)

    def common(action: argparse.ArgumentParser) -> None:
        action.add_argument("--config", default=None, type=path,
                            help="kaspar.toml (default: $KASPAR_CONFIG or /etc/kaspar)")

    check = actions.add_parser("check", help="every behaviour file against the configured robot")
    common(check)
    check.add_argument("--json", action="store_true", help="print the problems as JSON")
    check.set_defaults(run=run_check)

    play = actions.add_parser("play", help="play a behaviour (simulated unless --real)")
    play.add_argument("name", type=key)
    common(play)
    play.add_argument("--strength", type=number(0, 1), default=1.0, help="0 to 1 (default 1)")
    play.add_argument("--real", action="store_true",
                      help="on the configured servos (servos.backend), as `pose play`")
    play.add_argument("--motion", metavar="CSV", type=path,
                      help="simulated: write the joint goals sent")
    play.set_defaults(run=run_play)

    record = actions.add_parser("record", help="record a behaviour by moving the joints by hand")
    record.add_argument("name", type=key)
    common(record)
    which = record.add_mutually_exclusive_group()
    which.add_argument("--group", help="the group to move (default: every joint)")
    which.add_argument("--joints", type=names, help="joints to move, e.g. head_yaw,head_pitch")
    record.add_argument("--quiet", action="store_true", help="print the prompts, do not speak")
    record.set_defaults(run=run_record)


def _config(arguments: argparse.Namespace) -> Config:
    return load_config(arguments.config or default_config_path(), poses=False)


def run_check(arguments: argparse.Namespace) -> int:
    """Print every problem (exit 1), or how many behaviours fit (exit 0)."""
    config = _config(arguments)
    library = load_library(config.body.behaviours_dir)
    found = problems(library, config.servos)
    if arguments.json:
        print(json.dumps({"behaviours": sorted(library), "problems": found}))
    else:
        for line in found:
            print(line)
        if not found:
            print(f"{len(library)} behaviours fit the robot's {len(config.servos.joints)} joints: "
                  + ", ".join(sorted(library)))
    return 1 if found else 0


def run_play(arguments: argparse.Namespace) -> int:
    """Play one behaviour; exit 1 if it is unknown or cannot be played."""
    configure_logging("warning", "console", stream=sys.stderr)
    config = _config(arguments)
    library = load_library(config.body.behaviours_dir)
    if arguments.name not in library:
        raise BringUpError(f"no behaviour {arguments.name!r} (behaviours: "
                           f"{', '.join(sorted(library))})")
    if arguments.real:
        moved = asyncio.run(play_real(config, library, arguments.name, arguments.strength))
    else:
        moved = simtime.run(play_sim(config, library, arguments), virtual=True)
    where = "on the robot" if arguments.real else "on the simulated robot"
    print(f"played {arguments.name!r} {where} (strength {arguments.strength:g}): "
          + (", ".join(f"{joint} {low:+.1f}..{high:+.1f}" for joint, (low, high) in moved.items())
             or "nothing moved"))
    return 0


async def play_sim(config: Config, library: Any, arguments: argparse.Namespace
                   ) -> dict[str, tuple[float, float]]:
    """On the configured joints, simulated, in simulated time; --motion writes the goals."""
    servos = await powered_sim(config)
    clock = LoopClock()
    origin = clock.now()
    seen = await perform(servos, config, library, clock, arguments.name, arguments.strength)
    if arguments.motion:
        write_csv(trajectory(servos, origin), Path(arguments.motion))
    return seen


def run_record(arguments: argparse.Namespace) -> int:
    """Record one behaviour into body.behaviours_dir; exit 0 when saved."""
    configure_logging("warning", "console", stream=sys.stderr)
    config = _config(arguments)
    if config.body.behaviours_dir is None:
        raise BringUpError(
            "body.behaviours_dir is not set: recorded behaviours go to a directory of "
            "your own (copy the shipped phrases/behaviours/ there first)"
        )
    clock = MonotonicClock()
    servos = open_servos(config, clock)
    engineer = Engineer(config, clock, seconds=None, quiet=arguments.quiet, out=sys.stdout)
    saved = asyncio.run(record(config, servos, engineer, arguments.name,
                               select_joints(servos, arguments.joints, arguments.group)))
    if saved is None:
        print("cancelled: nothing saved")
        return 1
    print(f"behaviour {arguments.name!r} saved in {saved}")
    return 0
