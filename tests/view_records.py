"""Records made by hand for the view's tests: stamped in order, one second apart."""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

import msgspec

from kasparctl.game.records import AnyRecord, QuestionRecord, TrialRecord

T0 = dt.datetime(2026, 3, 2, 9, 0, 0, tzinfo=dt.UTC)
TOYS = ["lion", "elephant", "giraffe", "monkey", "zebra", "crocodile"]
PLAN = {
    "session": "20260302T090000-G7",
    "created": T0.isoformat(),
    "group": "G7",
    "condition": "paper/spoken",
    "variant": "names",
    "seed": 7,
    "plan": {"group": "G7", "profile": "paper", "speak_uncertainty": True, "children": []},
}


class Stamper:
    """Gives each record the next seq, a time one second later, and a clock to match."""

    def __init__(self) -> None:
        self.seq = 0

    def __call__(self, record: AnyRecord) -> AnyRecord:
        self.seq += 1
        return msgspec.structs.replace(
            record,
            seq=self.seq,
            time=(T0 + dt.timedelta(seconds=self.seq)).isoformat(),
            clock=float(self.seq),
        )

    def time_of(self, seq: int) -> dt.datetime:
        return T0 + dt.timedelta(seconds=seq)


def entropy(probabilities: list[float]) -> float:
    return -sum(p * math.log2(p) for p in probabilities if p > 0)


def question(
    trial: int,
    target: int = 0,
    choice: str = "lion",
    offered: list[str] | None = None,
    child: str = "child one",
    problem_trial: int = 1,
) -> QuestionRecord:
    """A question with the probabilities spread evenly over the offered toys."""
    offered = offered if offered is not None else TOYS
    probabilities = [1 / len(offered) if toy in offered else 0.0 for toy in TOYS]
    return QuestionRecord(
        trial=trial,
        problem_trial=problem_trial,
        target=f"bag {target + 1}",
        target_index=target,
        child=child,
        child_index=0,
        candidates=[toy for toy in TOYS if toy in offered],
        probabilities=probabilities,
        entropy=entropy(probabilities),
        band="no_idea",
        choice=choice,
        choice_index=TOYS.index(choice),
    )


def trial(asked: QuestionRecord, feedback: str = "green", **changes: Any) -> TrialRecord:
    """The answer to `asked`."""
    fields: dict[str, Any] = {
        "trial": asked.trial,
        "problem_trial": asked.problem_trial,
        "step": "guessing",
        "target": asked.target,
        "target_index": asked.target_index,
        "child": asked.child,
        "child_index": asked.child_index,
        "candidates": asked.candidates,
        "probabilities": asked.probabilities,
        "entropy": asked.entropy,
        "band": asked.band,
        "spoken": ["I have no idea.", f"Is it the {asked.choice}?"],
        "choice": asked.choice,
        "choice_index": asked.choice_index,
        "feedback": feedback,
        "question_end": 1.0,
        "feedback_at": 2.5,
        "reaction_time": 1.5,
        "reward": 1.0 if feedback == "green" else -1.0,
        "q_before": [0.0] * 6,
        "q_after": [0.0] * 6,
        "learner_rng": {},
        "perseverative": False,
        "win_shift": False,
        "correct": None,
        "feedback_right": None,
        "learned": False,
    }
    fields.update(changes)
    return TrialRecord(**fields)
