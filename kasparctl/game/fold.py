"""One reading of a session's records: what every reader of them takes as settled.

The game's own state (kasparctl.game.state.GameState, which a resume replays),
STATUS= (kasparctl.service.status), the live view (kasparctl.view.fold) and the
research exports and statistics (kasparctl.research.walk and what reads it) all
ask the same questions of the records: which targets are learned (with which
name), which are given up, whether Kaspar is confused (about which target, and
why), what the researcher's undo would take back, which targets were re-opened,
and for each guess whether it is a perseverative error or a win-shift. This
module answers them once. GameState applies the rules below to its snapshot's
fields; `Reading` folds the records alone into `Facts` for the readers, with the
very same rules. tests/test_one_reading.py plays games with every kind of
record and holds the readers together after each one.

The rules:

- **Learned**: the answer that completed a target says so (its trial record's
  `learned`). A re-open makes it learned no more; an undo of that answer, too.
- **Given up**: a target not learned after the session's limit of guesses
  (GameSettings.max_trials_per_target). The records do not say the limit: a
  reader given it knows at the answer itself; one without it knows when the
  game moves on, at the next question (or trial) on another target, or the
  farewell, since the game leaves a target only once it is done.
- **Confused**: from Kaspar's confused record, and only about a target still
  open: it ends once that target is done (learned, or given up: nothing more is
  asked about it, so there is nothing left to tell the researcher about it), at
  a re-open, or with the undo of the answer that showed it. A re-open taken back
  puts it back.
- **Flags**: a guess is compared with the answer before it on the same target,
  in the same asking of it: the target's first guess follows none, nor does the
  first guess after its name was re-opened (the green that had taught it was
  taken back), and an undone answer is not one to follow. The paper's
  definitions of the two flags are kasparctl.learning.study_stats'.
- **Undo**: takes back the last answer, or the last re-open; what it changed
  is as it was before, and nothing more can be undone until the next one.
- **Who answered**: a trial's answer is credited to the child the records credit
  (with one keyfob per child, the seat's child: `credited_index`), else to the
  child asked; the children out of the rotation are those the researcher's
  "away" took out and has not brought back (kasparctl.game.rotation).

Pure: no I/O, no clock; nothing raises on records that do not fit (a reader
reads sessions it did not write): a record that cannot apply changes nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import msgspec
from msgspec.structs import replace

from kasparctl.game.records import (
    AnyRecord,
    ConfusedRecord,
    QuestionRecord,
    ReopenRecord,
    RotationRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.learning.study_stats import is_perseverative, is_win_shift

# What a perseverative error or a win-shift followed: the children's answer before it
# was right (Kaspar's own exploration, as the paper attributes its events), or wrong (a
# red for the right toy, a green for a wrong one), or cannot be checked (no answer key).
EXPLORATORY = "exploratory"
AFTER_WRONG_FEEDBACK = "after_wrong_feedback"
UNKNOWN = "unknown"
# More targets than any game has: a record naming one further is damage, and read as none.
MAX_TARGETS = 1024

# -- the rules, as GameState applies them to its own fields ----------------------------


def flags(previous: tuple[int, bool] | None, choice: int) -> tuple[bool, bool]:
    """(perseverative, win_shift) of guessing `choice` after `previous`, the answer
    (label, green) it follows on its target; None: it follows none."""
    if previous is None:
        return False, False
    label, green = previous
    return is_perseverative(label, green, choice), is_win_shift(label, green, choice)


def followed(choice: int, green: bool, done: bool) -> tuple[int, bool] | None:
    """What the next guess on a target follows once `choice` was answered: that answer,
    unless it made the target done (the next guess is on another target)."""
    return None if done else (choice, green)


def standing(confused: int | None, done: Sequence[bool]) -> int | None:
    """The confusion that stands: `confused` (a target), unless that target is done."""
    if confused is None or not 0 <= confused < len(done) or done[confused]:
        return None
    return confused


# -- the facts every reader asks for -----------------------------------------------------


class Learned(msgspec.Struct, frozen=True):
    """The name learned for a target, and when."""

    label: int
    name: str
    problem_trial: int  # the guesses it took
    trial: int  # the session's trial that taught it


class Target(msgspec.Struct, frozen=True):
    """One target as the records have it so far."""

    index: int
    name: str = ""
    trials: int = 0  # guesses that count (an undone answer is taken back)
    learned: Learned | None = None
    given_up: bool = False
    reopened: int = 0  # the researcher's re-opens of its name, less those taken back

    @property
    def done(self) -> bool:
        """Learned or given up: nothing more is asked about it."""
        return self.learned is not None or self.given_up


class Confusion(msgspec.Struct, frozen=True):
    """Kaspar said it is confused about `target` after trial `trial`, and what it told."""

    target: int
    target_name: str
    trial: int
    reason: str  # kasparctl.game.recovery: all_rejected or learned_elsewhere
    name: str | None  # learned_elsewhere: the name answered green here...
    learned_for: str | None  # ...learned for this other target
    # What the researcher's re-open would re-open then (the name learned last).
    reopen_target: str | None
    reopen_name: str | None


class Answer(msgspec.Struct, frozen=True):
    """The answer the next guess on its target follows."""

    target: int
    label: int
    green: bool
    right: bool | None  # the children's answer agreed with the answer key (None: no key)


class Undoable(msgspec.Struct, frozen=True):
    """What the researcher's undo would take back: the last answer, or the last re-open."""

    what: Literal["answer", "reopen"]
    trial: int  # the answer's trial; for a re-open, the trials recorded before it
    target: int


