"""An export into a directory: the CSVs, codebook.md and datapackage.json (or Psych-DS).

`write_package` writes trials.csv, events.csv and sessions.csv with their
codebook and Frictionless data package (kasparctl.research.package) into one
directory (made 0700); with `psych_ds` the CSVs go under data/ with Psych-DS
names, beside dataset_description.json. `write_bundle` is what leaves the
robot (kasparctl.research.bundle): the anonymised records, the package made
from them, and the manifest of checksums.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from kasparctl.research.bundle import Keying, copy_sessions, write_manifest
from kasparctl.research.catalogue import SessionData, open_sessions
from kasparctl.research.output import private_directory, write_bytes
from kasparctl.research.package import (
    PSYCH_DS_NAMES,
    Table,
    codebook_markdown,
    datapackage,
    dataset_description,
)
from kasparctl.research.participants import NO_PARTICIPANTS, Participants
from kasparctl.research.sessions_table import sessions_header, write_sessions
from kasparctl.research.tidy import (
    EVENT_HEADER,
    toy_columns,
    trial_header,
    write_events,
    write_trials,
)

TITLE = "Kaspar: children as teachers"


@dataclass(frozen=True)
class Package:
    """What a package holds: rows per table, and the files written."""

    trials: int
    events: int
    sessions: int
    files: list[str]


def write_package(
    out: Path,
    sessions: Sequence[SessionData],
    anonymise: bool,
    participants: Participants = NO_PARTICIPANTS,
    psych_ds: bool = False,
) -> Package:
    """The three CSVs, codebook.md and datapackage.json (and Psych-DS's layout) in `out`."""
    private_directory(out)
    names = (
        PSYCH_DS_NAMES
        if psych_ds
        else {"trials": "trials.csv", "events": "events.csv", "sessions": "sessions.csv"}
    )
    if psych_ds:
        private_directory(out / "data")
    toys = toy_columns(sessions)
    tables = [
        Table("trials", names["trials"], trial_header(toys, participants)),
        Table("events", names["events"], EVENT_HEADER),
        Table("sessions", names["sessions"], sessions_header()),
    ]
    trials = write_trials(str(out / names["trials"]), sessions, anonymise, participants)
    events = write_events(str(out / names["events"]), sessions, anonymise)
    count = write_sessions(str(out / names["sessions"]), sessions)
    write_bytes(out / "codebook.md", codebook_markdown(tables).encode("utf-8"))
    write_bytes(out / "datapackage.json", _json(datapackage(tables, TITLE)))
    files = [*names.values(), "codebook.md", "datapackage.json"]
    if psych_ds:
        write_bytes(out / "dataset_description.json", _json(dataset_description(tables, TITLE)))
        files.append("dataset_description.json")
    return Package(trials, events, count, files)


def _json(value: object) -> bytes:
    return json.dumps(value, indent=2, ensure_ascii=False).encode("utf-8") + b"\n"


def write_bundle(
    out: Path,
    sessions: Sequence[SessionData],
    secret: bytes | None,
    shift_dates: bool,
    participants: Participants = NO_PARTICIPANTS,
) -> tuple[Package, int]:
    """The anonymised records, the package made from them, and MANIFEST.sha256; the
    package and the number of files the manifest lists."""
    private_directory(out)
    keying = Keying.make(secret, shift_dates)
    copies = open_sessions(copy_sessions(sessions, out, keying))
    package = write_package(out, copies.sessions, True, participants)
    return package, write_manifest(out)
