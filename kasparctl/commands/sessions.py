"""`kasparctl sessions`: every recorded session, with its group, condition, date and status.

Status is "finished", "stopped" (the researcher's stop gesture) or
"interrupted" (the robot never reached the end: it resumes the most recent
such session on its next start).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from kasparctl.research.catalogue import SessionData
from kasparctl.research.source import SourceError, add_source_arguments, read_sessions

COLUMNS = ("session", "group", "condition", "variant", "date", "trials", "status", "resumed")


def register(subparsers: Any) -> None:
    """Add the `sessions` subcommand."""
    parser = subparsers.add_parser(
        "sessions", help="list the recorded sessions", description=__doc__
    )
    add_source_arguments(parser, sessions=False)
    parser.add_argument("--json", action="store_true", help="one JSON array, for scripts")
    parser.set_defaults(run=run)


def describe(session: SessionData) -> dict[str, Any]:
    """One session as a row of the listing."""
    return {
        **session.identity,
        "created": session.created,
        "date": session.date,
        # Undone answers are not trials; they stay in the records and the export.
        "trials": len(session.trials),
        "undone": len(session.all_trials) - len(session.trials),
        "status": session.status,
        "resumed": session.resumed,
        "directory": str(session.directory),
    }


def run(arguments: argparse.Namespace) -> int:
    """List every session of a state directory: group, condition, date, trials, status."""
    try:
        source, sessions = read_sessions(arguments)
    except SourceError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    rows = [describe(session) for session in sessions]
    if arguments.json:
        print(json.dumps(rows, indent=1))
        return 0
    if not rows:
        print(f"no sessions in {source.state_dir}")
        return 0
    table = [list(COLUMNS), *([str(row[column]) for column in COLUMNS] for row in rows)]
    widths = [max(len(line[index]) for line in table) for index in range(len(COLUMNS))]
    for line in table:
        cells = (text.ljust(width) for text, width in zip(line, widths, strict=True))
        print("  ".join(cells).rstrip())
    return 0