class Guess(msgspec.Struct, frozen=True):
    """One trial as the records read when it was answered."""

    trial: int
    target: int
    perseverative: bool
    win_shift: bool
    # For a perseverative error or a win-shift: what it followed (EXPLORATORY...).
    cause: str | None
    # Asked while Kaspar was confused about its target.
    confused: bool
    # Its target's name had been re-opened by the researcher before it.
    reopened: bool
    # It follows no answer: its target's first guess, or the first after a re-open.
    first: bool
    # The child (place from 0) credited with the answer, and the seat (from 1) that
    # answered with one keyfob per child (None with one shared keyfob).
    credited: int = 0
    seat: int | None = None


class Facts(msgspec.Struct, frozen=True):
    """What the records say so far."""

    targets: tuple[Target, ...] = ()  # by index, as far as the records named them
    asking: int | None = None  # the target of the last question (or trial)
    previous: Answer | None = None
    confused: Confusion | None = None
    learned_order: tuple[int, ...] = ()  # the targets learned, the one learned last at the end
    undo: Undoable | None = None
    # The children (places from 0) the researcher took out of step 4's rotation.
    away: frozenset[int] = frozenset()

    def target(self, index: int) -> Target:
        """Target `index` (one the records have not named yet: nothing about it)."""
        return self.targets[index] if 0 <= index < len(self.targets) else Target(index)

    @property
    def learned(self) -> dict[int, int]:
        """Target -> the label learned for it."""
        return {t.index: t.learned.label for t in self.targets if t.learned is not None}

    @property
    def given_up(self) -> frozenset[int]:
        """The targets given up."""
        return frozenset(t.index for t in self.targets if t.given_up)

    @property
    def reopens(self) -> int:
        """Names the researcher re-opened, less those taken back."""
        return sum(t.reopened for t in self.targets)

    def with_target(self, target: Target) -> Facts:
        """These facts with `target` as it is now (and the ones before it named); the same
        facts for an index no game has (a damaged record)."""
        if not 0 <= target.index < MAX_TARGETS:
            return self
        targets = list(self.targets)
        targets.extend(Target(i) for i in range(len(targets), target.index + 1))
        targets[target.index] = target
        return replace(self, targets=tuple(targets))

    def settled(self) -> Facts:
        """These facts with the confusion that stands (none about a target done)."""
        confused = self.confused
        if confused is None or not self.target(confused.target).done:
            return self
        return replace(self, confused=None)


