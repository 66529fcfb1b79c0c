"""Many whole groups at once: the vectorised simulator of studies, for fits and power.

Every group plays its targets in order, as the game does (kasparctl.sim.simulate
is the scalar reference, one guess at a time): the groups of a chunk advance
together, one guess per step, as rows of numpy arrays, finished rows dropped.
Between targets a learned label is withdrawn from the group's later targets
when the game says so (GameSettings.exclude_learned: the names game, or the
pilot under `exclude_learned = "always"`). Children answer in turn, each with
their own rates when the teacher model has several children
(kasparctl.sim.teacher.TeacherModel).

Results come per group and target (GroupTable), so a study of n groups is a
block of n rows: `study_values` turns blocks into the paper's figures, one
value per simulated study. Chunks bound the memory (about 1 kB per group in
flight), and the tables of a long run can be reduced as they come.

Its random stream is its own: statistics agree with the scalar simulator, not
draw for draw (the tests hold the two together).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from kasparctl.config import GameSettings
from kasparctl.learning.learner import (
    LearnerParams,
    choose_batch,
    entropy_bits_batch,
    softmax_batch,
)
from kasparctl.learning.study_stats import ProblemTable
from kasparctl.sim.simulate import SimulationError, playable
from kasparctl.sim.teacher import Teacher, TeacherModel

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

CHUNK_GROUPS = 1 << 15


@dataclass(frozen=True)
class GroupTable:
    """Per group (rows) and target (columns), what each problem came to."""

    trials: IntArray
    learned: IntArray  # the label learned, -1 if given up
    answer: IntArray
    candidates: IntArray  # labels offered
    first_correct: BoolArray
    perseverative: IntArray
    win_shift: IntArray
    perseverative_after_wrong: IntArray
    win_shift_after_wrong: IntArray
    initial_entropy: FloatArray
    final_entropy: FloatArray
    final_entropy_after: FloatArray
    wrong_green: IntArray
    wrong_red: IntArray
    wrong_guesses: IntArray  # wrong guesses that were answered
    right_guesses: IntArray
    unanswered: IntArray
    # Over every problem of the table: the sum and count of the entropies before guess k+1.
    entropy_sum: FloatArray
    entropy_count: IntArray

    @property
    def groups(self) -> int:
        """How many groups (rows)."""
        return int(self.trials.shape[0])

    def rows(self, start: int, stop: int) -> GroupTable:
        """Groups start..stop-1 (entropy by trial is over the whole table)."""
        values = {
            f.name: getattr(self, f.name)[start:stop]
            for f in fields(self)
            if f.name not in ("entropy_sum", "entropy_count")
        }
        return GroupTable(**values, entropy_sum=self.entropy_sum, entropy_count=self.entropy_count)

    def problem_table(self) -> ProblemTable:
        """Every problem as one row of the statistics' table (kasparctl.learning.study_stats)."""
        learned = self.learned.ravel()
        perseverative = self.perseverative.ravel()
        win_shift = self.win_shift.ravel()
        return ProblemTable(
            trials=self.trials.ravel(),
            learned=learned >= 0,
            learned_wrong=(learned >= 0) & (learned != self.answer.ravel()),
            answer_known=np.ones(learned.shape, dtype=bool),
            first_correct=self.first_correct.ravel(),
            perseverative=perseverative,
            win_shift=win_shift,
            initial_entropy=self.initial_entropy.ravel(),
            final_entropy=self.final_entropy.ravel(),
            final_entropy_after=self.final_entropy_after.ravel(),
            entropy_sum_by_trial=self.entropy_sum,
            entropy_count_by_trial=self.entropy_count,
            perseverative_after_wrong=self.perseverative_after_wrong.ravel(),
            win_shift_after_wrong=self.win_shift_after_wrong.ravel(),
            perseverative_exploratory=perseverative - self.perseverative_after_wrong.ravel(),
            win_shift_exploratory=win_shift - self.win_shift_after_wrong.ravel(),
        )


