"""Sessions as tidy tables: one CSV row per trial, and one per other event.

Plain CSV from the csv module, readable by R's read.csv, readr and pandas'
read_csv alike as it is: a header of snake_case names, booleans TRUE/FALSE
(all read them as logical), NA where a value is missing (R's read.csv reads an
empty text cell as "", not NA; NA is missing to all three), numbers in full
precision, times in UTC ISO 8601. A text cell a spreadsheet would evaluate
(starting with =, +, -, @, a tab or a carriage return), or one that a reader
would take for a missing value ("NA", "null", "None"...), starts with a "'".
The columns are kasparctl.research.codebook's, which docs/research-data.md
shows.

Rows are streamed session by session, record by record: an export holds one
row at a time, whatever the size of the sessions.
"""

from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, TextIO

from kasparctl.game.jsonl import record_to_plain
from kasparctl.game.records import TrialRecord
from kasparctl.research import codebook
from kasparctl.research.anonymise import NO_PSEUDONYMS, Pseudonyms
from kasparctl.research.catalogue import SessionData
from kasparctl.research.children import in_question
from kasparctl.research.output import text_output
from kasparctl.research.participants import NO_PARTICIPANTS, Participants
from kasparctl.research.progress import progress
from kasparctl.research.walk import walk
from kasparctl.vocabulary import MISSING_MARKERS

# Fields of a record that are bookkeeping, not the event: in their own columns or nowhere.
# learner_rng is the learner's generator state, internal to resuming.
_EVENT_COLUMNS_FROM_RECORD = ("seq", "kind", "time", "clock", "trial")

_NOT_SNAKE = re.compile(r"[^a-z0-9]+")


def snake(name: str) -> str:
    """A toy name as part of a column name: "Teddy bear" -> "teddy_bear"."""
    return _NOT_SNAKE.sub("_", name.lower()).strip("_") or "toy"


# What a spreadsheet reads as the start of a formula (OWASP's list): such text gets a "'".
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
# A missing value, as base R's read.csv, readr and pandas all read it.
MISSING = "NA"


def cell(value: Any) -> str:
    """A value as a CSV cell: NA for None (and for empty text: R would read "" as text,
    pandas as missing), TRUE/FALSE, numbers in full, lists joined by ";".

    Text that a spreadsheet would evaluate as a formula, or that a reader would take for
    a missing value (kasparctl.vocabulary.MISSING_MARKERS: a group code "NA" recorded
    before the configuration refused it), is escaped with a leading "'".
    """
    if value is None:
        return MISSING
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else MISSING
    if isinstance(value, int):
        return str(value)
    text = ";".join(str(item) for item in value) if isinstance(value, list | tuple) else str(value)
    if not text:
        return MISSING
    if text.startswith(FORMULA_STARTS) or text.strip() in MISSING_MARKERS:
        return "'" + text
    return text


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


def trial_header(toys: dict[str, str], participants: Participants = NO_PARTICIPANTS) -> list[str]:
    """The trials CSV's columns (the codebook's), a column per toy for the per-toy values
    and per attribute."""
    return [
        name
        for name, _ in codebook.expanded(
            codebook.TRIALS, tuple(toys.values()), tuple(participants.columns)
        )
    ]


def learner_columns(session: SessionData) -> dict[str, Any]:
    """The learner frozen in the session's plan.json, as the learner_* columns."""
    frozen = session.learner or {}
    return {
        f"learner_{name}": value if isinstance(value, int | float) else None
        for name, _ in codebook.LEARNER_FIELDS
        for value in (frozen.get(name),)
    }


def trial_rows(
    session: SessionData,
    toys: dict[str, str],
    anonymise: bool = False,
    participants: Participants = NO_PARTICIPANTS,
) -> Iterator[dict[str, Any]]:
    """Every trial of a session, undone ones included and marked, streamed."""
    names = Pseudonyms(session.first_names()) if anonymise else NO_PSEUDONYMS
    answer_key = session.answer_key
    identity = session.identity
    learners = learner_columns(session)
    for walked in walk(session):
        trial, guess = walked.record, walked.guess
        if not isinstance(trial, TrialRecord) or guess is None:
            continue
        target_index, child_index = trial.target_index, trial.child_index
        code = session.participant(child_index)
        row: dict[str, Any] = {
            **identity,
            "script": session.script[0],
            "script_version": session.script[1],
            **learners,
            "trial": trial.trial,
            "seq": trial.seq,
            "problem_trial": trial.problem_trial,
            "target": trial.target,
            "answer": answer_key[target_index] if 0 <= target_index < len(answer_key) else None,
            "child": f"child {child_index + 1}" if anonymise else names.text(trial.child),
            "child_number": child_index + 1,
            "participant": code,
            **{
                f"participant_{column}": value
                for column, value in participants.attributes(code).items()
            },
            # One keyfob per child: the seat that answered, and the child credited
            # (kasparctl.game.fold: the seat's child, else the child asked).
            "seat": guess.seat,
            "device": trial.device if isinstance(trial.device, str) else None,
            "credited_child_number": guess.credited + 1,
            "credited_participant": session.participant(guess.credited),
            "candidates": trial.candidates,
            "n_candidates": len(trial.candidates),
            "entropy": trial.entropy,
            "band": trial.band,
            "spoken": names.text(" ".join(trial.spoken)) or None,
            "choice": trial.choice,
            "feedback": trial.feedback,
            "reaction_time": trial.reaction_time,
            # Answered in the question's last words; negative times recorded before the
            # flag existed are such answers too.
            "in_question": in_question(trial),
            "reward": trial.reward,
            # As the records read (kasparctl.game.fold), like the report's counts.
            "perseverative": guess.perseverative,
            "win_shift": guess.win_shift,
            "error_cause": guess.cause,
            "correct": trial.correct,
            "feedback_right": trial.feedback_right,
            "learned": trial.learned,
            "undone": walked.undone,
            "right_toy_offered": (
                answer_key[target_index] in trial.candidates
                if 0 <= target_index < len(answer_key)
                else None
            ),
            "confused": guess.confused,
            "reopened": guess.reopened,
            "time": trial.time,
            "session_clock": walked.session_clock,
            # Whether `time` can be trusted: the robot's wall clock synchronised all session.
            "clock_synchronised": session.index.clock_synchronised,
        }
        for prefix, values in _per_toy(trial):
            for toy, value in zip(session.toys, values, strict=False):
                row[prefix + toys[toy]] = value
        yield row


