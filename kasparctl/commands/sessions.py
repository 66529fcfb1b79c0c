"""`kasparctl sessions`: every recorded session, with its ids, group, condition, date and status.

Status is "finished", "stopped" (the researcher's stop gesture),
"interrupted" (the robot never reached the end: it resumes the most recent
such session on its next start), "absent" (the group was marked absent in
idle and never opened; "absent, taken back" once chosen again), or "damaged"
(it cannot be read: the reason is given). A session a crash cost a torn last
record says so ("recovered"), as does one recorded while the robot's clock was
not synchronised. Sessions are listed in the order they began on each robot
(its sequence number, never the wall clock alone). Each session is read in one
streaming pass, never held whole.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from kasparctl.commands.arguments import add_sources
from kasparctl.research.catalogue import Damaged, SessionData
from kasparctl.research.sessions_table import session_row
from kasparctl.research.source import read_sessions

COLUMNS = (
    "session_name",
    "session",
    "robot",
    "group",
    "condition",
    "variant",
    "date",
    "trials",
    "status",
    "resumed",
)


def register(subparsers: Any) -> None:
    """Add the `sessions` subcommand."""
    parser = subparsers.add_parser(
        "sessions", help="list the recorded sessions", description=__doc__
    )
    add_sources(parser, sessions=False)
    parser.add_argument("--json", action="store_true", help="one JSON array, for scripts")
    parser.set_defaults(run=run)


def describe(session: SessionData) -> dict[str, Any]:
    """One session as a row of the listing: the sessions table's row (research.codebook's
    SESSIONS: robot, session number, kasparctl version, learner, settings...), what a
    crash cost it, and its directory."""
    return {
        **session_row(session),
        "speak_uncertainty": session.speak_uncertainty,
        "recovered": session.recovered,
        "directory": str(session.directory),
    }


def describe_damaged(damaged: Damaged) -> dict[str, Any]:
    """A session that cannot be read, as a row: its directory and why."""
    return {
        "session_name": damaged.directory.name,
        "status": "damaged",
        "reason": damaged.reason,
        "directory": str(damaged.directory),
    }


def run(arguments: argparse.Namespace) -> int:
    """List every session of the state directories: ids, group, condition, date, status."""
    # Damaged sessions are part of the listing, not warnings beside it.
    source, catalogue = read_sessions(arguments, report_damaged=False)
    rows = [describe(session) for session in catalogue.sessions]
    damaged = [describe_damaged(d) for d in catalogue.damaged]
    if arguments.json:
        print(json.dumps(rows + damaged, indent=1))
        return 0
    if not rows and not damaged:
        where = ", ".join(str(d) for d in source.state_dirs)
        print(f"no sessions in {where}")
        return 0
    table = [list(COLUMNS), *([str(row[column]) for column in COLUMNS] for row in rows)]
    widths = [max(len(line[index]) for line in table) for index in range(len(COLUMNS))]
    for line in table:
        cells = (text.ljust(width) for text, width in zip(line, widths, strict=True))
        print("  ".join(cells).rstrip())
    for row in rows:
        if row["recovered"]:
            print(f"recovered: {row['session_name']}: {row['recovered']}")
    for row in rows:
        if row["clock_synchronised"] is False:
            print(f"clock: {row['session_name']}: recorded while the robot's clock was not "
                  "synchronised: its times may be wrong, its order is not")
    for row in damaged:
        print(f"damaged: {row['reason']}")
    sys.stdout.flush()
    return 0
