"""A recorded session as the problems the simulator's statistics work on.

Lets the paper's statistics (kasparctl.learning.study_stats) run on what the game
really recorded, so the demo, the robot and the simulator are measured by the
same code. An answer taken back with the researcher's undo is not a trial of
the problem: the caller leaves it out, and it stays marked in the records.

The trials come in as the game's trial records (kasparctl.game.records.TrialRecord);
this module asks only for the fields it reads (`RecordedTrial`), so the learning
layer needs nothing of the game.
"""

from __future__ import annotations

from collections.abc import Sequence
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
    def candidates(self) -> list[str]:
        """The labels offered, by name."""
        ...

    @property
    def q_after(self) -> list[float]:
        """The target's Q row after the update."""
        ...


def problems_from_trials(
    trials: Sequence[RecordedTrial],
    toys: Sequence[str],
    answer_key: Sequence[str],
    params: LearnerParams,
    group: int = 0,
) -> list[ProblemRecord]:
    """One ProblemRecord per target the session guessed at, in the order it did.

    `trials` are the trials that count (undone ones left out), in recorded order.
    """
    by_target: dict[int, list[RecordedTrial]] = {}
    for trial in trials:
        by_target.setdefault(trial.target_index, []).append(trial)
    problems = []
    for target, of_target in by_target.items():
        last = of_target[-1]
        learned = last.choice_index if last.learned else None
        candidates = np.array([toy in last.candidates for toy in toys])
        q_after = np.array(last.q_after, dtype=np.float64)
        answer = toys.index(answer_key[target]) if answer_key else None
        problems.append(
            ProblemRecord(
                group=group,
                target=target,
                answer=answer,
                trials=tuple(
                    TrialRecord(
                        choice=t.choice_index,
                        feedback=t.green,
                        entropy=t.entropy,
                        correct=t.correct,
                    )
                    for t in of_target
                ),
                learned=learned,
                final_q=tuple(float(q) for q in q_after),
                entropy_after=entropy_bits(softmax(q_after, params.beta, candidates)),
            )
        )
    return problems
