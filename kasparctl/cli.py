"""The `kasparctl` command line: argparse and dispatch, nothing else.

Each subcommand lives in kasparctl/commands/<name>.py with a `register`
function that adds its parser and sets `run`, a function of the parsed
arguments returning the exit code.

One contract for all of them (kasparctl.commands.arguments): a usage error exits 2
with one line naming the option; a failure exits 1 with one line naming its cause
(the project's own errors derive from hal.errors.KasparError; anything else is a
bug and says so), never a traceback unless asked for (--debug, or KASPAR_DEBUG=1);
a closed pipe exits 0.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from collections.abc import Sequence

from kasparctl import __version__
from kasparctl.commands.arguments import FAILURE_EXIT, USAGE_EXIT, Parser, UsageError, describe

DEBUG_ENV = "KASPAR_DEBUG"

COMMAND_MODULES = (
    "check",
    "simulate",
    "demo",
    "run",
    "reload",
    "install",
    "servos",
    "port_name",
    "pose",
    "behaviour",
    "say",
    "sessions",
    "export",
    "report",
    "watch",
    "replicate",
    "fit_teacher",
    "import_content",
    "keyfob",
    "plan",
)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand, each registered by its module; with `only` (a
    subcommand's name), of that one alone, so a command imports only what it runs."""
    parser = Parser(
        prog="kasparctl", description="Controller of the Kaspar robot and its teaching game."
    )
    parser.add_argument("--version", action="version", version=f"kasparctl {__version__}")
    parser.add_argument(
        "--debug",
        action="store_true",
        help=f"show the traceback of a failure (also with {DEBUG_ENV}=1)",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    chosen = [module for module in COMMAND_MODULES if _subcommand(module) == only]
    for name in chosen or COMMAND_MODULES:
        importlib.import_module(f"kasparctl.commands.{name}").register(subparsers)
    return parser


# Modules whose subcommand is not their name with dashes ("import" is Python's word).
SUBCOMMAND_OF_MODULE = {"import_content": "import"}


def _subcommand(module: str) -> str:
    """The subcommand a module registers: its name, with dashes (fit_teacher: fit-teacher)."""
    return SUBCOMMAND_OF_MODULE.get(module, module.replace("_", "-"))


def _chosen(argv: Sequence[str]) -> str | None:
    """The subcommand named on the line: the first word that is not an option (the
    options before it, --debug and --version, take no value)."""
    return next((word for word in argv if not word.startswith("-")), None)


def main(argv: Sequence[str] | None = None) -> int:
    """Run one subcommand and return its exit code: 0, 1 on a failure (one line), 2 on a
    usage error, 130 after Ctrl-C; 0 when the reader of its output went away.

    A bad argument found while parsing exits 2 here, in one line (SystemExit, as
    argparse's --help and --version exit 0).
    """
    words = sys.argv[1:] if argv is None else list(argv)
    # Importing every subcommand's room costs more than most commands do: a line that
    # names one builds that one's parser (an unknown name, or none, gets them all).
    arguments = build_parser(_chosen(words)).parse_args(words)
    debug = arguments.debug or os.environ.get(DEBUG_ENV, "") not in ("", "0")
    try:
        return int(arguments.run(arguments))
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return _pipe_closed()
    except UsageError as error:
        return _say(f"{arguments.usage_prog}: error: {error}", USAGE_EXIT)
    except Exception as error:
        if debug:
            traceback.print_exc()
        return _say(f"error: {describe(error)}", FAILURE_EXIT)


def _say(line: str, code: int) -> int:
    """The one line of a usage error or a failure, on stderr; its exit code."""
    try:
        print(" ".join(line.split()), file=sys.stderr)
    except BrokenPipeError:
        return _pipe_closed()
    return code


def _pipe_closed() -> int:
    """`kasparctl ... | head` closed the pipe: not an error of ours; say nothing more."""
    # Python would flush stdout again at exit, into the closed pipe, and complain.
    devnull = os.open(os.devnull, os.O_WRONLY)
    for stream in (sys.stdout, sys.stderr):
        try:
            os.dup2(devnull, stream.fileno())
        except (OSError, ValueError, AttributeError):
            continue
    return 0
