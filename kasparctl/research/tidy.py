"""Sessions as tidy tables: one CSV row per trial, and one per other event.

Plain CSV from the csv module, readable by R's read.csv and pandas' read_csv
as it is: a header of snake_case names, booleans TRUE/FALSE (both read them
as logical), an empty cell where a value is missing, numbers in full
precision, times in UTC ISO 8601. docs/research-data.md documents every
column; tests hold the two together.
"""

from __future__ import annotations

import csv
import json
import re
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

from kasparctl.game.records import TrialRecord
from kasparctl.game.session import record_to_plain
from kasparctl.research.anonymise import NO_PSEUDONYMS, Pseudonyms
from kasparctl.research.catalogue import SessionData
from kasparctl.research.progress import progress

# Fields of a record that are bookkeeping, not the event: in their own columns or nowhere.
# learner_rng is the learner's generator state, internal to resuming.
_EVENT_COLUMNS_FROM_RECORD = ("seq", "kind", "time", "clock", "trial")

_NOT_SNAKE = re.compile(r"[^a-z0-9]+")


def snake(name: str) -> str:
    """A toy name as part of a column name: "Teddy bear" -> "teddy_bear"."""
    return _NOT_SNAKE.sub("_", name.lower()).strip("_") or "toy"


def cell(value: Any) -> str:
    """A value as a CSV cell: empty for None, TRUE/FALSE, floats in full, lists joined by ";"."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list | tuple):
        return ";".join(str(item) for item in value)
    return str(value)


def toy_columns(sessions: Sequence[SessionData]) -> dict[str, str]:
    """Toy -> column suffix over every session, in the order first seen.

    Sessions of one study share their toys; any that do not get their own
    columns, empty on the other sessions' rows, so the header stays fixed.
    """
    suffixes: dict[str, str] = {}
    for session in sessions:
        for toy in session.toys:
            if toy not in suffixes:
                suffix = snake(toy)
                while suffix in suffixes.values():
                    suffix += "_"
                suffixes[toy] = suffix
    return suffixes


def trial_header(toys: dict[str, str]) -> list[str]:
    """The trials CSV's columns, a column per toy for the per-toy values."""
    def per_toy(prefix: str) -> list[str]:
        return [prefix + suffix for suffix in toys.values()]

    return [
        "session",
        "group",
        "condition",
        "profile",
        "speak_uncertainty",
        "variant",
        "script",
        "script_version",
        "trial",
        "problem_trial",
        "target",
        "answer",
        "child",
        "child_number",
        "candidates",
        *per_toy("p_"),
        "entropy",
        "band",
        "spoken",
        "choice",
        "feedback",
        "reaction_time",
        "reward",
        *per_toy("q_before_"),
        *per_toy("q_after_"),
        "perseverative",
        "win_shift",
        "correct",
        "feedback_right",
        "learned",
        "undone",
        "time",
    ]


def trial_rows(
    session: SessionData, toys: dict[str, str], anonymise: bool = False
) -> Iterator[dict[str, Any]]:
    """Every trial of a session, undone ones included and marked."""
    names = Pseudonyms(session.first_names()) if anonymise else NO_PSEUDONYMS
    answer_key = session.answer_key
    for trial in session.all_trials:
        target_index, child_index = trial.target_index, trial.child_index
        row: dict[str, Any] = {
            **session.identity,
            "script": session.script[0],
            "script_version": session.script[1],
            "trial": trial.trial,
            "problem_trial": trial.problem_trial,
            "target": trial.target,
            "answer": answer_key[target_index] if 0 <= target_index < len(answer_key) else None,
            "child": f"child {child_index + 1}" if anonymise else names.text(trial.child),
            "child_number": child_index + 1,
            "candidates": trial.candidates,
            "entropy": trial.entropy,
            "band": trial.band,
            "spoken": names.text(" ".join(trial.spoken)) or None,
            "choice": trial.choice,
            "feedback": trial.feedback,
            "reaction_time": trial.reaction_time,
            "reward": trial.reward,
            "perseverative": trial.perseverative,
            "win_shift": trial.win_shift,
            "correct": trial.correct,
            "feedback_right": trial.feedback_right,
            "learned": trial.learned,
            "undone": trial.trial in session.undone,
            "time": trial.time,
        }
        for prefix, values in _per_toy(trial):
            for toy, value in zip(session.toys, values, strict=False):
                row[prefix + toys[toy]] = value
        yield row