def concatenate(tables: list[GroupTable]) -> GroupTable:
    """The groups of several tables, in order, as one."""
    if len(tables) == 1:
        return tables[0]
    longest = max(len(t.entropy_sum) for t in tables)
    entropy_sum = np.zeros(longest)
    entropy_count = np.zeros(longest, dtype=np.int64)
    for table in tables:
        entropy_sum[: len(table.entropy_sum)] += table.entropy_sum
        entropy_count[: len(table.entropy_count)] += table.entropy_count
    values = {
        f.name: np.concatenate([getattr(t, f.name) for t in tables])
        for f in fields(GroupTable)
        if f.name not in ("entropy_sum", "entropy_count")
    }
    return GroupTable(**values, entropy_sum=entropy_sum, entropy_count=entropy_count)


def draw_answers(game: GameSettings, groups: int, rng: np.random.Generator) -> IntArray:
    """Each group's right label per target: a shuffle of the toys, or distinct ones per location."""
    n_toys, n_targets = len(game.toys), len(game.targets)
    if n_targets <= n_toys:
        shuffled: IntArray = rng.permuted(
            np.tile(np.arange(n_toys, dtype=np.int64), (groups, 1)), axis=1
        )
        return shuffled[:, :n_targets]
    drawn: IntArray = rng.integers(n_toys, size=(groups, n_targets), dtype=np.int64)
    return drawn


def simulate_groups(
    groups: int,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    rng: np.random.Generator,
    chunk_groups: int = CHUNK_GROUPS,
) -> Iterator[GroupTable]:
    """`groups` groups playing `game`, a chunk at a time (each chunk one GroupTable)."""
    if groups < 1:
        raise SimulationError(f"groups: expected >= 1, found {groups}")
    game = playable(game)
    model = teacher if isinstance(teacher, TeacherModel) else TeacherModel.of(teacher)
    for start in range(0, groups, chunk_groups):
        yield _Chunk(min(chunk_groups, groups - start), game, params, model, rng).run()


