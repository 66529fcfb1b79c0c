"""`kasparctl export`: trials (and other events) of recorded sessions as tidy CSV.

One row per trial, undone answers included and marked, with the session (its
unique id and readable name), robot, group, condition and participant on
every row; columns are documented in docs/research-data.md. --events writes
every other record (researcher commands, presses, prompts, faults, HAL
events, steps) to a second CSV, --sessions one row per session. --out DIR
writes all three with codebook.md and datapackage.json (a Frictionless data
package; --psych-ds: a Psych-DS layout with dataset_description.json).
--bundle DIR writes what leaves the robot: anonymised records and CSVs, the
codebook and package, and MANIFEST.sha256. --state-dir may be repeated to pool
robots or days. Outputs are private (0600), written whole or not at all, and
never inside a state or session directory.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from kasparctl.commands.arguments import UsageError, add_sources, path
from kasparctl.research.bundle import MANIFEST
from kasparctl.research.exported import write_bundle, write_package
from kasparctl.research.output import check_outputs
from kasparctl.research.participants import NO_PARTICIPANTS, Participants, load_participants
from kasparctl.research.sessions_table import write_sessions
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
    parser.add_argument("--csv", type=path, metavar="FILE", help="the trials CSV ('-': stdout)")
    parser.add_argument(
        "--events", metavar="FILE", type=path, help="also every non-trial record, as CSV"
    )
    parser.add_argument(
        "--sessions",
        dest="sessions_csv",
        metavar="FILE",
        type=path,
        help="also one row per session, as CSV",
    )
    parser.add_argument(
        "--out",
        metavar="DIR",
        type=path,
        help="trials.csv, events.csv, sessions.csv, codebook.md and datapackage.json in DIR",
    )
    parser.add_argument(
        "--psych-ds",
        action="store_true",
        help="with --out: a Psych-DS layout (data/*_data.csv, dataset_description.json)",
    )
    parser.add_argument(
        "--bundle",
        metavar="DIR",
        type=path,
        help="what leaves the robot: anonymised records and CSVs, codebook, package, checksums",
    )
    parser.add_argument(
        "--secret",
        metavar="FILE",
        type=path,
        help="with --bundle: a secret kept off the bundle; the same one re-keys ids alike",
    )
    parser.add_argument(
        "--shift-dates",
        action="store_true",
        help="with --bundle: move every date back by 1-104 weeks drawn from the secret",
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
    _check_usage(arguments)
    participants = _participants(arguments.participants)
    secret = _secret(arguments.secret)
    source, catalogue = read_sessions(arguments)
    sessions = catalogue.sessions
    outputs = [
        (option, value)
        for option, value in (
            ("--csv", arguments.csv),
            ("--events", arguments.events),
            ("--sessions", arguments.sessions_csv),
            ("--out", arguments.out),
            ("--bundle", arguments.bundle),
        )
        if value
    ]
    check_outputs(
        outputs,
        source.state_dirs,
        [s.directory for s in sessions] + [d.directory for d in catalogue.damaged],
        input_files(arguments),
    )
    report_unknown_codes(sessions, participants)
    said: list[str] = []
    try:
        if arguments.csv:
            rows = write_trials(arguments.csv, sessions, arguments.anonymise, participants)
            said.append(f"{rows} trials from {len(sessions)} sessions to {arguments.csv}")
        if arguments.events:
            events = write_events(arguments.events, sessions, arguments.anonymise)
            said.append(f"{events} events to {arguments.events}")
        if arguments.sessions_csv:
            write_sessions(arguments.sessions_csv, sessions)
            said.append(f"{len(sessions)} sessions to {arguments.sessions_csv}")
        if arguments.out:
            package = write_package(
                Path(arguments.out),
                sessions,
                arguments.anonymise,
                participants,
                arguments.psych_ds,
            )
            said.append(
                f"{package.trials} trials, {package.events} events and {package.sessions} "
                f"sessions with codebook.md and datapackage.json to {arguments.out}"
            )
        if arguments.bundle:
            bundle, files = write_bundle(
                Path(arguments.bundle), sessions, secret, arguments.shift_dates, participants
            )
            said.append(
                f"{bundle.sessions} sessions anonymised ({bundle.trials} trials) to "
                f"{arguments.bundle}, {files} files in its {MANIFEST}"
            )
    except OSError as error:
        if isinstance(error, BrokenPipeError):
            raise  # `--csv - | head`: the command line ends quietly
        print(f"error: cannot write the CSV: {_why(error)}", file=sys.stderr)
        return 1
    # Stdout may be the CSV itself: the tally goes with the warnings.
    message = "; ".join(said)
    if catalogue.damaged:
        message += f" ({len(catalogue.damaged)} damaged sessions left out, listed above)"
    print(message, file=sys.stderr)
    return 0


def _check_usage(arguments: argparse.Namespace) -> None:
    """At least one output; the options that qualify one only with it."""
    if not (arguments.csv or arguments.out or arguments.bundle):
        raise UsageError("export: give --csv FILE, --out DIR or --bundle DIR")
    if arguments.psych_ds and not arguments.out:
        raise UsageError("export: --psych-ds goes with --out DIR")
    if (arguments.secret or arguments.shift_dates) and not arguments.bundle:
        raise UsageError("export: --secret and --shift-dates go with --bundle DIR")


def _secret(path: str | None) -> bytes | None:
    """The bundle's secret, read whole; UsageError naming the file if it cannot be."""
    if path is None:
        return None
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise UsageError(f"--secret {path}: cannot read it: {error.strerror or error}") from None
    if len(data.strip()) < 16:
        raise UsageError(
            f"--secret {path}: expected a secret of at least 16 bytes, found {len(data.strip())}"
        )
    return data


def _participants(path: str | None) -> Participants:
    return NO_PARTICIPANTS if path is None else load_participants(Path(path))


def _why(error: OSError) -> str:
    where = f"{error.filename}: " if error.filename else ""
    return f"{where}{error.strerror or error}"
