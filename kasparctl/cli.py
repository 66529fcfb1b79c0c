"""The `kasparctl` command line: argparse and dispatch, nothing else.

Each subcommand lives in kasparctl/commands/<name>.py with a `register`
function that adds its parser and sets `run`, a function of the parsed
arguments returning the exit code.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from kasparctl import __version__

COMMAND_MODULES = (
    "check",
    "simulate",
    "demo",
    "run",
    "reload",
    "install",
    "servos",
    "pose",
    "say",
    "sessions",
    "export",
    "report",
    "watch",
    "replicate",
    "fit_teacher",
)


def build_parser() -> argparse.ArgumentParser:
    """The parser of every subcommand, each registered by its module."""
    parser = argparse.ArgumentParser(
        prog="kasparctl", description="Controller of the Kaspar robot and its teaching game."
    )
    parser.add_argument("--version", action="version", version=f"kasparctl {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(f"kasparctl.commands.{name}").register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one subcommand and return its exit code (130 after Ctrl-C)."""
    arguments = build_parser().parse_args(argv)
    try:
        return int(arguments.run(arguments))
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # `kasparctl ... | head` closed the pipe; that is not an error of ours.
        sys.stderr.close()
        return 0
