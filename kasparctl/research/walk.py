"""One session's records in order, each with what the research tables add to it.

Streamed, so a session of any size is read in constant memory. What is added:

- for a trial: whether it was undone, and for a perseverative error or a
  win-shift its cause: "after_wrong_feedback" when the children's answer to
  the guess before it on this target was wrong (a red for the right toy, a
  green for a wrong one), "exploratory" when that answer was right (Kaspar's
  own exploration, as the paper attributes its events), "unknown" without an
  answer key;
- for a prompt while guessing, an extra press and an undo: the child it
  concerns (whose question went unanswered, whose answer got the extra
  press, whose answer was taken back), by place in the turn order. Children
  answer in rotation: the child of the next question is (answers recorded -
  answers undone) modulo the group size, as the game counts it.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass

from kasparctl.game.records import (
    AnyRecord,
    PressRecord,
    PromptRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.research.catalogue import SessionData

EXPLORATORY = "exploratory"
AFTER_WRONG_FEEDBACK = "after_wrong_feedback"
UNKNOWN = "unknown"
# Undos and extra presses refer to the last answer; a few hundred back is plenty.
_RECENT_TRIALS = 256


@dataclass(frozen=True, slots=True)
class Walked:
    """A record, the child it concerns (place in the turn order), and for a trial more."""

    record: AnyRecord
    child_index: int | None = None
    undone: bool = False
    # For a perseverative error or a win-shift: EXPLORATORY, AFTER_WRONG_FEEDBACK or UNKNOWN.
    cause: str | None = None


def walk(session: SessionData) -> Iterator[Walked]:
    """Every record of the session, streamed, with its child and (for trials) cause."""
    undone = session.index.undone
    size = session.group_size
    step = ""
    turn = 0
    recent: OrderedDict[int, int] = OrderedDict()
    # The children's last counted answer on each target: was it right (None: no key)?
    last_right: dict[int, bool | None] = {}
    for record in session.records():
        if isinstance(record, TrialRecord):
            is_undone = record.trial in undone
            cause = None
            if record.perseverative or record.win_shift:
                right = last_right.get(record.target_index)
                cause = (
                    UNKNOWN if right is None else (EXPLORATORY if right else AFTER_WRONG_FEEDBACK)
                )
            if not is_undone:
                last_right[record.target_index] = record.feedback_right
            recent[record.trial] = record.child_index
            if len(recent) > _RECENT_TRIALS:
                recent.popitem(last=False)
            turn += 1
            yield Walked(record, record.child_index, is_undone, cause)
        elif isinstance(record, UndoRecord):
            turn -= 1
            yield Walked(record, recent.get(record.trial))
        elif isinstance(record, PressRecord):
            extra = record.extra is True and isinstance(record.trial, int)
            yield Walked(record, recent.get(record.trial) if extra else None)  # type: ignore[arg-type]
        elif isinstance(record, PromptRecord):
            yield Walked(record, turn % size if step == "guessing" else None)
        else:
            if isinstance(record, StepRecord):
                step = record.to
            yield Walked(record)