def _per_toy(trial: TrialRecord) -> tuple[tuple[str, list[float]], ...]:
    """The per-toy lists of a trial, each with the prefix of its columns."""
    return (("p_", trial.probabilities), ("q_before_", trial.q_before), ("q_after_", trial.q_after))


EVENT_HEADER = [
    "session",
    "group",
    "condition",
    "script",
    "script_version",
    "seq",
    "time",
    "clock",
    "kind",
    "name",
    "trial",
    "detail",
]

# The field that names what happened, per record kind ("command": which command).
_EVENT_NAME = {
    "command": "command",
    "fault": "fault",
    "hal": "event",
    "press": "button",
    "prompt": "line",
    "session": "event",
    "step": "to",
}


def event_rows(session: SessionData, anonymise: bool = False) -> Iterator[dict[str, Any]]:
    """Every record that is not a trial: commands, presses, prompts, faults, HAL events,
    steps, poses, undos and the session's start and resumes."""
    names = Pseudonyms(session.first_names()) if anonymise else NO_PSEUDONYMS
    for typed in session.records:
        if isinstance(typed, TrialRecord):
            continue
        # One table for every kind: each record as the plain object it is on disk.
        record = record_to_plain(typed)
        kind = record.get("kind")
        detail = {
            key: value
            for key, value in record.items()
            # The start record repeats the plan: it is plan.json, and the trial columns.
            if key not in _EVENT_COLUMNS_FROM_RECORD and not (kind == "session" and key == "plan")
        }
        name_field = _EVENT_NAME.get(str(kind))
        name = detail.pop(name_field, None) if name_field else None
        yield {
            "session": session.id,
            "group": session.group,
            "condition": session.condition,
            "script": session.script[0],
            "script_version": session.script[1],
            "seq": record.get("seq"),
            "time": record.get("time"),
            "clock": record.get("clock"),
            "kind": kind,
            "name": names.value(name),
            "trial": record.get("trial"),
            "detail": json.dumps(names.value(detail), sort_keys=True) if detail else None,
        }


@contextmanager
def _open_csv(path: Path | str) -> Iterator[TextIO]:
    if str(path) == "-":
        yield sys.stdout
        return
    with open(path, "w", newline="", encoding="utf-8") as stream:
        yield stream


def _write(
    path: Path | str,
    header: list[str],
    sessions: Sequence[SessionData],
    rows_of: Callable[[SessionData], Iterable[dict[str, Any]]],
    what: str,
) -> int:
    count = 0
    with _open_csv(path) as stream:
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(header)
        for session in progress(sessions, what, "session"):
            for row in rows_of(session):
                writer.writerow([cell(row.get(column)) for column in header])
                count += 1
    return count


def write_trials(path: Path | str, sessions: Sequence[SessionData], anonymise: bool) -> int:
    """The trials CSV; returns the number of rows (undone trials included)."""
    toys = toy_columns(sessions)
    return _write(
        path,
        trial_header(toys),
        sessions,
        lambda session: trial_rows(session, toys, anonymise),
        "exporting trials",
    )


def write_events(path: Path | str, sessions: Sequence[SessionData], anonymise: bool) -> int:
    """The events CSV (every record that is not a trial); returns the number of rows."""
    return _write(
        path,
        EVENT_HEADER,
        sessions,
        lambda session: event_rows(session, anonymise),
        "exporting events",
    )
