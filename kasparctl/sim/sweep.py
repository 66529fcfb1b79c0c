"""Vectorised simulation of pilot problems, for parameter sweeps.

Many independent pilot problems (one location over all the toys) advance one
guess per step as rows of arrays, each row with its own alpha and beta, using
the learner's batch forms. Finished rows are written out and dropped, so each
step costs only what is still running. It applies the rule of
kasparctl.game.problem and the teacher of kasparctl.sim.teacher row-wise; for a single
row it draws the very random numbers the scalar simulator draws, and the tests
hold the two to the same records and statistics.

Only the pilot: in the names game the candidates of a bag depend on what the
earlier bags learned, which the scalar simulator handles.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kasparctl.config import GameSettings
from kasparctl.learning.learner import (
    LearnerError,
    LearnerParams,
    choose_batch,
    entropy_bits_batch,
    softmax_batch,
)
from kasparctl.learning.study_stats import ProblemTable, StudyStats, summarise_table
from kasparctl.sim.teacher import Teacher

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# Rows simulated at once: bounds memory (about 0.4 kB per row in flight) while
# keeping numpy's per-call overhead negligible.
CHUNK_ROWS = 1 << 18


@dataclass(frozen=True, slots=True)
class PilotShape:
    """What a pilot problem looks like, from the game settings."""

    n_toys: int = 6
    correct_answers_to_learn: int = 2
    max_trials: int = 30
    # Only for gamma > 0: the last problem of a group has no next state to bootstrap from.
    problems_per_group: int = 3

    @classmethod
    def from_game(cls, game: GameSettings) -> PilotShape:
        """The shape of the game's problems (3 per group without locations, as the pilot)."""
        return cls(
            n_toys=len(game.toys),
            correct_answers_to_learn=game.correct_answers_to_learn,
            max_trials=game.max_trials_per_target,
            problems_per_group=len(game.locations) or 3,
        )


def check_rates(alpha: FloatArray, beta: FloatArray) -> None:
    """The per-row form of LearnerParams' checks on alpha and beta."""
    bad_alpha = ~(np.isfinite(alpha) & (alpha > 0.0) & (alpha <= 1.0))
    if bad_alpha.any():
        found = alpha[bad_alpha][0]
        raise LearnerError(f"expected a number in (0, 1], found {found!r}", "alpha")
    bad_beta = ~(np.isfinite(beta) & (beta >= 0.0))
    if bad_beta.any():
        raise LearnerError(f"expected a number >= 0, found {beta[bad_beta][0]!r}", "beta")


def simulate_pilot_problems(
    alpha: FloatArray,
    beta: FloatArray,
    rng: np.random.Generator,
    params: LearnerParams | None = None,
    teacher: Teacher | None = None,
    shape: PilotShape | None = None,
    answers: IntArray | None = None,
    setting: IntArray | None = None,
    chunk_rows: int = CHUNK_ROWS,
) -> list[ProblemTable]:
    """One problem per row of `alpha`/`beta`; one ProblemTable per setting.

    `setting[i]` (default all 0) says which table row i belongs to, so a sweep
    runs all its settings in the same arrays. `params` gives gamma, the rewards
    and Q0 (its alpha and beta are not used). `answers` (default: drawn) is the
    correct toy of each row.
    """
    params = params or LearnerParams()
    teacher = teacher or Teacher()
    shape = shape or PilotShape()
    alpha = np.asarray(alpha, dtype=np.float64)
    beta = np.asarray(beta, dtype=np.float64)
    n = len(alpha)
    if beta.shape != (n,):
        raise ValueError(f"beta: expected {n} values (one per row), found shape {beta.shape}")
    check_rates(alpha, beta)
    if answers is None:
        answers = rng.integers(shape.n_toys, size=n)
    setting = (
        np.zeros(n, dtype=np.int64) if setting is None else np.asarray(setting, dtype=np.int64)
    )
    n_settings = int(setting.max()) + 1 if n else 1

    columns: list[dict[str, NDArray[np.generic]]] = []
    entropy_sum = np.zeros((n_settings, shape.max_trials))
    entropy_count = np.zeros((n_settings, shape.max_trials), dtype=np.int64)
    for start in range(0, n, chunk_rows):
        rows = slice(start, start + chunk_rows)
        chunk = _Chunk(
            alpha[rows],
            beta[rows],
            np.asarray(answers[rows]),
            setting[rows],
            np.arange(start, min(n, start + chunk_rows)),
            params,
            teacher,
            shape,
            n_settings,
        )
        chunk.run(rng)
        columns.append(chunk.out)
        entropy_sum += chunk.entropy_sum
        entropy_count += chunk.entropy_count
    merged = (
        {key: np.concatenate([c[key] for c in columns]) for key in _Chunk.OUTPUTS}
        if columns
        else None
    )
    tables = []
    for index in range(n_settings):
        mine = setting == index
        out = {key: merged[key][mine] for key in _Chunk.OUTPUTS} if merged else _empty_outputs()
        learned = out["learned"].astype(np.int64)
        tables.append(
            ProblemTable(
                trials=out["trials"].astype(np.int64),
                learned=learned >= 0,
                learned_wrong=(learned >= 0) & (learned != out["answer"]),
                answer_known=np.ones(len(out["trials"]), dtype=bool),
                first_correct=out["first_correct"].astype(bool),
                perseverative=out["perseverative"].astype(np.int64),
                win_shift=out["win_shift"].astype(np.int64),
                perseverative_after_wrong=out["perseverative_after_wrong"].astype(np.int64),
                win_shift_after_wrong=out["win_shift_after_wrong"].astype(np.int64),
                # Every answer is checked in a simulation: the rest were exploratory.
                perseverative_exploratory=out["perseverative"].astype(np.int64)
                - out["perseverative_after_wrong"].astype(np.int64),
                win_shift_exploratory=out["win_shift"].astype(np.int64)
                - out["win_shift_after_wrong"].astype(np.int64),
                initial_entropy=out["initial_entropy"].astype(np.float64),
                final_entropy=out["final_entropy"].astype(np.float64),
                final_entropy_after=out["final_entropy_after"].astype(np.float64),
                entropy_sum_by_trial=entropy_sum[index],
                entropy_count_by_trial=entropy_count[index],
            )
        )
    return tables


