"""Per-problem trial records and the paper's statistics over them (section IV).

Plain data in, plain data out: the simulator produces these records, and a
report over recorded sessions can build the same records from its trial
files and get the same statistics. Nothing here knows the learner.

Definitions, as the paper uses them:
- a problem is one target (a location in the pilot, a bag in the names game)
  from its first guess until it is learned or given up;
- trials to learn: the number of guesses of a learned problem, the confirming
  greens included (so at least `correct_answers_to_learn`);
- a perseverative error: choosing the same label again right after it got red;
- a win-shift: choosing a different label right after a green;
  both within one problem, counted per trial (the paper: 1 of each in 202);
- initial entropy: the entropy spoken before the first guess of a problem;
- final entropy: the entropy spoken before the last guess of a learned
  problem (the last uncertainty the children heard), and separately the
  entropy of the problem's Q row after the last update (what Kaspar would say
  if asked once more);
- entropy by trial: the mean entropy before guess k over the problems that
  had a k-th guess (the paper's Fig. 2).
Trials to learn and final entropies are over learned problems only; a problem
given up after the maximum number of trials is counted apart.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import msgspec
import numpy as np
from numpy.typing import NDArray


class TrialRecord(msgspec.Struct, frozen=True, gc=False):
    """One guess of a problem: the label chosen, the feedback and the entropy before it."""

    choice: int
    # True green, False red, None unanswered.
    feedback: bool | None
    # Entropy (bits) of the choice probabilities before this guess.
    entropy: float
    # None when the answer is unknown (a session recorded without an answer key).
    correct: bool | None


class ProblemRecord(msgspec.Struct, frozen=True):
    """One problem (a target of a group) from its first guess until learned or given up."""

    group: int
    target: int
    answer: int | None
    trials: tuple[TrialRecord, ...]
    learned: int | None
    # The target's Q row after the last update, and the entropy of its choice
    # probabilities over the same candidates.
    final_q: tuple[float, ...]
    entropy_after: float


@dataclass(frozen=True, slots=True)
class ProblemTable:
    """One value per problem, in columns: what the statistics are computed from.

    The vectorised simulator fills this directly, without trial records.
    """

    trials: NDArray[np.int64]
    learned: NDArray[np.bool_]
    # Learned a label other than the answer (False when the answer is unknown).
    learned_wrong: NDArray[np.bool_]
    answer_known: NDArray[np.bool_]
    first_correct: NDArray[np.bool_]
    perseverative: NDArray[np.int64]
    win_shift: NDArray[np.int64]
    initial_entropy: NDArray[np.float64]
    final_entropy: NDArray[np.float64]
    final_entropy_after: NDArray[np.float64]
    # Index k holds the sum (and count) of the entropies before guess k+1.
    entropy_sum_by_trial: NDArray[np.float64]
    entropy_count_by_trial: NDArray[np.int64]


class StudyStats(msgspec.Struct, frozen=True):
    """The paper's statistics over a set of problems; None where nothing was counted."""

    problems: int
    problems_learned: int
    problems_given_up: int
    problems_learned_wrong: int
    trials_total: int
    trials_mean: float | None
    trials_sd: float | None
    trials_min: int | None
    trials_max: int | None
    first_guess_correct: int
    first_guess_correct_rate: float | None
    perseverative_errors: int
    perseverative_error_rate: float | None
    win_shifts: int
    win_shift_rate: float | None
    initial_entropy: float | None
    final_entropy_mean: float | None
    final_entropy_sd: float | None
    final_entropy_after_mean: float | None
    final_entropy_after_sd: float | None
    entropy_by_trial: list[float]
    entropy_by_trial_n: list[int]


def count_perseverative_and_win_shift(trials: Sequence[TrialRecord]) -> tuple[int, int]:
    """Perseverative errors and win-shifts within one problem's trials."""
    perseverative = win_shift = 0
    for previous, current in itertools.pairwise(trials):
        if previous.feedback is False and current.choice == previous.choice:
            perseverative += 1
        elif previous.feedback is True and current.choice != previous.choice:
            win_shift += 1
    return perseverative, win_shift


