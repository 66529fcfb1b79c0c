"""A recorded session as the problems the simulator's statistics work on.

Lets the paper's statistics (kasparctl.learning.study_stats) run on what the game
really recorded, so the demo, the robot and the simulator are measured by the
same code. An answer taken back with the researcher's undo is not a trial of
the problem: it is left out here, and stays marked in the records.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from kasparctl.learning.learner import LearnerParams, entropy_bits, softmax
from kasparctl.learning.study_stats import ProblemRecord, TrialRecord


def undone_trials(records: Sequence[dict[str, Any]]) -> set[int]:
    return {int(r["trial"]) for r in records if r.get("kind") == "undo"}


def problems_from_records(
    records: Sequence[dict[str, Any]],
    toys: Sequence[str],
    answer_key: Sequence[str],
    params: LearnerParams,
    group: int = 0,
) -> list[ProblemRecord]:
    """One ProblemRecord per target the session guessed at, in the order it did."""
    undone = undone_trials(records)
    by_target: dict[int, list[dict[str, Any]]] = {}
    for record in records:
        if record.get("kind") == "trial" and int(record["trial"]) not in undone:
            by_target.setdefault(int(record["target_index"]), []).append(record)
    problems = []
    for target, trials in by_target.items():
        last = trials[-1]
        learned = int(last["choice_index"]) if last.get("learned") else None
        candidates = np.array([toy in last["candidates"] for toy in toys])
        q_after = np.array(last["q_after"], dtype=np.float64)
        answer = toys.index(answer_key[target]) if answer_key else None
        problems.append(
            ProblemRecord(
                group=group,
                target=target,
                answer=answer,
                trials=tuple(
                    TrialRecord(
                        choice=int(t["choice_index"]),
                        feedback=t["feedback"] == "green",
                        entropy=float(t["entropy"]),
                        correct=t.get("correct"),
                    )
                    for t in trials
                ),
                learned=learned,
                final_q=tuple(float(q) for q in q_after),
                entropy_after=entropy_bits(softmax(q_after, params.beta, candidates)),
            )
        )
    return problems