class Reading:
    """The facts of a session's records, moved on one record at a time.

    `limit`: the session's max_trials_per_target, if the reader knows it (the game
    does); without it a give-up is read when the game moves on from the target.
    """

    def __init__(self, limit: int | None = None) -> None:
        """The facts of a session with no records yet."""
        self.limit = limit
        self.facts = Facts()
        # The facts as they were before what the undo would take back.
        self._before_undoable: Facts | None = None

    def apply(self, record: AnyRecord) -> Guess | None:
        """Move on by `record`; for a trial, how it reads (its flags, asked while confused...)."""
        if isinstance(record, TrialRecord):
            return self._trial(record)
        if isinstance(record, QuestionRecord):
            self.facts = self._asking(record.target_index, record.target)
        elif isinstance(record, UndoRecord):
            self._undo(record)
        elif isinstance(record, ReopenRecord):
            self._reopen(record)
        elif isinstance(record, ConfusedRecord):
            self._confused(record)
        elif isinstance(record, StepRecord) and record.to == "farewell":
            self._farewell()
        elif isinstance(record, RotationRecord) and record.event != "skipped":
            away = self.facts.away
            child = frozenset({record.child_index})
            self.facts = replace(
                self.facts, away=away | child if record.event == "away" else away - child
            )
        return None

    def _asking(self, index: int, name: str) -> Facts:
        """The facts once the game asks about target `index`: the one it moved on from after
        an answer that left it open was given up (read so where the limit is not known)."""
        facts = self.facts
        previous = facts.previous
        if previous is not None and previous.target != index:
            gone = facts.target(previous.target)
            if self.limit is None and not gone.done:
                facts = facts.with_target(replace(gone, given_up=True))
            facts = replace(facts, previous=None)
        target = facts.target(index)
        if name and target.name != name:
            facts = facts.with_target(replace(target, name=name))
        elif target.index >= len(facts.targets):
            facts = facts.with_target(target)  # named by the records from now on
        if facts.asking != index:
            facts = replace(facts, asking=index)
        return facts.settled()

    def _trial(self, record: TrialRecord) -> Guess:
        facts = self._asking(record.target_index, record.target)
        index, choice = record.target_index, record.choice_index
        target = facts.target(index)
        previous = facts.previous if facts.previous and facts.previous.target == index else None
        perseverative, win_shift = flags(
            None if previous is None else (previous.label, previous.green), choice
        )
        cause = None
        if previous is not None and (perseverative or win_shift):
            right = previous.right
            cause = UNKNOWN if right is None else (EXPLORATORY if right else AFTER_WRONG_FEEDBACK)
        confused = facts.confused
        guess = Guess(
            trial=record.trial,
            target=index,
            perseverative=perseverative,
            win_shift=win_shift,
            cause=cause,
            confused=confused is not None and confused.target == index,
            reopened=target.reopened > 0,
            first=previous is None,
            credited=(
                record.credited_index
                if isinstance(record.credited_index, int)
                else record.child_index
            ),
            seat=record.seat if isinstance(record.seat, int) else None,
        )
        trials = target.trials + 1
        learned = (
            Learned(choice, record.choice, trials, record.trial) if record.learned else None
        )
        given_up = learned is None and self.limit is not None and trials >= self.limit
        answered = replace(target, trials=trials, learned=learned, given_up=given_up)
        order = facts.learned_order
        if learned is not None:
            order = (*(t for t in order if t != index), index)
        self._before_undoable = facts
        after = answered.done
        self.facts = replace(
            facts.with_target(answered),
            previous=None
            if after
            else Answer(index, choice, record.green, record.feedback_right),
            learned_order=order,
            undo=Undoable("answer", record.trial, index),
        ).settled()
        return guess

    def _undo(self, record: UndoRecord) -> None:
        undo, before = self.facts.undo, self._before_undoable
        if undo is None or undo.what != "answer" or undo.trial != record.trial or before is None:
            return  # not the last answer: the game refuses such an undo
        self.facts = replace(before, asking=undo.target, undo=None)
        self._before_undoable = None

    def _reopen(self, record: ReopenRecord) -> None:
        facts, index = self.facts, record.target_index
        if record.taken_back is True:
            undo, before = facts.undo, self._before_undoable
            if undo is not None and undo.what == "reopen" and undo.target == index and before:
                self.facts = replace(before, undo=None)
                self._before_undoable = None
            return
        target = facts.target(index)
        if target.learned is None:
            return  # nothing learned to re-open: the game refuses such a re-open
        self._before_undoable = facts
        reopened = replace(
            target,
            name=record.target or target.name,
            learned=None,
            # Its guesses are not counted again: with none left, it is given up at once.
            given_up=self.limit is not None and target.trials >= self.limit,
            reopened=target.reopened + 1,
        )
        self.facts = replace(
            facts.with_target(reopened),
            learned_order=tuple(t for t in facts.learned_order if t != index),
            confused=None,
            undo=Undoable("reopen", record.trial, index),
        )

    def _confused(self, record: ConfusedRecord) -> None:
        if not 0 <= record.target_index < MAX_TARGETS:
            return  # about a target no game has: damage
        confusion = Confusion(
            target=record.target_index,
            target_name=record.target,
            trial=record.trial,
            reason=record.reason,
            name=record.name if isinstance(record.name, str) else None,
            learned_for=record.learned_for if isinstance(record.learned_for, str) else None,
            reopen_target=record.reopen_target,
            reopen_name=record.reopen_name,
        )
        self.facts = replace(self.facts, confused=confusion).settled()

    def _farewell(self) -> None:
        """The game says goodbye once every target is done: those not learned are given up."""
        facts = self.facts
        for target in facts.targets:
            if target.learned is None and target.trials > 0 and not target.given_up:
                facts = facts.with_target(replace(target, given_up=True))
        self.facts = replace(facts, previous=None).settled()


def read(records: Sequence[AnyRecord], limit: int | None = None) -> Facts:
    """The facts of `records`, in order."""
    reading = Reading(limit)
    for record in records:
        reading.apply(record)
    return reading.facts