class _Chunk:
    """The groups of one chunk, target after target."""

    def __init__(
        self,
        groups: int,
        game: GameSettings,
        params: LearnerParams,
        model: TeacherModel,
        rng: np.random.Generator,
    ) -> None:
        self.groups, self.game, self.params, self.model, self.rng = groups, game, params, model, rng
        self.n_targets, self.n_toys = len(game.targets), len(game.toys)
        self.answers = draw_answers(game, groups, rng)
        shape = (groups, self.n_targets)
        self.out: dict[str, NDArray[np.generic]] = {
            f.name: np.zeros(shape, dtype=np.float64 if "entropy" in f.name else np.int64)
            for f in fields(GroupTable)
            if f.name not in ("entropy_sum", "entropy_count", "first_correct")
        }
        self.out["first_correct"] = np.zeros(shape, dtype=bool)
        self.out["answer"] = self.answers
        self.out["learned"][:] = -1
        self.entropy_sum = np.zeros(game.max_trials_per_target)
        self.entropy_count = np.zeros(game.max_trials_per_target, dtype=np.int64)
        # Children answer in rotation over the whole session, as the game counts turns.
        self.turn = np.zeros(groups, dtype=np.int64)
        self.offered = np.ones((groups, self.n_toys), dtype=bool)
        self.beta = np.full(groups, params.beta)
        self.rates = model.rates()

    def run(self) -> GroupTable:
        for target in range(self.n_targets):
            self._problem(target)
        values = {name: self.out[name] for name in self.out}
        return GroupTable(
            **values,  # type: ignore[arg-type]
            entropy_sum=self.entropy_sum,
            entropy_count=self.entropy_count,
        )

    def _problem(self, target: int) -> None:
        params, game, out = self.params, self.game, self.out
        g = self.groups
        rows = np.arange(g)
        q = np.full((g, self.n_toys), params.initial_q)
        candidates = self.offered.copy()
        out["candidates"][:, target] = candidates.sum(axis=1)
        answer = self.answers[:, target]
        streak = np.zeros(g, dtype=np.int64)
        streak_label = np.full(g, -1, dtype=np.int64)
        previous_choice = np.full(g, -1, dtype=np.int64)
        previous_feedback = np.zeros(g, dtype=np.int8)
        previous_wrong = np.zeros(g, dtype=bool)
        last_target = target == self.n_targets - 1
        for trial in range(game.max_trials_per_target):
            if len(rows) == 0:
                break
            probabilities = softmax_batch(q[rows], self.beta[rows], candidates[rows])
            entropy = entropy_bits_batch(probabilities)
            choice = choose_batch(probabilities, self.rng).astype(np.int64)
            correct = choice == answer[rows]
            feedback = self._answers(correct, self.turn[rows])
            self.turn[rows] += 1
            self.entropy_sum[trial] += entropy.sum()
            self.entropy_count[trial] += len(rows)
            if trial == 0:
                out["initial_entropy"][rows, target] = entropy
                out["first_correct"][rows, target] = correct
            else:
                perseverative = (previous_feedback[rows] == -1) & (choice == previous_choice[rows])
                win_shift = (previous_feedback[rows] == 1) & (choice != previous_choice[rows])
                out["perseverative"][rows, target] += perseverative
                out["win_shift"][rows, target] += win_shift
                out["perseverative_after_wrong"][rows, target] += (
                    perseverative & previous_wrong[rows]
                )
                out["win_shift_after_wrong"][rows, target] += win_shift & previous_wrong[rows]
            green, red = feedback == 1, feedback == -1
            out["wrong_green"][rows, target] += green & ~correct
            out["wrong_red"][rows, target] += red & correct
            out["wrong_guesses"][rows, target] += (feedback != 0) & ~correct
            out["right_guesses"][rows, target] += (feedback != 0) & correct
            out["unanswered"][rows, target] += feedback == 0
            same = green & (choice == streak_label[rows])
            streak[rows] = np.where(same, streak[rows] + 1, np.where(green, 1, 0))
            streak_label[rows] = np.where(green, choice, -1)
            learned = streak[rows] >= game.correct_answers_to_learn
            done = learned | (trial + 1 >= game.max_trials_per_target)
            answered = feedback != 0
            if answered.any():
                who, action = rows[answered], choice[answered]
                reward = np.where(green[answered], params.reward_green, params.reward_red)
                q_sa = q[who, action]
                next_max: FloatArray | float = 0.0
                if params.gamma != 0.0:
                    # s_{t+1} as the scalar simulator has it: this target until done, then the
                    # next (untouched) one, nothing after the last.
                    fresh = 0.0 if last_target else params.initial_q
                    next_max = np.where(done[answered], fresh, q[who].max(axis=1))
                q[who, action] = q_sa + params.alpha * (reward + params.gamma * next_max - q_sa)
            previous_choice[rows] = choice
            previous_feedback[rows] = feedback
            previous_wrong[rows] = (green & ~correct) | (red & correct)
            if done.any():
                finished = rows[done]
                after = entropy_bits_batch(
                    softmax_batch(q[finished], self.beta[finished], candidates[finished])
                )
                out["trials"][finished, target] = trial + 1
                out["learned"][finished, target] = np.where(learned[done], choice[done], -1)
                out["final_entropy"][finished, target] = entropy[done]
                out["final_entropy_after"][finished, target] = after
                rows = rows[~done]
        if self.game.exclude_learned:
            learned_label = out["learned"][:, target].astype(np.int64)
            won = np.flatnonzero(learned_label >= 0)
            self.offered[won, learned_label[won]] = False

    def _answers(self, correct: BoolArray, turn: IntArray) -> NDArray[np.int8]:
        """+1 green, -1 red, 0 no answer: each child with its own rates, two draws a guess."""
        honest = np.where(correct, 1, -1).astype(np.int8)
        rates = self.rates
        if rates.honest:
            return honest
        child = turn % rates.children
        draws = self.rng.random((len(correct), 2))
        p_mistake = np.where(correct, rates.p_wrong_red[child], rates.p_wrong_green[child])
        given = np.where(draws[:, 1] < p_mistake, -honest, honest).astype(np.int8)
        return np.where(draws[:, 0] < rates.p_no_answer[child], 0, given).astype(np.int8)


# -- one value per simulated study ---------------------------------------------------

STUDY_FIGURES = (
    "trials_total",
    "trials_mean",
    "trials_sd",
    "trials_min",
    "trials_max",
    "problems_given_up",
    "first_guess_correct",
    "perseverative_errors",
    "win_shifts",
    "final_entropy_mean",
    "final_entropy_sd",
)


