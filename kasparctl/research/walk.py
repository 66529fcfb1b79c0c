"""One session's records in order, each with what the research tables add to it.

Streamed, so a session of any size is read in constant memory. What is added:

- for a trial: whether it was undone, and how the records read when it was
  answered (kasparctl.game.fold, the one reading the game, STATUS= and the live
  view share): its perseverative and win-shift flags, for either its cause
  ("after_wrong_feedback" when the children's answer to the guess it follows
  was wrong: a red for the right toy, a green for a wrong one; "exploratory"
  when that answer was right, Kaspar's own exploration as the paper attributes
  its events; "unknown" without an answer key), whether Kaspar was confused
  about its target, and whether its target had been re-opened;
- for a prompt while guessing, an extra press and an undo: the child it
  concerns (whose question went unanswered, whose answer got the extra
  press, whose answer was taken back), by place in the turn order. Children
  answer in rotation: the child of the next question is the rotation's turn
  modulo the group size, as the game counts it (an answer moves it on, an undo
  back, a `rotation` record sets it: a child away passed over); for a press of
  a seat's own keyfob, the seat's child, and for a rotation record, its child;
  for a prompt while guessing, also the trial of the question it repeated (the
  trial number that question's answer has or would have had);
- for every record, `session_clock`: seconds since the session's first record on
  a clock that runs on across resumes. The records' `clock` is the robot's
  monotonic clock, which starts again when the robot (or the demo) restarts; at
  a resume (or wherever `clock` goes back) the session clock carries on from the
  last record before it plus the wall-clock gap between the two records (none
  when the wall clock went back or cannot be read).
"""

from __future__ import annotations

import datetime as dt
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass, field

from kasparctl.game.fold import AFTER_WRONG_FEEDBACK, EXPLORATORY, UNKNOWN, Facts, Guess, Reading
from kasparctl.game.records import (
    AnyRecord,
    PressRecord,
    PromptRecord,
    QuestionRecord,
    Record,
    RotationRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.research.catalogue import SessionData

__all__ = ["AFTER_WRONG_FEEDBACK", "EXPLORATORY", "UNKNOWN", "Walked", "walk"]
# Undos and extra presses refer to the last answer; a few hundred back is plenty.
_RECENT_TRIALS = 256


@dataclass(frozen=True, slots=True)
class Walked:
    """A record, the child it concerns (place in the turn order), and for a trial more."""

    record: AnyRecord
    child_index: int | None = None
    undone: bool = False
    # A trial as the records read when it was answered (kasparctl.game.fold).
    guess: Guess | None = None
    # What the records read once this one is applied: after the last record, what the
    # session ended with (a name re-opened and never asked again is not learned).
    facts: Facts = field(kw_only=True)  # required: no record may leave it out
    # Seconds since the session's first record, continuous across resumes.
    session_clock: float = field(default=0.0, kw_only=True)
    # For a prompt while guessing: the trial of the question it repeated.
    trial: int | None = field(default=None, kw_only=True)

    @property
    def cause(self) -> str | None:
        """For a perseverative error or a win-shift: EXPLORATORY, AFTER_WRONG_FEEDBACK or
        UNKNOWN."""
        return None if self.guess is None else self.guess.cause


# The phrase keys of the check of the buttons at a session's start (kasparctl.game.buttons).
CHECK_LINES = "buttons."


class SessionClock:
    """The records' clock made continuous across the restarts of the robot."""

    def __init__(self) -> None:
        """A clock that has seen no record."""
        self.offset: float | None = None
        self.last: tuple[float, str] = (0.0, "")  # the last record's session clock, time

    def read(self, record: Record) -> float:
        """The session clock of `record` (records in order)."""
        clock = record.clock
        last_clock, last_time = self.last
        resumed = isinstance(record, SessionRecord) and record.event is SessionEvent.RESUMED
        if self.offset is None:
            self.offset = -clock
        elif resumed or clock + self.offset < last_clock:
            self.offset = last_clock + _gap(last_time, record.time) - clock
        now = clock + self.offset
        self.last = (now, record.time)
        return now


def _gap(before: str, after: str) -> float:
    """Seconds of wall clock from `before` to `after` (ISO 8601); 0 if unknown or back."""
    try:
        seconds = dt.datetime.fromisoformat(after) - dt.datetime.fromisoformat(before)
    except (ValueError, TypeError):
        return 0.0
    return max(0.0, seconds.total_seconds())


def walk(session: SessionData) -> Iterator[Walked]:
    """Every record of the session, streamed, with its child and (for trials) cause."""
    undone = session.index.undone
    size = session.group_size
    step = ""
    turn = 0
    # trial -> (its child, the rotation's turn before it): an undo goes back there.
    recent: OrderedDict[int, tuple[int, int]] = OrderedDict()
    # The research is not told the session's limit of guesses: a give-up is read when
    # the game moves on, which is before any later trial.
    reading = Reading()
    clock = SessionClock()
    asked: int | None = None  # the trial of the question waiting for its answer
    for record in session.records():
        guess = reading.apply(record)
        now = clock.read(record)
        if isinstance(record, TrialRecord):
            recent[record.trial] = (record.child_index, turn)
            if len(recent) > _RECENT_TRIALS:
                recent.popitem(last=False)
            turn += 1
            asked = None
            undone_now = record.trial in undone
            yield Walked(
                record,
                record.child_index,
                undone_now,
                guess,
                facts=reading.facts,
                session_clock=now,
            )
        elif isinstance(record, UndoRecord):
            child, turn = recent.get(record.trial, (None, turn - 1))
            yield Walked(record, child, facts=reading.facts, session_clock=now)
        elif isinstance(record, RotationRecord):
            turn = record.turn  # a child out of the rotation passed over, taken out, back
            yield Walked(record, record.child_index, facts=reading.facts, session_clock=now)
        elif isinstance(record, PressRecord):
            if isinstance(record.pressed_by_index, int):  # a seat's own keyfob
                yield Walked(
                    record, record.pressed_by_index, facts=reading.facts, session_clock=now
                )
                continue
            extra = record.extra is True and isinstance(record.trial, int)
            answered = recent.get(record.trial) if extra else None  # type: ignore[arg-type]
            yield Walked(
                record,
                None if answered is None else answered[0],
                facts=reading.facts,
                session_clock=now,
            )
        elif isinstance(record, PromptRecord):
            # A prompt of the check of the buttons is to the whole group, no child's turn.
            turn_taking = step == "guessing" and not record.line.startswith(CHECK_LINES)
            yield Walked(
                record,
                turn % size if turn_taking else None,
                facts=reading.facts,
                session_clock=now,
                trial=asked if turn_taking else None,
            )
        else:
            if isinstance(record, StepRecord):
                step = record.to
            elif isinstance(record, QuestionRecord):
                asked = record.trial
            yield Walked(record, facts=reading.facts, session_clock=now)
