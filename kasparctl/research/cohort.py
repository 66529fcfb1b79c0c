"""Recorded sessions as a cohort to compare with the model: its figures, shape and children.

`kasparctl replicate` places a cohort's figures among simulated studies of
the same size; `kasparctl fit-teacher` (and replicate by default) models the
cohort's children from what they did. This module reads both from the
sessions, in the same single pass the report makes, and returns plain
numbers: the simulator (a room on the same floor) never sees a session.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from hal.errors import KasparError
from kasparctl.game.records import PromptRecord, TrialRecord
from kasparctl.learning.learner import LearnerParams
from kasparctl.research.catalogue import SessionData
from kasparctl.research.conditions import by_condition
from kasparctl.research.walk import walk


class CohortError(KasparError, ValueError):
    """Sessions that do not make one cohort; the message says what to give."""


@dataclass(frozen=True)
class Cohort:
    """One condition's sessions as a study: its figures and what the model must play."""

    label: str
    sessions: int
    variant: str
    profile: str
    toys: tuple[str, ...]
    targets: int
    figures: dict[str, float]


def cohort_of(sessions: Sequence[SessionData], params: Callable[[str], LearnerParams]) -> Cohort:
    """The figures of sessions of one condition (CohortError if they span several)."""
    conditions = by_condition(sessions, params)
    if len(conditions) != 1:
        labels = ", ".join(c.label for c in conditions)
        raise CohortError(
            f"the sessions are of {len(conditions)} conditions ({labels}): a cohort is one "
            "condition; name its sessions (`kasparctl sessions` lists them)"
        )
    (condition,) = conditions
    stats = condition.stats
    first_right: dict[int, int] = {}
    for problem in condition.problems:
        record = problem.record
        first_right[record.group] = first_right.get(record.group, 0) + (
            record.trials[0].correct is True
        )
    figures = {
        "trials_total": stats.trials_total,
        "trials_mean": stats.trials_mean,
        "trials_sd": stats.trials_sd,
        "trials_min": stats.trials_min,
        "trials_max": stats.trials_max,
        "problems_given_up": stats.problems_given_up,
        "first_guess_correct": stats.first_guess_correct,
        "groups_first_right_twice": sum(1 for n in first_right.values() if n >= 2),
        "perseverative_errors": stats.perseverative_errors,
        "win_shifts": stats.win_shifts,
        "final_entropy_mean": stats.final_entropy_mean,
        "final_entropy_sd": stats.final_entropy_sd,
    }
    session = condition.sessions[0]
    targets = max((p.record.target + 1 for p in condition.problems), default=0)
    return Cohort(
        label=condition.label,
        sessions=len(condition.sessions),
        variant=session.variant,
        profile=session.profile,
        toys=session.toys,
        targets=targets,
        figures={k: float(v) for k, v in figures.items() if v is not None},
    )


@dataclass
class PlaceCounts:
    """What the children at one place in the turn order did, over every session."""

    place: int  # 1 for the first child
    answers: int = 0
    wrong_guesses: int = 0
    false_greens: int = 0
    right_guesses: int = 0
    false_reds: int = 0
    prompted: int = 0  # questions that needed at least one prompt
    reaction_times: list[float] = field(default_factory=list)


def teaching_by_place(sessions: Sequence[SessionData]) -> list[PlaceCounts]:
    """The children's answers by place in the turn order: what a teacher model is fitted from.

    Only answers that count (not undone) and, for the error rates, only sessions
    with an answer key.
    """
    places: dict[int, PlaceCounts] = {}
    for session in sessions:
        prompted: set[int] = set()
        for walked in walk(session):
            record = walked.record
            if isinstance(record, PromptRecord) and walked.child_index is not None:
                prompted.add(walked.child_index)
            elif isinstance(record, TrialRecord):
                was_prompted = record.child_index in prompted
                prompted.discard(record.child_index)
                if walked.undone:
                    continue
                counts = places.setdefault(record.child_index, PlaceCounts(record.child_index + 1))
                counts.answers += 1
                counts.prompted += was_prompted
                counts.reaction_times.append(record.reaction_time)
                if record.correct is True:
                    counts.right_guesses += 1
                    counts.false_reds += not record.green
                elif record.correct is False:
                    counts.wrong_guesses += 1
                    counts.false_greens += record.green
    return [places[index] for index in sorted(places)]