def study_values(table: GroupTable, groups_per_study: int) -> dict[str, FloatArray]:
    """The paper's figures of each study: consecutive blocks of `groups_per_study` groups.

    Groups left over after the last whole block are not used.
    """
    studies = table.groups // groups_per_study
    if studies == 0:
        raise SimulationError(
            f"a study of {groups_per_study} groups needs that many, found {table.groups}"
        )
    used = studies * groups_per_study

    def block(values: NDArray[np.generic]) -> NDArray[np.generic]:
        return values[:used].reshape(studies, -1)

    trials = block(table.trials).astype(np.float64)
    learned = block(table.learned).astype(np.int64) >= 0
    count = learned.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        trials_learned = np.where(learned, trials, np.nan)
        mean = np.nanmean(trials_learned, axis=1) if learned.any() else np.full(studies, np.nan)
        sd = np.where(count > 1, np.nanstd(trials_learned, axis=1, ddof=1), np.nan)
        final = np.where(learned, block(table.final_entropy), np.nan)
        final_mean = np.nanmean(final, axis=1)
        final_sd = np.where(count > 1, np.nanstd(final, axis=1, ddof=1), np.nan)
    return {
        "trials_total": trials.sum(axis=1),
        "trials_mean": mean,
        "trials_sd": sd,
        "trials_min": np.where(learned, trials, np.inf).min(axis=1),
        "trials_max": np.where(learned, trials, -np.inf).max(axis=1),
        "problems_given_up": (~learned).sum(axis=1).astype(np.float64),
        "first_guess_correct": block(table.first_correct).sum(axis=1).astype(np.float64),
        "perseverative_errors": block(table.perseverative).sum(axis=1).astype(np.float64),
        "win_shifts": block(table.win_shift).sum(axis=1).astype(np.float64),
        "final_entropy_mean": final_mean,
        "final_entropy_sd": final_sd,
    }


# What a group contributes to a measure: its own value (numerator over denominator).
GROUP_MEASURES = {
    "trials_mean": "mean trials to learn over its learned problems",
    "problems_learned_rate": "share of its problems learned",
    "first_guess_correct_rate": "share of its problems whose first guess was right",
    "perseverative_error_rate": "perseverative errors per trial",
    "win_shift_rate": "win-shifts per trial",
    "final_entropy_mean": "mean entropy before the last guess of its learned problems",
    "wrong_feedback_rate": "wrong answers of the children per answer",
}


def group_values(table: GroupTable, measure: str) -> FloatArray:
    """One value per group (NaN where it has none): the unit a comparison of groups tests."""
    numerator, denominator = group_sums(table, measure)
    with np.errstate(invalid="ignore", divide="ignore"):
        values: FloatArray = numerator / denominator
    return np.where(np.isfinite(values), values, np.nan)


def group_sums(table: GroupTable, measure: str) -> tuple[FloatArray, FloatArray]:
    """Each group's numerator and denominator of a measure (its value is their ratio), as
    the report's cluster totals are (kasparctl.research.inference)."""
    learned = table.learned >= 0
    trials = table.trials.astype(np.float64)
    total = trials.sum(axis=1)
    answered = (table.wrong_guesses + table.right_guesses).sum(axis=1)
    numerator, denominator = {
        "trials_mean": ((trials * learned).sum(axis=1), learned.sum(axis=1)),
        "problems_learned_rate": (learned.sum(axis=1), learned.shape[1]),
        "first_guess_correct_rate": (table.first_correct.sum(axis=1), learned.shape[1]),
        "perseverative_error_rate": (table.perseverative.sum(axis=1), total),
        "win_shift_rate": (table.win_shift.sum(axis=1), total),
        "final_entropy_mean": ((table.final_entropy * learned).sum(axis=1), learned.sum(axis=1)),
        "wrong_feedback_rate": ((table.wrong_green + table.wrong_red).sum(axis=1), answered),
    }[measure]
    groups = table.groups
    return (
        np.broadcast_to(np.asarray(numerator, dtype=np.float64), (groups,)).copy(),
        np.broadcast_to(np.asarray(denominator, dtype=np.float64), (groups,)).copy(),
    )