def _empty_outputs() -> dict[str, NDArray[np.generic]]:
    return {key: np.zeros(0) for key in _Chunk.OUTPUTS}


class _Chunk:
    """The rows of one chunk, shrinking as their problems finish."""

    OUTPUTS = (
        "trials",
        "learned",
        "answer",
        "first_correct",
        "perseverative",
        "win_shift",
        "perseverative_after_wrong",
        "win_shift_after_wrong",
        "initial_entropy",
        "final_entropy",
        "final_entropy_after",
    )

    def __init__(
        self,
        alpha: FloatArray,
        beta: FloatArray,
        answers: IntArray,
        setting: IntArray,
        index: IntArray,
        params: LearnerParams,
        teacher: Teacher,
        shape: PilotShape,
        n_settings: int,
    ) -> None:
        n = len(alpha)
        self.params, self.teacher, self.shape, self.n_settings = params, teacher, shape, n_settings
        # Live state, one entry per running row.
        self.alpha, self.beta, self.answers, self.setting = alpha, beta, answers, setting
        self.row = np.arange(n)
        self.last_in_group = (index % shape.problems_per_group) == shape.problems_per_group - 1
        self.q = np.full((n, shape.n_toys), params.initial_q)
        self.streak = np.zeros(n, dtype=np.int64)
        self.streak_label = np.full(n, -1, dtype=np.int64)
        self.previous_choice = np.full(n, -1, dtype=np.int64)
        # +1 green, -1 red, 0 unanswered (or no previous guess).
        self.previous_feedback = np.zeros(n, dtype=np.int8)
        self.perseverative = np.zeros(n, dtype=np.int64)
        self.win_shift = np.zeros(n, dtype=np.int64)
        # Whether the children's previous answer disagreed with the guess being right.
        self.previous_wrong = np.zeros(n, dtype=bool)
        self.perseverative_after_wrong = np.zeros(n, dtype=np.int64)
        self.win_shift_after_wrong = np.zeros(n, dtype=np.int64)
        self.first_correct = np.zeros(n, dtype=bool)
        self.initial_entropy = np.zeros(n)
        # Results, by position in the chunk.
        self.out: dict[str, NDArray[np.generic]] = {
            "trials": np.zeros(n, dtype=np.int64),
            "learned": np.full(n, -1, dtype=np.int64),
            "answer": answers.copy(),
            "first_correct": np.zeros(n, dtype=bool),
            "perseverative": np.zeros(n, dtype=np.int64),
            "win_shift": np.zeros(n, dtype=np.int64),
            "perseverative_after_wrong": np.zeros(n, dtype=np.int64),
            "win_shift_after_wrong": np.zeros(n, dtype=np.int64),
            "initial_entropy": np.zeros(n),
            "final_entropy": np.zeros(n),
            "final_entropy_after": np.zeros(n),
        }
        self.entropy_sum = np.zeros((n_settings, shape.max_trials))
        self.entropy_count = np.zeros((n_settings, shape.max_trials), dtype=np.int64)

    def run(self, rng: np.random.Generator) -> None:
        for trial in range(self.shape.max_trials):
            if len(self.row) == 0:
                return
            self._step(trial, rng)

    def _step(self, trial: int, rng: np.random.Generator) -> None:
        params, shape = self.params, self.shape
        probabilities = softmax_batch(self.q, self.beta)
        entropy = entropy_bits_batch(probabilities)
        choice = choose_batch(probabilities, rng).astype(np.int64)
        correct = choice == self.answers
        feedback = self._answers(correct, rng)

        self.entropy_sum[:, trial] += np.bincount(self.setting, entropy, self.n_settings)
        self.entropy_count[:, trial] += np.bincount(self.setting, minlength=self.n_settings)
        if trial == 0:
            self.initial_entropy = entropy
            self.first_correct = correct
        else:
            perseverative = (self.previous_feedback == -1) & (choice == self.previous_choice)
            win_shift = (self.previous_feedback == 1) & (choice != self.previous_choice)
            self.perseverative += perseverative
            self.win_shift += win_shift
            self.perseverative_after_wrong += perseverative & self.previous_wrong
            self.win_shift_after_wrong += win_shift & self.previous_wrong

        green = feedback == 1
        same = green & (choice == self.streak_label)
        self.streak = np.where(same, self.streak + 1, np.where(green, 1, 0))
        self.streak_label = np.where(green, choice, -1)
        learned = self.streak >= shape.correct_answers_to_learn
        done = learned | (trial + 1 >= shape.max_trials)

        answered = np.flatnonzero(feedback != 0)
        if len(answered):
            rows, actions = answered, choice[answered]
            reward = np.where(feedback[answered] == 1, params.reward_green, params.reward_red)
            q_sa = self.q[rows, actions]
            if params.gamma != 0.0:
                # s_{t+1} as in the scalar simulator: this row until it is done,
                # then the group's next (untouched) row, or nothing after the last.
                next_max: FloatArray | float = np.where(
                    done[answered],
                    np.where(self.last_in_group[answered], 0.0, params.initial_q),
                    self.q[rows].max(axis=1),
                )
            else:
                next_max = 0.0
            self.q[rows, actions] = q_sa + self.alpha[rows] * (
                reward + params.gamma * next_max - q_sa
            )

        self.previous_choice = choice
        self.previous_feedback = feedback
        self.previous_wrong = ((feedback == 1) & ~correct) | ((feedback == -1) & correct)
        if done.any():
            self._finish(done, trial, choice, learned, entropy)

    def _answers(self, correct: NDArray[np.bool_], rng: np.random.Generator) -> NDArray[np.int8]:
        """Teacher.answer row-wise, drawing the same two numbers per guess."""
        teacher = self.teacher
        honest = np.where(correct, 1, -1).astype(np.int8)
        if teacher.honest:
            return honest
        draws = rng.random((len(correct), 2))
        p_mistake = np.where(correct, teacher.p_wrong_red, teacher.p_wrong_green)
        given = np.where(draws[:, 1] < p_mistake, -honest, honest).astype(np.int8)
        return np.where(draws[:, 0] < teacher.p_no_answer, 0, given).astype(np.int8)

    def _finish(
        self,
        done: NDArray[np.bool_],
        trial: int,
        choice: IntArray,
        learned: NDArray[np.bool_],
        entropy: FloatArray,
    ) -> None:
        where = self.row[done]
        after = entropy_bits_batch(softmax_batch(self.q[done], self.beta[done]))
        out = self.out
        out["trials"][where] = trial + 1
        out["learned"][where] = np.where(learned[done], choice[done], -1)
        out["first_correct"][where] = self.first_correct[done]
        out["perseverative"][where] = self.perseverative[done]
        out["win_shift"][where] = self.win_shift[done]
        out["perseverative_after_wrong"][where] = self.perseverative_after_wrong[done]
        out["win_shift_after_wrong"][where] = self.win_shift_after_wrong[done]
        out["initial_entropy"][where] = self.initial_entropy[done]
        out["final_entropy"][where] = entropy[done]
        out["final_entropy_after"][where] = after
        keep = ~done
        for name in (
            "alpha",
            "beta",
            "answers",
            "setting",
            "row",
            "last_in_group",
            "q",
            "streak",
            "streak_label",
            "previous_choice",
            "previous_feedback",
            "perseverative",
            "win_shift",
            "previous_wrong",
            "perseverative_after_wrong",
            "win_shift_after_wrong",
            "first_correct",
            "initial_entropy",
        ):
            setattr(self, name, getattr(self, name)[keep])


def sweep(
    settings: Sequence[tuple[float, float]],
    problems_per_setting: int,
    seed: int | None,
    params: LearnerParams | None = None,
    teacher: Teacher | None = None,
    shape: PilotShape | None = None,
) -> list[StudyStats]:
    """The pilot's statistics for each (alpha, beta) in `settings`, in that order."""
    if problems_per_setting < 1:
        raise ValueError(f"problems_per_setting: expected >= 1, found {problems_per_setting}")
    values = np.asarray(settings, dtype=np.float64).reshape(-1, 2)
    alpha = np.repeat(values[:, 0], problems_per_setting)
    beta = np.repeat(values[:, 1], problems_per_setting)
    setting = np.repeat(np.arange(len(values)), problems_per_setting)
    tables = simulate_pilot_problems(
        alpha, beta, np.random.default_rng(seed), params, teacher, shape, setting=setting
    )
    return [summarise_table(table) for table in tables]
