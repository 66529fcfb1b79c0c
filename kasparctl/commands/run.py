"""`kasparctl run`: the service itself (systemd starts it at boot)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from kasparctl.commands.arguments import UsageError, path, stdin_readable
from kasparctl.config import default_config_path
from kasparctl.service.daemon import DaemonOptions, run_daemon


def register(subparsers: Any) -> None:
    """Add `run` and its options to the command line."""
    parser = subparsers.add_parser("run", help="run the controller (what systemd starts)")
    parser.add_argument(
        "--config",
        default=None,
        type=path,
        help="kaspar.toml (default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )
    parser.add_argument(
        "--sim", action="store_true", help="simulated hardware throughout (keys on standard input)"
    )
    parser.add_argument(
        "--keys",
        default=None,
        type=path,
        metavar="FIFO",
        help="with --sim: the keyfob's keys from this fifo instead of standard input; "
        "it may appear after the start (a keyfob plugged in late) and go again",
    )
    parser.add_argument(
        "--state-dir", default=None, type=path, help="overrides the configured state_dir"
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Run the daemon until it is stopped; 1 when the configuration or phrases are unusable,
    or when another process already writes to the state directory."""
    if arguments.keys is not None and not arguments.sim:
        raise UsageError("--keys: only with --sim (the real keyfob is configured in [keyfob])")
    if arguments.sim and arguments.keys is None and not stdin_readable():
        print(
            "error: --sim: standard input is closed, and the simulated keyfob reads the keys "
            "from it: give --keys FIFO, or run it from a terminal",
            file=sys.stderr,
        )
        return 1
    options = DaemonOptions(
        config_path=arguments.config or default_config_path(),
        sim=arguments.sim,
        state_dir=arguments.state_dir,
        keys=arguments.keys,
    )
    return run_daemon(options)
