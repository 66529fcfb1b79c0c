"""`kasparctl export`: trials (and other events) of recorded sessions as tidy CSV.

One row per trial, undone answers included and marked, with the session,
group and condition on every row; columns are documented in
docs/research-data.md. --events writes every other record (researcher
commands, presses, prompts, faults, HAL events, steps) to a second CSV.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from kasparctl.research.source import SourceError, add_source_arguments, read_sessions
from kasparctl.research.tidy import write_events, write_trials


def register(subparsers: Any) -> None:
    """Add the `export` subcommand."""
    parser = subparsers.add_parser(
        "export", help="export trials to CSV for R or pandas", description=__doc__
    )
    add_source_arguments(parser)
    parser.add_argument("--csv", required=True, metavar="FILE", help="the trials CSV ('-': stdout)")
    parser.add_argument("--events", metavar="FILE", help="also every non-trial record, as CSV")
    parser.add_argument(
        "--anonymise",
        action="store_true",
        help='replace children\'s first names by "child N" (N: their place in the plan)',
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Write the trials (and optionally the events) of every session as CSV."""
    try:
        _, sessions = read_sessions(arguments)
    except SourceError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    try:
        rows = write_trials(arguments.csv, sessions, arguments.anonymise)
        events = (
            write_events(arguments.events, sessions, arguments.anonymise)
            if arguments.events
            else None
        )
    except OSError as error:
        print(f"error: cannot write the CSV: {error}", file=sys.stderr)
        return 1
    # Stdout may be the CSV itself: the tally goes with the warnings.
    message = f"{rows} trials from {len(sessions)} sessions to {arguments.csv}"
    if events is not None:
        message += f"; {events} events to {arguments.events}"
    print(message, file=sys.stderr)
    return 0
