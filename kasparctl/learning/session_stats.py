"""A recorded session as the problems the simulator's statistics work on.

Lets the paper's statistics (kasparctl.learning.study_stats) run on what the game
really recorded, so the demo, the robot and the simulator are measured by the
same code. An answer taken back with the researcher's undo is not a trial of
the problem: the caller leaves it out, and it stays marked in the records.

The trials come in as the game's trial records (kasparctl.game.records.TrialRecord);
this module asks only for the fields it reads (`RecordedTrial`), so the learning
layer needs nothing of the game. A trial's perseverative and win-shift flags are
the ones the records read (kasparctl.game.fold: the research passes them, else
the record's own, which the game wrote by the same rule), never recounted from
the guess before it in the list: after a re-open that one is not the guess it
follows.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Protocol

import numpy as np

from kasparctl.learning.learner import LearnerParams, entropy_bits, softmax
from kasparctl.learning.study_stats import ProblemRecord, TrialRecord


class RecordedTrial(Protocol):
    """The fields of a recorded trial that the statistics read."""

    @property
    def target_index(self) -> int:
        """The target guessed at."""
        ...

    @property
    def choice_index(self) -> int:
        """The label guessed."""
        ...

    @property
    def green(self) -> bool:
        """Whether the children said yes."""
        ...

    @property
    def entropy(self) -> float:
        """Eq. 3 before the guess, bits."""
        ...

    @property
    def correct(self) -> bool | None:
        """Whether the guess matched the answer key (None without one)."""
        ...

    @property
    def learned(self) -> bool:
        """Whether this answer made the target learned."""
        ...

    @property
    def perseverative(self) -> bool:
        """The record's own flag: the label answered red just before, chosen again."""
        ...

    @property
    def win_shift(self) -> bool:
        """The record's own flag: another label chosen right after a green."""
        ...

    @property
    def candidates(self) -> list[str]:
        """The labels offered, by name."""
        ...

    @property
    def q_after(self) -> list[float]:
        """The target's Q row after the update."""
        ...


class ProblemBuilder:
    """Problems built from a session's trials one at a time, holding only what they need.

    Each trial is kept as the values the statistics read (choice, answer, entropy,
    correctness, flags), never as the record, so a session of any length costs a few
    dozen bytes per trial.
    """

    def __init__(
        self,
        toys: Sequence[str],
        answer_key: Sequence[str],
        params: LearnerParams,
        group: int = 0,
    ) -> None:
        """Problems of one session, whose toys and answer key are these."""
        self.toys = list(toys)
        self.answer_key = list(answer_key)
        self.params = params
        self.group = group
        self._trials: dict[int, list[TrialRecord]] = {}
        # Of each target's last trial, only what the problem's end needs: was it learned
        # (and with which label), the labels offered and the Q row after it.
        self._last: dict[int, tuple[int | None, tuple[str, ...], tuple[float, ...]]] = {}
        self._candidates: dict[int, int] = {}

    def add(
        self,
        trial: RecordedTrial,
        flags: tuple[bool, bool] | None = None,
        after_wrong: bool | None = None,
    ) -> None:
        """One trial that counts (undone ones are left out by the caller), in recorded order;
        `flags` (perseverative, win_shift) as the records read, else the record's own;
        `after_wrong` the fold's cause of such an error (True after wrong feedback, False
        exploratory, None unknown), else the answer before it on this target decides."""
        target = trial.target_index
        perseverative, win_shift = (
            (trial.perseverative, trial.win_shift) if flags is None else flags
        )
        if flags is None:
            previous = self._trials.get(target, [])
            last = previous[-1] if previous else None
            after_wrong = (
                None if last is None or last.correct is None else last.feedback != last.correct
            )
        self._trials.setdefault(target, []).append(
            TrialRecord(
                choice=trial.choice_index,
                feedback=trial.green,
                entropy=trial.entropy,
                correct=trial.correct,
                perseverative=perseverative,
                win_shift=win_shift,
                after_wrong=after_wrong,
            )
        )
        self._candidates.setdefault(target, len(trial.candidates))
        self._last[target] = (
            trial.choice_index if trial.learned else None,
            tuple(trial.candidates),
            tuple(trial.q_after),
        )

    def problems(self, learned: Mapping[int, int] | None = None) -> list[ProblemRecord]:
        """One ProblemRecord per target the session guessed at, in the order it did.

        `learned` (target -> label), the records' reading of what the session ended with,
        decides what each problem learned; without it, each target's last trial does (a
        name re-opened after it and never asked again would count as learned).
        """
        toys = self.toys
        problems = []
        for target, trials in self._trials.items():
            last_learned, offered, last_q = self._last[target]
            learned_label = last_learned if learned is None else learned.get(target)
            candidates = np.array([toy in offered for toy in toys])
            if not candidates.any():
                # A record naming none of the session's toys: over all of them.
                candidates = np.ones(len(toys), dtype=bool)
            q_after = np.array(last_q, dtype=np.float64)
            answer = (
                toys.index(self.answer_key[target]) if 0 <= target < len(self.answer_key) else None
            )
            problems.append(
                ProblemRecord(
                    group=self.group,
                    target=target,
                    answer=answer,
                    trials=tuple(trials),
                    learned=learned_label,
                    final_q=tuple(float(q) for q in q_after),
                    entropy_after=entropy_bits(softmax(q_after, self.params.beta, candidates)),
                    candidates=self._candidates[target],
                )
            )
        return problems


def problems_from_trials(
    trials: Iterable[RecordedTrial],
    toys: Sequence[str],
    answer_key: Sequence[str],
    params: LearnerParams,
    group: int = 0,
) -> list[ProblemRecord]:
    """One ProblemRecord per target the session guessed at, in the order it did.

    `trials` are the trials that count (undone ones left out), in recorded order.
    """
    builder = ProblemBuilder(toys, answer_key, params, group)
    for trial in trials:
        builder.add(trial)
    return builder.problems()
