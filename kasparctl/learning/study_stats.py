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
  "right after" is the guess before on the same problem, except that a
  problem's first guess after the researcher re-opened its name follows none
  (the green that had taught it was taken back): recorded trials carry their
  flags as kasparctl.game.fold reads them, simulated ones are compared pairwise;
  each is attributed, where the answer is known, to the children's feedback
  before it: "after wrong feedback" when that red was for the right label (or
  that green for a wrong one), "exploratory" when it was right (the paper
  attributes its events to Kaspar's exploration);
- initial entropy: the entropy spoken before the first guess of a problem;
- final entropy: the entropy spoken before the last guess of a learned
  problem (the last uncertainty the children heard), and separately the
  entropy of the problem's Q row after the last update (what Kaspar would say
  if asked once more);
- entropy by trial: the mean entropy before guess k over the problems that
  had a k-th guess (the paper's Fig. 2).
Trials to learn and final entropies are over learned problems only; a problem
given up after the maximum number of trials is counted apart.

The statistics are sums and moments (StatsAccumulator), so problems can be
added a chunk at a time and a simulation of any size holds only its totals.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

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
    # The flags as the records read (kasparctl.game.fold, which knows which guess this
    # one follows: none after a re-open); None: from the guess before it in the problem,
    # as a simulated problem is asked in one go.
    perseverative: bool | None = None
    win_shift: bool | None = None
    # With the recorded flags, what the fold read the error followed: True after wrong
    # feedback, False exploratory, None unknown (no answer key) or not an error.
    after_wrong: bool | None = None


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
    # Labels offered at its first guess (fewer than all in the names game's later bags).
    candidates: int = 0
    # Times the researcher re-opened its learned name (kasparctl.game.recovery).
    reopened: int = 0


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
    # Of the perseverative errors and win-shifts: those right after a wrong answer of
    # the children, and those after a right one (exploratory). Zeros when unknown.
    perseverative_after_wrong: NDArray[np.int64] | None = None
    win_shift_after_wrong: NDArray[np.int64] | None = None
    perseverative_exploratory: NDArray[np.int64] | None = None
    win_shift_exploratory: NDArray[np.int64] | None = None


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
    # Perseverative errors and win-shifts by what came before (see the module's docstring);
    # the rest of each count followed an answer that cannot be checked (no answer key).
    perseverative_after_wrong_feedback: int = 0
    perseverative_exploratory: int = 0
    win_shifts_after_wrong_feedback: int = 0
    win_shifts_exploratory: int = 0


class ErrorCounts(msgspec.Struct, frozen=True):
    """One problem's perseverative errors and win-shifts, and what preceded each."""

    perseverative: int = 0
    win_shift: int = 0
    perseverative_after_wrong: int = 0
    win_shift_after_wrong: int = 0
    perseverative_exploratory: int = 0
    win_shift_exploratory: int = 0


def is_perseverative(previous_choice: int, previous_feedback: bool | None, choice: int) -> bool:
    """A perseverative error: the label that was just answered red, chosen again."""
    return previous_feedback is False and choice == previous_choice


def is_win_shift(previous_choice: int, previous_feedback: bool | None, choice: int) -> bool:
    """A win-shift: another label chosen right after a green."""
    return previous_feedback is True and choice != previous_choice


def count_perseverative_and_win_shift(trials: Sequence[TrialRecord]) -> tuple[int, int]:
    """Perseverative errors and win-shifts within one problem's trials."""
    counts = count_errors(trials)
    return counts.perseverative, counts.win_shift


def count_errors(trials: Sequence[TrialRecord]) -> ErrorCounts:
    """Perseverative errors and win-shifts within one problem, each attributed.

    The answer before an error was wrong when it disagreed with whether that guess
    was right (a red for the right label, a green for a wrong one); unknown without
    an answer key.
    """
    counts = [0] * 6
    for previous, current in itertools.pairwise(trials):
        if current.perseverative is None or current.win_shift is None:
            flags = (
                is_perseverative(previous.choice, previous.feedback, current.choice),
                is_win_shift(previous.choice, previous.feedback, current.choice),
            )
        else:
            flags = (current.perseverative, current.win_shift)
        if flags[0]:
            kind = 0
        elif flags[1]:
            kind = 1
        else:
            continue
        counts[kind] += 1
        if current.perseverative is not None and current.win_shift is not None:
            # Recorded: the cause as the fold read it, the CSV's error_cause.
            wrong: bool | None = current.after_wrong
        else:
            wrong = None if previous.correct is None else previous.feedback != previous.correct
        if wrong is not None:
            counts[kind + (2 if wrong else 4)] += 1
    return ErrorCounts(*counts)


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
    errors = [count_errors(p.trials) for p in problems]
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
        perseverative=np.array([e.perseverative for e in errors], dtype=np.int64),
        win_shift=np.array([e.win_shift for e in errors], dtype=np.int64),
        initial_entropy=np.array([p.trials[0].entropy for p in problems]),
        final_entropy=np.array([p.trials[-1].entropy for p in problems]),
        final_entropy_after=np.array([p.entropy_after for p in problems]),
        entropy_sum_by_trial=entropy_sum,
        entropy_count_by_trial=entropy_count,
        perseverative_after_wrong=np.array(
            [e.perseverative_after_wrong for e in errors], dtype=np.int64
        ),
        win_shift_after_wrong=np.array([e.win_shift_after_wrong for e in errors], dtype=np.int64),
        perseverative_exploratory=np.array(
            [e.perseverative_exploratory for e in errors], dtype=np.int64
        ),
        win_shift_exploratory=np.array([e.win_shift_exploratory for e in errors], dtype=np.int64),
    )


