"""Sessions grouped by condition, as the problems the paper's statistics work on.

A condition is the plan's (learner profile / uncertainty spoken or silent).
The pilot and the names game are different games, so when the sessions mix
variants the variant is part of the condition too.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

from kasparctl.game.records import TrialRecord
from kasparctl.learning.learner import LearnerParams
from kasparctl.learning.session_stats import problems_from_trials
from kasparctl.learning.study_stats import ProblemRecord, StudyStats, summarise
from kasparctl.research.catalogue import SessionData


@dataclass(frozen=True, slots=True)
class Problem:
    """One problem with the toy names its indices refer to (sessions may differ)."""

    toys: tuple[str, ...]
    record: ProblemRecord

    @property
    def answer(self) -> str | None:
        """The right toy's name, where the plan had an answer key."""
        return None if self.record.answer is None else self.toys[self.record.answer]


@dataclass
class Condition:
    """The sessions of one condition and their problems."""

    label: str
    sessions: list[SessionData] = field(default_factory=list)
    problems: list[Problem] = field(default_factory=list)

    @cached_property
    def stats(self) -> StudyStats:
        """The paper's statistics over this condition's problems."""
        # The paper's statistics, computed by the simulator's own code.
        return summarise([problem.record for problem in self.problems])

    @property
    def trials(self) -> list[TrialRecord]:
        """Trials that count (not undone), over every session."""
        return [trial for session in self.sessions for trial in session.trials]

    @property
    def undone(self) -> int:
        """How many answers were taken back, over every session."""
        return sum(len(s.all_trials) - len(s.trials) for s in self.sessions)


def condition_labels(sessions: Sequence[SessionData]) -> list[str]:
    """Each session's condition label; with the variant when the sessions mix variants."""
    mixed = len({session.variant for session in sessions}) > 1
    return [
        f"{session.condition} ({session.variant})" if mixed else session.condition
        for session in sessions
    ]


def by_condition(
    sessions: Sequence[SessionData], params: Callable[[str], LearnerParams]
) -> list[Condition]:
    """One Condition per label, sorted by label; `params` maps a profile name to its values."""
    conditions: dict[str, Condition] = {}
    for index, (session, label) in enumerate(
        zip(sessions, condition_labels(sessions), strict=True)
    ):
        condition = conditions.setdefault(label, Condition(label))
        condition.sessions.append(session)
        toys = session.toys
        # An answer key naming a toy the session never offered cannot be used.
        answer_key = session.answer_key if set(session.answer_key) <= set(toys) else ()
        records = problems_from_trials(
            session.trials, toys, answer_key, params(session.profile), group=index
        )
        condition.problems.extend(Problem(toys, record) for record in records)
    return [conditions[label] for label in sorted(conditions)]


def pooled(conditions: Sequence[Condition]) -> Condition:
    """Every session in one: the "all" column beside the conditions."""
    everything = Condition("all")
    for condition in conditions:
        everything.sessions.extend(condition.sessions)
        everything.problems.extend(condition.problems)
    return everything
