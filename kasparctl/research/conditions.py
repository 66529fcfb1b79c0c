"""Sessions grouped by condition, as the problems, clusters and children the report works on.

A condition is the plan's (learner profile / uncertainty mode: spoken, body, both, or
silent for none).
The pilot and the names game are different games, so when the sessions mix
variants the variant is part of the condition too.

Everything is collected in one streaming pass over each session's records
(kasparctl.research.walk): per problem the values per trial the paper's
statistics need (with the flags as the records read, kasparctl.game.fold, so
the report counts what the trials CSV marks), per cluster (the unit a
confidence interval resamples: a group of children, or a session) the counts
of checked answers, and per child the teaching measures of
kasparctl.research.children.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

from kasparctl.game.records import PressRecord, PromptRecord, TrialRecord, UndoRecord
from kasparctl.learning.learner import LearnerParams
from kasparctl.learning.session_stats import ProblemBuilder
from kasparctl.learning.study_stats import ProblemRecord, StudyStats, summarise
from kasparctl.research.catalogue import SessionData
from kasparctl.research.children import Children, Feedback, in_question
from kasparctl.research.progress import progress
from kasparctl.research.walk import AFTER_WRONG_FEEDBACK, EXPLORATORY, walk

# What a cluster is: the group of children (the paper's unit: groups came back for
# more sessions), or the session.
CLUSTER_UNITS = ("group", "session")


@dataclass(frozen=True, slots=True)
class Factors:
    """What makes a condition: the learner profile, the uncertainty mode, the game."""

    profile: str
    uncertainty: str  # spoken, body, both or none
    variant: str


@dataclass(frozen=True, slots=True)
class Problem:
    """One problem, the toy names its indices refer to (sessions may differ), and its cluster."""

    toys: tuple[str, ...]
    record: ProblemRecord
    cluster: str = ""

    @property
    def answer(self) -> str | None:
        """The right toy's name, where the plan had an answer key."""
        return None if self.record.answer is None else self.toys[self.record.answer]


@dataclass
class Condition:
    """The sessions of one condition, their problems, and answers checked per cluster."""

    label: str
    factors: Factors | None = None
    sessions: list[SessionData] = field(default_factory=list)
    problems: list[Problem] = field(default_factory=list)
    feedback_by_cluster: dict[str, Feedback] = field(default_factory=dict)
    # By place in the turn order (child 1, 2...), over every session: the plan's own view.
    feedback_by_position: dict[int, Feedback] = field(default_factory=dict)
    undone: int = 0
    # Seconds from each counted question's end to its answer, for answers after the
    # question (research.children.in_question: those in its last words are counted apart);
    # prompts while guessing.
    reaction_times: list[float] = field(default_factory=list)
    answers_in_question: int = 0
    prompts: int = 0

    @cached_property
    def stats(self) -> StudyStats:
        """The paper's statistics over this condition's problems."""
        # The paper's statistics, computed by the simulator's own code.
        return summarise([problem.record for problem in self.problems])

    @property
    def feedback(self) -> Feedback:
        """Every answer of the condition checked against the answer key."""
        total = Feedback()
        for counts in self.feedback_by_cluster.values():
            total.merge(counts)
        return total

    @property
    def clusters(self) -> list[str]:
        """The clusters with problems, in the order first seen."""
        return list(dict.fromkeys(p.cluster for p in self.problems))


def learner_key(session: SessionData) -> tuple[float, ...] | None:
    """The learner's parameters frozen in the session's plan.json, as a key; None if none."""
    params = session.learner_params()
    return None if params is None else tuple(getattr(params, f) for f in _LEARNER_KEYS)


_LEARNER_KEYS = ("alpha", "beta", "gamma", "reward_green", "reward_red", "initial_q")


def learner_split(sessions: Sequence[SessionData]) -> dict[str, str]:
    """Session uid -> the learner's mark in its condition's label, for profiles whose
    sessions were recorded with different parameters under one name (a profile redefined
    between sessions): those are different learners and are not pooled. "" for the rest."""
    by_profile: dict[str, set[tuple[float, ...] | None]] = {}
    for session in sessions:
        by_profile.setdefault(session.profile, set()).add(learner_key(session))
    marks: dict[str, str] = {}
    for session in sessions:
        key = learner_key(session)
        if len(by_profile[session.profile]) < 2:
            marks[session.uid] = ""
        elif key is None:
            marks[session.uid] = " [learner not recorded]"
        else:
            marks[session.uid] = f" [alpha {key[0]:g}, beta {key[1]:g}]" + (
                "" if key[2:] == (0.0, 1.0, -1.0, 0.0) else " [other rewards]"
            )
    return marks


def condition_labels(sessions: Sequence[SessionData]) -> list[str]:
    """Each session's condition label; with the variant when the sessions mix variants,
    and with the learner's parameters when one profile name had several."""
    mixed = len({session.variant for session in sessions}) > 1
    marks = learner_split(sessions)
    labels = []
    for session in sessions:
        profile, _, mode = session.condition.partition("/")
        label = f"{profile}{marks[session.uid]}/{mode}" if marks[session.uid] else session.condition
        labels.append(f"{label} ({session.variant})" if mixed else label)
    return labels


