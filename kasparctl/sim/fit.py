"""How well a model of the study reproduces a cohort's figures: parametric bootstrap.

A cohort (the paper's pilot, or recorded sessions) is one study of n groups.
The model (a learner, a game, a teacher) is simulated as many studies of the
same n groups (kasparctl.sim.studies); each of the cohort's figures is then
placed among the simulated studies' values:

- percentile: the share of simulated studies below the cohort's value (ties
  count half), so 50 % is typical and 1 % or 99 % is rare;
- p: two-sided, 2 x min(P(X <= x), P(X >= x)), capped at 1, with the usual
  +1 in numerator and denominator so a Monte Carlo p is never 0;
- a joint p for trials to learn, mean and sd together: the share of simulated
  studies whose (mean, sd) is as far or farther from the model's centre, by
  Mahalanobis distance, as the cohort's;
- for the paper's puzzle, the share of simulated studies with a final entropy
  at least the cohort's and at most its number of win-shifts.

The paper's readings (`READINGS`) are the ways of reading its text that this
module compares; docs/simulation.md gives the table and the command.

The cohort's children are modelled here too (`fitted_teacher`): one child per
place in the turn order, from what the children at that place did
(kasparctl.research.cohort counts it; this room never sees a session).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import msgspec
import numpy as np
from numpy.typing import NDArray

from kasparctl.config import GameSettings
from kasparctl.learning.learner import LearnerParams
from kasparctl.sim.simulate import pilot_game, playable
from kasparctl.sim.studies import GroupTable, simulate_groups, study_values
from kasparctl.sim.teacher import ChildTeacher, Teacher, TeacherModel, load_teacher, teacher_toml

FloatArray = NDArray[np.float64]

# The pilot study's figures (section IV): 16 groups, 3 locations each.
PAPER = {
    "problems": 48,
    "trials_total": 202,
    "trials_mean": 4.21,
    "trials_sd": 1.46,
    "trials_min": 2,
    "trials_max": 7,
    "problems_given_up": 0,
    "problems_learned_wrong": 0,
    "first_guess_correct": 7,
    "groups_first_right_twice": 0,
    "perseverative_errors": 1,
    "win_shifts": 1,
    "initial_entropy": 2.585,
    "final_entropy_mean": 0.73,
    "final_entropy_sd": 0.58,
}
# The same figures as a study's statistics (kasparctl.learning.study_stats.StudyStats names),
# with the rates they give: what `kasparctl simulate` prints beside its own.
PAPER_STATS = {
    **PAPER,
    "first_guess_correct_rate": PAPER["first_guess_correct"] / PAPER["problems"],
    "perseverative_error_rate": PAPER["perseverative_errors"] / PAPER["trials_total"],
    "win_shift_rate": PAPER["win_shifts"] / PAPER["trials_total"],
}
PAPER_GROUPS = 16
# The pilot's children: 3 greens for a wrong guess (no other mistake) in 202 trials, of which
# about 106 were wrong guesses (202 less the two confirming greens of each of 48 problems).
PAPER_WRONG_GREENS = 3
PILOT_TEACHER = Teacher(
    p_wrong_green=PAPER_WRONG_GREENS / (PAPER["trials_total"] - 2 * PAPER["problems"])
)
# The figures placed among the simulated studies, with the words the tables use.
FIGURES = {
    "trials_total": "trials",
    "trials_mean": "trials to learn, mean",
    "trials_sd": "trials to learn, sd",
    "trials_max": "trials to learn, max",
    "first_guess_correct": "first guess right (problems)",
    "groups_first_right_twice": "groups with two first guesses right",
    "perseverative_errors": "perseverative errors",
    "win_shifts": "win-shifts",
    "final_entropy_mean": "final entropy, mean",
    "final_entropy_sd": "final entropy, sd",
}


@dataclass(frozen=True)
class Reading:
    """One way of reading the paper's text as a game and a learner."""

    name: str
    # Why the text allows it.
    reason: str
    exclude_learned: str = "names"
    initial_q: float = 0.0
    reward_red: float = -1.0

    def game(self) -> GameSettings:
        """The pilot as this reading plays it."""
        return pilot_game(exclude_learned_rule=self.exclude_learned)

    def params(self, base: LearnerParams | None = None) -> LearnerParams:
        """The paper's learner (alpha 0.6, beta 8) as this reading initialises and rewards it."""
        return dataclasses.replace(
            base or LearnerParams(), initial_q=self.initial_q, reward_red=self.reward_red
        )


