"""The sessions table: one row per session, what its trials and events share.

Its columns are kasparctl.research.codebook.SESSIONS: the session's ids, robot
(id and name), group and session number, condition, status and resumes, the
kasparctl that opened it, the learner frozen in plan.json and every setting
plan.json recorded. A trial or an event joins its row by `session`. plan.json's
keys added over time are read when present; a session recorded before them has
None there (NA in a CSV).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from typing import Any

from kasparctl.research import codebook
from kasparctl.research.catalogue import SessionData
from kasparctl.research.output import text_output
from kasparctl.research.tidy import cell, learner_columns

# The settings columns: plan.json's settings key (a voice key within settings.voice).
_SETTINGS = tuple(
    column.name
    for column in codebook.SESSIONS
    if column.empty_when.startswith("recorded before settings") and column.name != "settings"
)


def session_row(session: SessionData) -> dict[str, Any]:
    """One session as the sessions table's row (every codebook column)."""
    settings = session.settings
    row: dict[str, Any] = {
        **session.identity,
        "script": session.script[0],
        "script_version": session.script[1],
        "created": session.created,
        "date": session.date,
        "status": session.status,
        "resumed": session.resumed,
        # Undone answers are not trials; they stay in the records and the export.
        "trials": session.index.trials,
        "undone": len(session.index.undone),
        "clock_synchronised": session.index.clock_synchronised,
        "kasparctl_version": session.kasparctl_version,
        **learner_columns(session),
        **{name: _setting(settings, name) for name in _SETTINGS},
        "settings": None if settings is None else json.dumps(settings, sort_keys=True),
    }
    return {name: row.get(name) for name in sessions_header()}


def _setting(settings: dict[str, Any] | None, name: str) -> Any:
    """A setting's value from plan.json's settings ("voice_rate": settings.voice.rate)."""
    if settings is None:
        return None
    if name.startswith("voice_"):
        voice = settings.get("voice")
        value = voice.get(name.removeprefix("voice_")) if isinstance(voice, dict) else None
    else:
        value = settings.get(name)
    return value if isinstance(value, str | int | float | bool | list) else None


def sessions_header() -> list[str]:
    """The sessions table's columns."""
    return [column.name for column in codebook.SESSIONS]


def session_rows(sessions: Sequence[SessionData]) -> list[dict[str, Any]]:
    """Every session's row, in the catalogue's order."""
    return [session_row(session) for session in sessions]


def write_sessions(target: str, sessions: Sequence[SessionData]) -> int:
    """sessions.csv ("-": stdout); returns the number of rows."""
    header = sessions_header()
    with text_output(target) as stream:
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(header)
        for row in session_rows(sessions):
            writer.writerow([cell(row[column]) for column in header])
    return len(sessions)