def cluster_of(session: SessionData, unit: str) -> str:
    """The key of the cluster a session's problems belong to."""
    return session.uid if unit == "session" else f"group {session.group}"


def by_condition(
    sessions: Sequence[SessionData],
    params: Callable[[str], LearnerParams],
    children: Children | None = None,
    cluster_unit: str = "group",
) -> list[Condition]:
    """One Condition per label, sorted by label; `params` maps a profile name to its values.

    `children`, if given, gets every child's teaching measures from the same pass. A group
    marked absent (kasparctl.game.opening.PlanQueue) is left out.
    """
    conditions: dict[str, Condition] = {}
    # A group marked absent was never taught: no session of any condition.
    sessions = [session for session in sessions if session.index.absent is None]
    labelled = list(zip(sessions, condition_labels(sessions), strict=True))
    marks = learner_split(sessions)
    for index, (session, label) in enumerate(progress(labelled, "reading records", "session")):
        profile = session.profile + marks[session.uid]
        condition = conditions.setdefault(
            label,
            Condition(label, Factors(profile, session.uncertainty, session.variant)),
        )
        condition.sessions.append(session)
        _collect(session, index, condition, params, children, cluster_of(session, cluster_unit))
    return [conditions[label] for label in sorted(conditions)]


def _collect(
    session: SessionData,
    index: int,
    condition: Condition,
    params: Callable[[str], LearnerParams],
    children: Children | None,
    cluster: str,
) -> None:
    toys = session.toys
    # The learner the session really had (frozen in plan.json); the configuration's
    # profile only for sessions recorded before it was frozen.
    learner = session.learner_params() or params(session.profile)
    builder = ProblemBuilder(toys, session.answer_key, learner, group=index)
    feedback = condition.feedback_by_cluster.setdefault(cluster, Feedback())
    ended_with = None
    for walked in walk(session):
        ended_with = walked.facts
        record, child = walked.record, walked.child_index
        if isinstance(record, TrialRecord):
            if walked.undone:
                condition.undone += 1
                continue
            if len(record.q_after) != len(toys):
                continue  # damage the index warned about
            guess = walked.guess
            if guess is None:
                builder.add(record)
            else:
                # The flags and their cause as the fold reads them: the CSV's columns.
                cause = {AFTER_WRONG_FEEDBACK: True, EXPLORATORY: False}.get(guess.cause or "")
                builder.add(record, (guess.perseverative, guess.win_shift), cause)
            feedback.add(record)
            if in_question(record):
                condition.answers_in_question += 1
            else:
                condition.reaction_times.append(record.reaction_time)
            condition.feedback_by_position.setdefault(record.child_index + 1, Feedback()).add(
                record
            )
            if children is not None:
                children.child(session, record.child_index, condition.label).answer(record)
        elif child is not None and isinstance(record, PromptRecord):
            condition.prompts += 1  # a prompt while guessing (whose turn it was)
            if children is not None:
                children.child(session, child, condition.label).prompts += 1
        elif children is not None and child is not None:
            measures = children.child(session, child, condition.label)
            if isinstance(record, PressRecord):
                measures.extra_presses += 1
            elif isinstance(record, UndoRecord):
                measures.undos += 1
    learned = None if ended_with is None else ended_with.learned
    condition.problems.extend(
        Problem(toys, record, cluster) for record in builder.problems(learned)
    )


def pooled(conditions: Sequence[Condition], label: str = "all") -> Condition:
    """Every session in one: the "all" column beside the conditions."""
    everything = Condition(label)
    for condition in conditions:
        everything.sessions.extend(condition.sessions)
        everything.problems.extend(condition.problems)
        everything.undone += condition.undone
        everything.reaction_times.extend(condition.reaction_times)
        everything.answers_in_question += condition.answers_in_question
        everything.prompts += condition.prompts
        for cluster, counts in condition.feedback_by_cluster.items():
            everything.feedback_by_cluster.setdefault(cluster, Feedback()).merge(counts)
        for position, counts in condition.feedback_by_position.items():
            everything.feedback_by_position.setdefault(position, Feedback()).merge(counts)
    return everything


def by_uncertainty(conditions: Sequence[Condition]) -> list[Condition]:
    """The conditions pooled by uncertainty mode (across profiles and variants), in
    MODE_ORDER: spoken, body, both, none; each labelled by its mode."""
    modes: dict[str, list[Condition]] = {}
    for condition in conditions:
        mode = condition.factors.uncertainty if condition.factors else "unknown"
        modes.setdefault(mode, []).append(condition)
    order = [mode for mode in MODE_ORDER if mode in modes] + sorted(set(modes) - set(MODE_ORDER))
    return [pooled(modes[mode], mode) for mode in order]


# The uncertainty modes in the report's order.
MODE_ORDER = ("spoken", "body", "both", "none")