READINGS = (
    Reading(
        "project",
        "kasparctl's default: each location a problem over all 6 toys (Fig. 2: every "
        f"problem starts at log2 6 = {PAPER['initial_entropy']} bits), Q0 = 0, rewards +1/-1, "
        "two greens in a row",
    ),
    Reading(
        "elimination",
        "section II's rule, 'as Kaspar gets each animal correct this should be eliminated "
        "from the list', applied across the pilot's 3 locations (6, 5, then 4 toys)",
        exclude_learned="always",
    ),
    Reading(
        "optimistic Q0",
        "Algorithm 1's 'Initialize Q0(s, a)' with Q0 = 0.5 (any constant still starts at "
        f"{PAPER['initial_entropy']} bits): the reading that reproduces the final entropy",
        initial_q=0.5,
    ),
    Reading(
        "elimination, optimistic Q0",
        "both of the above",
        exclude_learned="always",
        initial_q=0.5,
    ),
    Reading(
        "red is no reward",
        "'positive or negative reinforcement' read as green +1 and red 0",
        reward_red=0.0,
    ),
)


def simulate_studies(
    studies: int,
    groups_per_study: int,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    seed: int | None,
) -> dict[str, FloatArray]:
    """The figures of `studies` simulated studies of `groups_per_study` groups each."""
    rng = np.random.default_rng(seed)
    values: dict[str, list[FloatArray]] = {}
    groups = studies * groups_per_study
    # Whole studies per chunk, so no study straddles two tables.
    chunk = max(groups_per_study, (1 << 15) // groups_per_study * groups_per_study)
    for table in simulate_groups(groups, game, params, teacher, rng, chunk_groups=chunk):
        for name, column in _study_figures(table, groups_per_study).items():
            values.setdefault(name, []).append(column)
    return {name: np.concatenate(columns) for name, columns in values.items()}


def _study_figures(table: GroupTable, groups_per_study: int) -> dict[str, FloatArray]:
    figures = study_values(table, groups_per_study)
    studies = table.groups // groups_per_study
    used = studies * groups_per_study
    twice = table.first_correct[:used].sum(axis=1) >= 2
    figures["groups_first_right_twice"] = (
        twice.reshape(studies, groups_per_study).sum(axis=1).astype(np.float64)
    )
    return figures


@dataclass(frozen=True)
class Placed:
    """A cohort's figure among the simulated studies' values."""

    figure: str
    cohort: float
    median: float
    low: float  # 2.5th percentile
    high: float  # 97.5th percentile
    percentile: float  # 0 to 100
    p: float

    def plain(self) -> dict[str, float | str]:
        """As JSON-ready data."""
        return dataclasses.asdict(self)


def place(figure: str, cohort: float, simulated: FloatArray) -> Placed | None:
    """The cohort's value among the simulated ones (None if none of them has the figure)."""
    values = simulated[np.isfinite(simulated)]
    if len(values) == 0 or not math.isfinite(cohort):
        return None
    n = len(values)
    below = int((values < cohort).sum())
    equal = int((values == cohort).sum())
    at_most, at_least = below + equal, n - below
    p = min(1.0, 2 * min((at_most + 1) / (n + 1), (at_least + 1) / (n + 1)))
    low, median, high = np.percentile(values, [2.5, 50, 97.5])
    return Placed(
        figure,
        cohort,
        float(median),
        float(low),
        float(high),
        100.0 * (below + 0.5 * equal) / n,
        p,
    )


def joint_trials_p(cohort: dict[str, float], simulated: dict[str, FloatArray]) -> float | None:
    """The share of simulated studies whose (mean, sd) of trials to learn is as unusual."""
    x = np.column_stack([simulated["trials_mean"], simulated["trials_sd"]])
    x = x[np.isfinite(x).all(axis=1)]
    if len(x) < 3:
        return None
    centre = x.mean(axis=0)
    covariance = np.cov(x.T)
    if np.linalg.matrix_rank(covariance) < 2:
        return None
    inverse = np.linalg.inv(covariance)
    offsets = x - centre
    distances = np.einsum("ij,jk,ik->i", offsets, inverse, offsets)
    point = np.array([cohort["trials_mean"], cohort["trials_sd"]]) - centre
    mine = float(point @ inverse @ point)
    return (int((distances >= mine).sum()) + 1) / (len(x) + 1)


def entropy_with_win_shifts_p(cohort: dict[str, float], simulated: dict[str, FloatArray]) -> float:
    """The share of simulated studies with a final entropy >= the cohort's and win-shifts <= its."""
    both = (simulated["final_entropy_mean"] >= cohort["final_entropy_mean"]) & (
        simulated["win_shifts"] <= cohort["win_shifts"]
    )
    return (int(both.sum()) + 1) / (len(both) + 1)


@dataclass(frozen=True)
class Fit:
    """A model's fit to a cohort: every figure placed, and the joint p-values."""

    name: str
    placed: list[Placed]
    joint_trials_p: float | None
    entropy_with_win_shifts_p: float | None
    studies: int
    groups_per_study: int

    def plain(self) -> dict[str, object]:
        """As JSON-ready data."""
        return {
            "name": self.name,
            "studies": self.studies,
            "groups_per_study": self.groups_per_study,
            "joint_trials_p": self.joint_trials_p,
            "entropy_with_win_shifts_p": self.entropy_with_win_shifts_p,
            "figures": [p.plain() for p in self.placed],
        }


def fit(
    name: str,
    cohort: dict[str, float],
    simulated: dict[str, FloatArray],
    groups_per_study: int,
) -> Fit:
    """Place each of the cohort's figures among the simulated studies."""
    placed = [
        found
        for figure in FIGURES
        if figure in cohort and figure in simulated
        for found in [place(figure, float(cohort[figure]), simulated[figure])]
        if found is not None
    ]
    joint = (
        joint_trials_p(cohort, simulated) if {"trials_mean", "trials_sd"} <= set(cohort) else None
    )
    entropy = (
        entropy_with_win_shifts_p(cohort, simulated)
        if {"final_entropy_mean", "win_shifts"} <= set(cohort)
        else None
    )
    studies = len(next(iter(simulated.values())))
    return Fit(name, placed, joint, entropy, studies, groups_per_study)


def fit_readings(
    studies: int,
    seed: int | None,
    readings: Sequence[Reading] = READINGS,
    on_reading: Callable[[Reading], None] | None = None,
) -> list[tuple[Reading, Fit]]:
    """Each reading of the paper fitted to its pilot (16 groups of children as its were).

    The children make the pilot's mistakes at its rate (PILOT_TEACHER).
    """
    teacher = PILOT_TEACHER
    results = []
    for reading in readings:
        if on_reading is not None:
            on_reading(reading)
        simulated = simulate_studies(
            studies, PAPER_GROUPS, reading.game(), reading.params(), teacher, seed
        )
        results.append((reading, fit(reading.name, PAPER, simulated, PAPER_GROUPS)))
    return results


# -- the cohort: its game, its children, its fit -------------------------------------------


class PlaceTally(Protocol):
    """What the children at one place in the turn order did, over every session."""

    @property
    def answers(self) -> int:
        """Answers that count (none undone)."""
    @property
    def wrong_guesses(self) -> int:
        """Wrong guesses answered, in sessions with an answer key."""
    @property
    def false_greens(self) -> int:
        """Greens for a wrong guess."""
    @property
    def right_guesses(self) -> int:
        """Right guesses answered, in sessions with an answer key."""
    @property
    def false_reds(self) -> int:
        """Reds for a right guess."""
    @property
    def prompted(self) -> int:
        """Questions that needed at least one prompt."""
    @property
    def reaction_times(self) -> Sequence[float]:
        """Seconds from each question to its answer."""


class CohortFigures(Protocol):
    """Recorded sessions of one condition as a study (kasparctl.research.cohort.Cohort)."""

    @property
    def label(self) -> str:
        """The condition's label."""
    @property
    def sessions(self) -> int:
        """Its sessions, each a group of children."""
    @property
    def variant(self) -> str:
        """The game variant played."""
    @property
    def toys(self) -> tuple[str, ...]:
        """The toys, in the game's order."""
    @property
    def targets(self) -> int:
        """Targets (locations or bags) per session."""
    @property
    def figures(self) -> Mapping[str, float]:
        """Its figures by FIGURES' names."""


def fitted_teacher(places: Sequence[PlaceTally], sessions: int) -> TeacherModel:
    """The children of `sessions` recorded sessions: one ChildTeacher fitted per place.

    Without a single answer to fit, every child is honest.
    """
    if not places:
        return TeacherModel.of(Teacher())
    children = tuple(
        ChildTeacher.fitted(
            p.answers,
            p.wrong_guesses,
            p.false_greens,
            p.right_guesses,
            p.false_reds,
            p.prompted,
            p.reaction_times,
        )
        for p in places
    )
    return TeacherModel(children, f"fitted from {sessions} sessions")


def fitted_teacher_file(
    model: TeacherModel, sessions: int, keyed: int, groups: Sequence[str]
) -> str:
    """The fitted model as the TOML file `kasparctl fit-teacher` writes, saying what it is."""
    comment = "\n".join(
        [
            "kasparctl teacher model, written by `kasparctl fit-teacher`.",
            f"From {sessions} sessions ({keyed} with an answer key); groups: "
            + ", ".join(sorted(set(groups))),
            "One [[children]] table per place in the turn order (the first child first).",
            "p_wrong_green: greens for a wrong guess / wrong guesses answered;",
            "p_wrong_red: reds for a right guess / right guesses answered;",
            "p_prompt: questions that needed a prompt / questions;",
            "reaction_time_median (s) and reaction_time_log_sd: a log-normal;",
            "answers: how many answers each child's rates rest on.",
        ]
    )
    return teacher_toml(model, comment)


def chosen_teacher(choice: str | None) -> Teacher | TeacherModel | None:
    """--teacher FILE|honest: a model file's children, honest ones, or None when not given."""
    if choice is None:
        return None
    return Teacher() if choice == "honest" else load_teacher(choice)


def cohort_game(
    cohort: CohortFigures, configured: GameSettings | None, rule: str | None
) -> GameSettings:
    """The cohort's game: its variant, toys and targets; the rest from the configuration."""
    base = configured or GameSettings()
    rule = rule or base.exclude_learned_rule
    if cohort.variant == "pilot":
        locations = tuple(f"location {i + 1}" for i in range(max(cohort.targets, 1)))
        game = msgspec.structs.replace(
            base, variant="pilot", toys=cohort.toys, locations=locations, poses={}
        )
    else:
        game = msgspec.structs.replace(
            base, variant="names", toys=cohort.toys, locations=(), poses={}
        )
    return playable(msgspec.structs.replace(game, exclude_learned_rule=rule))


def fit_cohort(
    cohort: CohortFigures,
    game: GameSettings,
    profile: str,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    studies: int,
    seed: int | None,
) -> tuple[str, Fit]:
    """The cohort's figures among `studies` simulated studies of its size; with their label."""
    simulated = simulate_studies(studies, cohort.sessions, game, params, teacher, seed)
    label = (
        f"{cohort.label}: {cohort.sessions} sessions vs {profile}, {game.variant}, "
        f"exclude_learned {game.exclude_learned_rule}"
    )
    return label, fit(cohort.label, dict(cohort.figures), simulated, cohort.sessions)


def fit_paper(
    profile: str,
    params: LearnerParams,
    rule: str,
    teacher: Teacher | TeacherModel | None,
    studies: int,
    seed: int | None,
) -> tuple[str, Fit]:
    """The paper's pilot among studies of 16 groups (its children: PILOT_TEACHER by default)."""
    game = pilot_game(exclude_learned_rule=rule)
    chosen = PILOT_TEACHER if teacher is None else teacher
    simulated = simulate_studies(studies, PAPER_GROUPS, game, params, chosen, seed)
    label = f"the paper's pilot vs {profile}, exclude_learned {rule}"
    return label, fit("paper", PAPER, simulated, PAPER_GROUPS)