def summarise(problems: Sequence[ProblemRecord]) -> StudyStats:
    """The statistics of trial records."""
    return summarise_table(tabulate(problems))


def summarise_table(table: ProblemTable) -> StudyStats:
    """The statistics of per-problem columns (the vectorised simulator's form)."""
    return StatsAccumulator().add_table(table).result()


class Moments:
    """Count, sum and sum of squares of values, shifted by the first one for exactness.

    Equal values (every problem starts at log2(6)) give that value exactly as the
    mean, not a sum rounded and divided; chunks add up to the same totals. Up to
    EXACT_VALUES values are also kept, so the mean and sd of any study of a
    usual size are computed from the values themselves, to the last bit as
    numpy computes them; beyond, from the running sums.
    """

    EXACT_VALUES = 1 << 20

    def __init__(self) -> None:
        """No values yet."""
        self.kept: list[NDArray[np.float64]] | None = []
        self.count = 0
        self.shift = 0.0
        self.total = 0.0
        self.squares = 0.0
        self.low: float | None = None
        self.high: float | None = None

    def add(self, values: NDArray[np.floating] | NDArray[np.integer]) -> None:
        """Add values (any number, in any order)."""
        if len(values) == 0:
            return
        array = np.asarray(values, dtype=np.float64)
        if self.kept is not None:
            self.kept.append(array)
            if self.count + len(array) > self.EXACT_VALUES:
                self.kept = None
        if self.count == 0:
            self.shift = float(array[0])
        shifted = array - self.shift
        self.count += len(array)
        self.total += float(shifted.sum())
        self.squares += float((shifted * shifted).sum())
        low, high = float(array.min()), float(array.max())
        self.low = low if self.low is None else min(self.low, low)
        self.high = high if self.high is None else max(self.high, high)

    @property
    def mean(self) -> float | None:
        """The mean, None without values."""
        if self.kept:
            return _mean(np.concatenate(self.kept))
        return None if self.count == 0 else self.shift + self.total / self.count

    @property
    def sd(self) -> float | None:
        """Sample standard deviation (n - 1), as a paper's "mean ± sd" reports; 0 for one value."""
        if self.kept:
            return _sd(np.concatenate(self.kept))
        if self.count < 2:
            return 0.0 if self.count == 1 else None
        variance = (self.squares - self.total * self.total / self.count) / (self.count - 1)
        return math.sqrt(max(variance, 0.0))