def _per_toy(trial: TrialRecord) -> tuple[tuple[str, list[float]], ...]:
    """The per-toy lists of a trial, each with the prefix of its columns."""
    return (("p_", trial.probabilities), ("q_before_", trial.q_before), ("q_after_", trial.q_after))


EVENT_HEADER = [column.name for column in codebook.EVENTS]

# The field that names what happened, per record kind ("command": which command).
_EVENT_NAME = {
    "command": "command",
    "fault": "fault",
    "hal": "event",
    "press": "button",
    "prompt": "line",
    "session": "event",
    "step": "to",
    "confused": "reason",
    "reopen": "name",
    "alert": "alert",
    "rotation": "event",
    "button_check": "asked",
}


def event_rows(session: SessionData, anonymise: bool = False) -> Iterator[dict[str, Any]]:
    """Every record that is not a trial: commands, presses, prompts, faults, HAL events,
    steps, poses, undos and the session's start and resumes."""
    names = Pseudonyms(session.first_names()) if anonymise else NO_PSEUDONYMS
    for walked in walk(session):
        typed = walked.record
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
        child = walked.child_index
        yield {
            "session": session.uid,
            "session_name": session.name,
            "robot": session.robot,
            "robot_name": session.robot_name,
            "group": session.group,
            "session_number": session.number,
            "condition": session.condition,
            "uncertainty": session.uncertainty,
            "script": session.script[0],
            "script_version": session.script[1],
            "language": session.language,
            "seq": record.get("seq"),
            "time": record.get("time"),
            "clock": record.get("clock"),
            "session_clock": walked.session_clock,
            "kind": kind,
            "name": names.value(name),
            # A prompt's trial: the question it repeated (the walk knows which).
            "trial": record.get("trial", walked.trial),
            "participant": None if child is None else session.participant(child),
            "detail": (
                json.dumps(names.value(detail), sort_keys=True, ensure_ascii=False)
                if detail
                else None
            ),
        }


def _write(
    target: str,
    header: list[str],
    sessions: Sequence[SessionData],
    rows_of: Callable[[SessionData], Iterable[dict[str, Any]]],
    what: str,
) -> int:
    count = 0
    with text_output(target) as stream:
        count = write_rows(stream, header, sessions, rows_of, what)
    return count


def write_rows(
    stream: TextIO,
    header: list[str],
    sessions: Sequence[SessionData],
    rows_of: Callable[[SessionData], Iterable[dict[str, Any]]],
    what: str,
) -> int:
    """The header and every session's rows as CSV on `stream`; returns the number of rows."""
    writer = csv.writer(stream, lineterminator="\n")
    writer.writerow(header)
    count = 0
    for session in progress(sessions, what, "session"):
        for row in rows_of(session):
            writer.writerow([cell(row.get(column)) for column in header])
            count += 1
    return count


def write_trials(
    target: str,
    sessions: Sequence[SessionData],
    anonymise: bool,
    participants: Participants = NO_PARTICIPANTS,
) -> int:
    """The trials CSV ("-": stdout); returns the number of rows (undone trials included)."""
    toys = toy_columns(sessions)
    return _write(
        target,
        trial_header(toys, participants),
        sessions,
        lambda session: trial_rows(session, toys, anonymise, participants),
        "exporting trials",
    )


def write_events(target: str, sessions: Sequence[SessionData], anonymise: bool) -> int:
    """The events CSV (every record that is not a trial); returns the number of rows."""
    return _write(
        target,
        EVENT_HEADER,
        sessions,
        lambda session: event_rows(session, anonymise),
        "exporting events",
    )
