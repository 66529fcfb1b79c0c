"""`kasparctl export`: trials (and other events) of recorded sessions as tidy CSV.

One row per trial, undone answers included and marked, with the session (its
unique id and readable name), robot, group, condition and participant on
every row; columns are documented in docs/research-data.md. --events writes
every other record (researcher commands, presses, prompts, faults, HAL
events, steps) to a second CSV. --state-dir may be repeated to pool robots
or days. Outputs are private (0600), written whole or not at all, and never
inside a state or session directory.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from kasparctl.commands.arguments import add_sources, path
from kasparctl.research.output import check_outputs
from kasparctl.research.participants import NO_PARTICIPANTS, Participants, load_participants
from kasparctl.research.source import (
    input_files,
    read_sessions,
    report_unknown_codes,
)
from kasparctl.research.tidy import write_events, write_trials


def register(subparsers: Any) -> None:
    """Add the `export` subcommand."""
    parser = subparsers.add_parser(
        "export", help="export trials to CSV for R or pandas", description=__doc__
    )
    add_sources(parser)
    parser.add_argument(
        "--csv", required=True, type=path, metavar="FILE", help="the trials CSV ('-': stdout)"
    )
    parser.add_argument(
        "--events", metavar="FILE", type=path, help="also every non-trial record, as CSV"
    )
    parser.add_argument(
        "--participants",
        metavar="FILE",
        type=path,
        help="participants.csv: the children's attributes by code, joined to every row",
    )
    parser.add_argument(
        "--anonymise",
        action="store_true",
        help='replace children\'s first names by "child N" (N: their place in the plan)',
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Write the trials (and optionally the events) of every session as CSV."""
    participants = _participants(arguments.participants)
    source, catalogue = read_sessions(arguments)
    sessions = catalogue.sessions
    outputs = [("--csv", arguments.csv)]
    if arguments.events:
        outputs.append(("--events", arguments.events))
    check_outputs(
        outputs,
        source.state_dirs,
        [s.directory for s in sessions] + [d.directory for d in catalogue.damaged],
        input_files(arguments),
    )
    report_unknown_codes(sessions, participants)
    try:
        rows = write_trials(arguments.csv, sessions, arguments.anonymise, participants)
        events = (
            write_events(arguments.events, sessions, arguments.anonymise)
            if arguments.events
            else None
        )
    except OSError as error:
        if isinstance(error, BrokenPipeError):
            raise  # `--csv - | head`: the command line ends quietly
        print(f"error: cannot write the CSV: {_why(error)}", file=sys.stderr)
        return 1
    # Stdout may be the CSV itself: the tally goes with the warnings.
    message = f"{rows} trials from {len(sessions)} sessions to {arguments.csv}"
    if events is not None:
        message += f"; {events} events to {arguments.events}"
    if catalogue.damaged:
        message += f" ({len(catalogue.damaged)} damaged sessions left out, listed above)"
    print(message, file=sys.stderr)
    return 0


def _participants(path: str | None) -> Participants:
    return NO_PARTICIPANTS if path is None else load_participants(Path(path))


def _why(error: OSError) -> str:
    where = f"{error.filename}: " if error.filename else ""
    return f"{where}{error.strerror or error}"
