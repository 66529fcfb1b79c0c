"""`kasparctl watch`: the researcher's live view of the session, from its records.

Full screen on a terminal (with the `view` extra: pip install 'kasparctl[view]'),
plain text on a dumb terminal or a pipe. Read-only: it reads the state
directory (over ssh on the robot, or a copy on a laptop), takes no lock and
opens no socket, and sleeps until a record is written. `--replay SESSION`
plays a recorded session back at its own pace (`--speed N` times faster).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from hal.errors import KasparError
from kasparctl.commands.arguments import number, path
from kasparctl.config import ConfigError, default_config_path, load_config


class NoStateDir(KasparError):
    """Neither --state-dir nor a configuration names the state directory."""


def register(subparsers: Any) -> None:
    """Add the `watch` subcommand."""
    parser = subparsers.add_parser(
        "watch",
        help="the live view of the session, as the children teach Kaspar",
        description=__doc__,
    )
    parser.add_argument(
        "--state-dir", default=None, type=path,
        help="the robot's state directory (default: the config's)",
    )  # fmt: skip
    parser.add_argument(
        "--config",
        default=None,
        type=path,
        help="kaspar.toml naming the state directory "
        "(default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )
    parser.add_argument(
        "--replay",
        metavar="SESSION",
        type=path,
        default=None,
        help="replay a recorded session (its id, or its directory) instead of following",
    )
    parser.add_argument(
        "--speed", type=number(0, 1e6, low_open=True), default=1.0,
        help="replay N times faster than it was recorded",
    )  # fmt: skip
    parser.add_argument(
        "--plain", action="store_true", help="plain text even on a terminal that can do more"
    )
    parser.add_argument(
        "--once", action="store_true", help="print the picture now as plain text, and exit"
    )
    parser.set_defaults(run=run)


def state_dir_of(arguments: argparse.Namespace) -> Path:
    """--state-dir, else the configuration's state_dir; it need not exist yet (it is waited for)."""
    if arguments.state_dir is not None:
        return Path(arguments.state_dir)
    path = arguments.config or default_config_path()
    if arguments.config is None and not Path(path).is_file():
        raise NoStateDir(
            f"no state directory: give --state-dir DIR, or --config FILE "
            f"(the default configuration {path} does not exist)"
        )
    return Path(load_config(path).state_dir)


def run(arguments: argparse.Namespace) -> int:
    """Follow (or replay) a session in the live view."""
    # Imported here: the daemon, which imports every command module, does not need the view.
    from kasparctl.view import main as view
    from kasparctl.view.screen import rich_available

    try:
        state_dir: Path | None = state_dir_of(arguments)
    except (ConfigError, NoStateDir):
        if arguments.replay is None or not Path(arguments.replay).is_dir():
            raise
        state_dir = None  # a session directory given as it is needs no state directory
    if sys.stdout.isatty() and not (arguments.plain or arguments.once) and not rich_available():
        print(
            "note: plain text; for the full-screen view: pip install 'kasparctl[view]'",
            file=sys.stderr,
        )
    if arguments.replay is not None or state_dir is None:
        view.replay(arguments.replay, state_dir, arguments.speed, arguments.plain)
    elif arguments.once:
        view.print_once(state_dir)
    else:
        view.follow(state_dir, arguments.plain)
    return 0
