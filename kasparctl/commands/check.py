"""`kasparctl check`: is this robot ready for a session? A table, and an exit code.

Validates the configuration and phrases, the body's behaviours against the
configured joints (as `behaviour check`: a bad file would leave Kaspar still in
front of the children), pings and reads every configured servo (its
temperature, voltage, error bits; an impossible reading fails; nothing moves on
a powered robot), finds the keyfob and the researcher's device (with --press, a button of each
within SECONDS), speaks a test line, and warns (WARN, exit 0) when the wall clock is not
synchronised. Usable over ssh by an engineer; exit 1 when anything is wrong.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from kasparctl.bringup.readiness import Result, Robot
from kasparctl.commands.arguments import number, path
from kasparctl.config import default_config_path
from kasparctl.log import configure_logging


def register(subparsers: Any) -> None:
    """Add the `check` subcommand."""
    parser = subparsers.add_parser("check", help="check the configuration and the hardware")
    parser.add_argument(
        "--config",
        default=None,
        type=path,
        help="kaspar.toml (default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )
    parser.add_argument(
        "--quiet", action="store_true", help="do not speak the test line (check the voice silently)"
    )
    parser.add_argument(
        "--press",
        type=number(1.0, 600.0),
        default=None,
        metavar="SECONDS",
        help="ask for a button of the keyfob and of the researcher's device, each within SECONDS",
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Check the configuration, phrases, servos, keyfob and voice; exit 1 if any fails."""
    robot = Robot.read(arguments.config or default_config_path())
    # Errors only: the table says what is wrong, once per part (a bus's retries would
    # repeat its adapter's row).
    configure_logging("error", "console", stream=sys.stderr)
    results = [
        *robot.settings(),
        *robot.hardware(speak=not arguments.quiet, press_within=arguments.press),
    ]
    _print_table(results)
    return 0 if all(result.ok for result in results) else 1


def _print_table(results: list[Result]) -> None:
    width = max(len(result.part) for result in results)
    for result in results:
        verdict = "FAIL" if not result.ok else "WARN" if result.warning else "ok"
        print(f"{result.part:<{width}}  {verdict:<4}  {result.detail}")