def tabulate(problems: Sequence[ProblemRecord]) -> ProblemTable:
    """Trial records to per-problem columns; a problem without trials is an error."""
    for problem in problems:
        if not problem.trials:
            raise ValueError(
                f"problem of group {problem.group}, target {problem.target} has no trials"
            )
    longest = max((len(p.trials) for p in problems), default=0)
    entropy_sum = np.zeros(longest)
    entropy_count = np.zeros(longest, dtype=np.int64)
    for problem in problems:
        entropies = np.fromiter((t.entropy for t in problem.trials), float, len(problem.trials))
        entropy_sum[: len(entropies)] += entropies
        entropy_count[: len(entropies)] += 1
    pairs = [count_perseverative_and_win_shift(p.trials) for p in problems]
    return ProblemTable(
        trials=np.array([len(p.trials) for p in problems], dtype=np.int64),
        learned=np.array([p.learned is not None for p in problems], dtype=bool),
        learned_wrong=np.array(
            [
                p.learned is not None and p.answer is not None and p.learned != p.answer
                for p in problems
            ],
            dtype=bool,
        ),
        answer_known=np.array([p.trials[0].correct is not None for p in problems], dtype=bool),
        first_correct=np.array([p.trials[0].correct is True for p in problems], dtype=bool),
        perseverative=np.array([pair[0] for pair in pairs], dtype=np.int64),
        win_shift=np.array([pair[1] for pair in pairs], dtype=np.int64),
        initial_entropy=np.array([p.trials[0].entropy for p in problems]),
        final_entropy=np.array([p.trials[-1].entropy for p in problems]),
        final_entropy_after=np.array([p.entropy_after for p in problems]),
        entropy_sum_by_trial=entropy_sum,
        entropy_count_by_trial=entropy_count,
    )


def summarise(problems: Sequence[ProblemRecord]) -> StudyStats:
    """The statistics of trial records."""
    return summarise_table(tabulate(problems))


def summarise_table(table: ProblemTable) -> StudyStats:
    """The statistics of per-problem columns (the vectorised simulator's form)."""
    learned = table.learned
    trials_learned = table.trials[learned]
    trials_total = int(table.trials.sum())
    n_known = int(table.answer_known.sum())
    first_correct = int(table.first_correct.sum())
    perseverative = int(table.perseverative.sum())
    win_shift = int(table.win_shift.sum())
    counts = table.entropy_count_by_trial
    return StudyStats(
        problems=len(table.trials),
        problems_learned=int(learned.sum()),
        problems_given_up=int((~learned).sum()),
        problems_learned_wrong=int(table.learned_wrong.sum()),
        trials_total=trials_total,
        trials_mean=_mean(trials_learned),
        trials_sd=_sd(trials_learned),
        trials_min=int(trials_learned.min()) if len(trials_learned) else None,
        trials_max=int(trials_learned.max()) if len(trials_learned) else None,
        first_guess_correct=first_correct,
        first_guess_correct_rate=first_correct / n_known if n_known else None,
        perseverative_errors=perseverative,
        perseverative_error_rate=perseverative / trials_total if trials_total else None,
        win_shifts=win_shift,
        win_shift_rate=win_shift / trials_total if trials_total else None,
        initial_entropy=_mean(table.initial_entropy),
        final_entropy_mean=_mean(table.final_entropy[learned]),
        final_entropy_sd=_sd(table.final_entropy[learned]),
        final_entropy_after_mean=_mean(table.final_entropy_after[learned]),
        final_entropy_after_sd=_sd(table.final_entropy_after[learned]),
        entropy_by_trial=[
            float(s / n) for s, n in zip(table.entropy_sum_by_trial, counts, strict=True) if n
        ],
        entropy_by_trial_n=[int(n) for n in counts if n],
    )


def _mean(values: NDArray[np.floating] | NDArray[np.integer]) -> float | None:
    if len(values) == 0:
        return None
    # Shifted by the first value: equal values (every problem starts at log2(6))
    # give that value exactly, not a sum rounded then divided.
    shifted = np.asarray(values, dtype=np.float64)
    first = float(shifted[0])
    return first + float((shifted - first).sum()) / len(shifted)


def _sd(values: NDArray[np.floating] | NDArray[np.integer]) -> float | None:
    """Sample standard deviation (n - 1), as a paper's "mean ± sd" reports."""
    if len(values) < 2:
        return 0.0 if len(values) == 1 else None
    return float(np.std(np.asarray(values, dtype=np.float64), ddof=1))
