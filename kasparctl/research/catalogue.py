"""Sessions read back from disk: plan, records, and what they add up to.

The records are the truth (see kasparctl.game.session): a session's status and
trial count come from them, not from the state snapshot, which a crash can
leave one record behind.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.game.records import (
    AnyRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE, read_records, session_dirs


class CatalogueError(Exception):
    """A session that cannot be found or read, with its path."""


@dataclass(frozen=True)
class SessionData:
    """One recorded session: its plan.json, its typed records, and what could not be read."""

    directory: Path
    # plan.json as the robot wrote it: session, created, group, condition, variant, seed, plan.
    meta: dict[str, Any]
    records: list[AnyRecord]
    # Lines of records.jsonl that were not whole records, one message each.
    warnings: list[str] = field(default_factory=list)

    @property
    def id(self) -> str:
        """The session's id (its directory's name)."""
        return str(self.meta.get("session", self.directory.name))

    @property
    def plan(self) -> dict[str, Any]:
        """The session's plan entry as the robot used it."""
        return dict(self.meta.get("plan") or {})

    @property
    def group(self) -> str:
        """The group's code."""
        return str(self.meta.get("group", self.plan.get("group", "")))

    @property
    def profile(self) -> str:
        """The learner profile's name."""
        return str(self.plan.get("profile", "paper"))

    @property
    def speak_uncertainty(self) -> bool:
        """Whether Kaspar said how sure it was."""
        return bool(self.plan.get("speak_uncertainty", True))

    @property
    def condition(self) -> str:
        """profile/spoken or profile/silent."""
        spoken = "spoken" if self.speak_uncertainty else "silent"
        return str(self.meta.get("condition") or f"{self.profile}/{spoken}")

    @property
    def variant(self) -> str:
        """The game variant: "names" or "pilot"."""
        return str(self.meta.get("variant", ""))

    @property
    def script(self) -> tuple[str, int]:
        """The uncertainty script and its version; ("varied", 0) for a session planned
        before scripts existed (the five bands, with the words of then)."""
        return str(self.meta.get("script", "varied")), int(self.meta.get("script_version", 0))

    @property
    def identity(self) -> dict[str, Any]:
        """The columns that name a session and its condition, first in every table of it."""
        return {
            "session": self.id,
            "group": self.group,
            "condition": self.condition,
            "profile": self.profile,
            "speak_uncertainty": self.speak_uncertainty,
            "variant": self.variant,
        }

    @property
    def created(self) -> str:
        """When the session was opened, UTC ISO 8601."""
        return str(self.meta.get("created", ""))

    @property
    def date(self) -> str:
        """The day the session was opened, YYYY-MM-DD."""
        return self.created[:10]

    @property
    def children(self) -> tuple[str, ...]:
        """The first names in the plan, if any."""
        return tuple(self.plan.get("children") or ())

    @property
    def answer_key(self) -> tuple[str, ...]:
        """The right toy of each target, if the plan has a key."""
        return tuple(self.plan.get("answer_key") or ())

    @cached_property
    def undone(self) -> frozenset[int]:
        """The numbers of the trials whose answers the researcher took back."""
        return frozenset(r.trial for r in self.records if isinstance(r, UndoRecord))

    @cached_property
    def all_trials(self) -> list[TrialRecord]:
        """Every trial record, undone ones included, in the order they were recorded."""
        return [r for r in self.records if isinstance(r, TrialRecord)]

    @cached_property
    def trials(self) -> list[TrialRecord]:
        """The trials that count: an answer taken back with undo is not one."""
        return [r for r in self.all_trials if r.trial not in self.undone]

    @property
    def status(self) -> str:
        """ "finished", "stopped" (the researcher's stop) or "interrupted" (never ended)."""
        last_step = None
        for record in self.records:
            if isinstance(record, StepRecord):
                last_step = record.to
        return last_step if last_step in ("finished", "stopped") else "interrupted"

    @property
    def resumed(self) -> int:
        """How many times the robot carried this session on after a crash or restart."""
        return sum(
            1
            for r in self.records
            if isinstance(r, SessionRecord) and r.event is SessionEvent.RESUMED
        )

    @cached_property
    def toys(self) -> tuple[str, ...]:
        """The game's toys in the order of the per-toy lists (probabilities, Q rows).

        plan.json does not hold them; a guess over every toy lists them all as
        candidates, in that order, and the first guess of a problem is such a
        guess in both variants. Failing that, positions are named from the choices.
        """
        width = 0
        for trial in self.all_trials:
            width = max(width, len(trial.probabilities))
            if trial.candidates and len(trial.candidates) == len(trial.probabilities):
                return tuple(trial.candidates)
        names = [f"toy {index + 1}" for index in range(width)]
        for trial in self.all_trials:
            if 0 <= trial.choice_index < width:
                names[trial.choice_index] = trial.choice
        return tuple(names)

    def first_names(self) -> dict[str, str]:
        """Each first name in the plan and the pseudonym that replaces it ("child 2")."""
        return {name: f"child {index + 1}" for index, name in enumerate(self.children) if name}


def load_session(directory: Path) -> SessionData:
    """A session directory read back; a line that is no record is a warning, not an error."""
    try:
        meta = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
    except (OSError, msgspec.DecodeError) as error:
        raise CatalogueError(f"{directory / PLAN_FILE}: cannot read the plan: {error}") from error
    if not isinstance(meta, dict):
        raise CatalogueError(f"{directory / PLAN_FILE}: expected a JSON object")
    read = read_records(directory / RECORDS_FILE)
    return SessionData(directory, meta, read.records, list(read.warnings))


def find_sessions(state_dir: Path | None, names: Sequence[str]) -> list[Path]:
    """Session directories: every one in `state_dir`, or the named ones.

    A name is a session id (a directory name under <state_dir>/sessions) or the
    path of a session directory, so sessions copied off the robot need no state dir.
    """
    if not names:
        if state_dir is None:
            raise CatalogueError("no state directory to list sessions from")
        return list(session_dirs(state_dir))
    found = []
    for name in names:
        path = Path(name)
        if (path / PLAN_FILE).is_file():
            found.append(path)
        elif state_dir is not None and (state_dir / "sessions" / name / PLAN_FILE).is_file():
            found.append(state_dir / "sessions" / name)
        else:
            where = f" in {state_dir / 'sessions'}" if state_dir is not None else ""
            raise CatalogueError(
                f"no session {name!r}{where} (`kasparctl sessions` lists them; "
                "a session directory's path works too)"
            )
    return found