class StatsAccumulator:
    """The paper's statistics over problems added a table at a time, holding only totals."""

    def __init__(self) -> None:
        """No problems yet."""
        self.counts: dict[str, int] = dict.fromkeys(
            (
                "problems",
                "learned",
                "learned_wrong",
                "answer_known",
                "first_correct",
                "trials_total",
                "perseverative",
                "win_shift",
                "perseverative_after_wrong",
                "win_shift_after_wrong",
                "perseverative_exploratory",
                "win_shift_exploratory",
            ),
            0,
        )
        self.trials = Moments()
        self.initial_entropy = Moments()
        self.final_entropy = Moments()
        self.final_entropy_after = Moments()
        self.entropy_sum = np.zeros(0)
        self.entropy_count = np.zeros(0, dtype=np.int64)

    def add(self, problems: Sequence[ProblemRecord]) -> StatsAccumulator:
        """Add problems as trial records; returns self."""
        if problems:
            self.add_table(tabulate(problems))
        return self

    def add_table(self, table: ProblemTable) -> StatsAccumulator:
        """Add problems as per-problem columns; returns self."""
        learned = table.learned
        counts = self.counts
        counts["problems"] += len(table.trials)
        counts["learned"] += int(learned.sum())
        counts["learned_wrong"] += int(table.learned_wrong.sum())
        counts["answer_known"] += int(table.answer_known.sum())
        counts["first_correct"] += int(table.first_correct.sum())
        counts["trials_total"] += int(table.trials.sum())
        counts["perseverative"] += int(table.perseverative.sum())
        counts["win_shift"] += int(table.win_shift.sum())
        for name in (
            "perseverative_after_wrong",
            "win_shift_after_wrong",
            "perseverative_exploratory",
            "win_shift_exploratory",
        ):
            column = getattr(table, name)
            if column is not None:
                counts[name] += int(column.sum())
        self.trials.add(table.trials[learned])
        self.initial_entropy.add(table.initial_entropy)
        self.final_entropy.add(table.final_entropy[learned])
        self.final_entropy_after.add(table.final_entropy_after[learned])
        longest = max(len(self.entropy_sum), len(table.entropy_sum_by_trial))
        self.entropy_sum = _padded(self.entropy_sum, longest) + _padded(
            table.entropy_sum_by_trial, longest
        )
        self.entropy_count = _padded(self.entropy_count, longest) + _padded(
            table.entropy_count_by_trial, longest
        )
        return self

    def result(self) -> StudyStats:
        """The statistics of every problem added."""
        c = self.counts
        trials_total, known = c["trials_total"], c["answer_known"]
        counts = self.entropy_count
        trials = self.trials
        return StudyStats(
            problems=c["problems"],
            problems_learned=c["learned"],
            problems_given_up=c["problems"] - c["learned"],
            problems_learned_wrong=c["learned_wrong"],
            trials_total=trials_total,
            trials_mean=trials.mean,
            trials_sd=trials.sd,
            trials_min=None if trials.low is None else int(trials.low),
            trials_max=None if trials.high is None else int(trials.high),
            first_guess_correct=c["first_correct"],
            first_guess_correct_rate=c["first_correct"] / known if known else None,
            perseverative_errors=c["perseverative"],
            perseverative_error_rate=c["perseverative"] / trials_total if trials_total else None,
            win_shifts=c["win_shift"],
            win_shift_rate=c["win_shift"] / trials_total if trials_total else None,
            initial_entropy=self.initial_entropy.mean,
            final_entropy_mean=self.final_entropy.mean,
            final_entropy_sd=self.final_entropy.sd,
            final_entropy_after_mean=self.final_entropy_after.mean,
            final_entropy_after_sd=self.final_entropy_after.sd,
            entropy_by_trial=[
                float(s / n) for s, n in zip(self.entropy_sum, counts, strict=True) if n
            ],
            entropy_by_trial_n=[int(n) for n in counts if n],
            perseverative_after_wrong_feedback=c["perseverative_after_wrong"],
            perseverative_exploratory=c["perseverative_exploratory"],
            win_shifts_after_wrong_feedback=c["win_shift_after_wrong"],
            win_shifts_exploratory=c["win_shift_exploratory"],
        )


def _padded(values: NDArray[Any], length: int) -> NDArray[Any]:
    if len(values) >= length:
        return values
    return np.concatenate([values, np.zeros(length - len(values), dtype=values.dtype)])


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
