"""`kasparctl servos calibrate`: ranges, rest positions and directions shown by hand.

Torque goes off for the chosen joints only (the rest hold); the engineer moves
each through its whole safe travel (told on the terminal, and aloud with a real
voice), then presses green or Enter. The proposal is printed as a diff of the
configuration and written only with --write, every comment kept.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from typing import Any

from kasparctl.bringup.calibrate import DEFAULT_MARGIN_DEG, calibrate, print_result
from kasparctl.bringup.engineer import Ending
from kasparctl.commands.arguments import names, number, path
from kasparctl.log import configure_logging


def register(commands: Any) -> None:
    """Add `servos calibrate` to the `servos` actions."""
    parser = commands.add_parser(
        "calibrate",
        help="move joints by hand; propose their ranges, rest positions and directions",
    )
    parser.add_argument("--config", required=True, type=path,
                        help="kaspar.toml (edited with --write)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--joints", type=names, help="joints to calibrate, e.g. left_elbow,smile")
    which.add_argument("--group", help="a group to calibrate, e.g. left_arm (default: all joints)")
    parser.add_argument(
        "--margin", type=number(0, 45, unit="deg"), default=DEFAULT_MARGIN_DEG,
        help=f"degrees kept inside each end seen (default {DEFAULT_MARGIN_DEG})",
    )
    parser.add_argument(
        "--seconds", type=number(0, 3600, low_open=True, unit="s"), default=None,
        help="end after N seconds instead of waiting for a press or Enter (scripts)",
    )
    parser.add_argument("--write", action="store_true", help="write the proposal to --config")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--quiet", action="store_true", help="print the prompts, do not speak")
    parser.add_argument(
        "--sim-sweep", type=number(0, 180, unit="deg"), default=None, metavar="DEG",
        help="simulated servos only: a hand sweeps each joint DEG beyond its configured range",
    )
    parser.set_defaults(run=run)  # fmt: skip


def run(arguments: argparse.Namespace) -> int:
    """Calibrate; exit 0 when done (and written if asked), 1 on any error or warning."""
    configure_logging("warning", "console", stream=sys.stderr)
    out = sys.stderr if arguments.json else sys.stdout
    result = asyncio.run(calibrate(
        arguments.config, arguments.joints, arguments.group, margin=arguments.margin,
        seconds=arguments.seconds, quiet=arguments.quiet, sim_sweep=arguments.sim_sweep,
        write=arguments.write, out=out,
    ))  # fmt: skip
    if arguments.json:
        print(json.dumps(result.as_json()))
    else:
        print_result(result, arguments.config, out)
    if result.ending is Ending.CANCELLED:
        return 1
    return 1 if result.warnings else 0
