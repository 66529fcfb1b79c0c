"""The children's green and red keys: when a press is the answer, and what every other press is.

Kaspar listens when it has asked. A question (or, in step 2, a request to show
a bag) is opened when Kaspar starts asking and is answered by the first press
from the moment it may be: the question's last words (the guess itself, where
the toy is named: a press there has heard the guess and is taken, recorded
with its time) or, for a request, its end. Before that a press is early: it
cannot judge a guess not yet made (the paper's children reward the choice
Kaspar announced), so it is never the answer, but it is never met with
silence either: Kaspar says once per question that it is still talking. A
press within SAME_GESTURE_S of an early one is part of it (the other button
of a squeeze, the second tap of a double), early too, even if the question's
last words began in between: a squeeze is the first button's, never the
second's.

After the answer, a press within `extra_press_gap_s` of the moment it was taken
(its key-down, or later for a hold decided at its release or its threshold) is an
extra (the second tap of a double, the other button of a squeeze, a second child
a moment too late), recorded with the trial it followed. Any other press has no
question to answer and is recorded as such.

One rule more, for a researcher who has only the children's keyfob: a gesture
that began while the children were being asked (from the start of a question
to `extra_press_gap_s` after its answer was taken, or after it was abandoned by
anything but the researcher's own command on the keyfob) is the children's, whatever
it became (a hold of 3 s, both buttons held): `asking_at` says so. Once Kaspar
has begun to ask for a grown-up's help (`hand_to_researcher`), a hold begun from
then on is the grown-up's again. A hold that reached the researcher's hold is
never the answer (`held`): a researcher's pause held during a question is the
same keys as a child's long hold, so neither is taken; the question stays open,
and a quick press (decided at its release on one keyfob) answers it.

Pure bookkeeping on the times it is given: the game (kasparctl.game.machine)
feeds it and acts on what it returns.
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from dataclasses import dataclass

from msgspec import UNSET

from kasparctl.game.records import PressRecord

Press = tuple[str, float]  # the key ("green" or "red") and when it went down

EARLY = "before the question was finished"
HELD = "held as long as a researcher's command: not an answer"
# Presses this close together are one gesture: a squeeze of both buttons, a double tap.
SAME_GESTURE_S = 0.4
# How many past questions `asking_at` remembers: a hold decided 3 s after its
# key-down may look back past the next question's start.
_REMEMBERED = 4


@dataclass(frozen=True, slots=True)
class Outcome:
    """What a press was: the answer (record None), or a record to write; `acknowledge`
    when Kaspar should say it is still talking (the first early press of a question)."""

    record: PressRecord | None
    acknowledge: bool = False


class ChildPresses:
    """The one open question's answer, and what every other press was."""

    def __init__(self, extra_press_gap_s: float) -> None:
        """A press this close after an answer is an extra, not a press without a question."""
        self.extra_press_gap_s = extra_press_gap_s
        self._answer: asyncio.Future[Press] | None = None
        self.question_start = math.inf
        # From here a press answers: the last words, or the end of the question.
        self.answers_from = math.inf
        self.question_end = math.inf
        self._acknowledged = False
        self._last_early_at = -math.inf
        self._last_answer_at: float | None = None  # when the last answer was taken
        self._last_answer_trial: int | None = None
        self._taken_at = -math.inf
        # (start, end) of the recent times the children were asked; end inf while open.
        self._asked: deque[tuple[float, float]] = deque(maxlen=_REMEMBERED)
        # When Kaspar began to ask for a grown-up's help with the open question.
        self.handed_at = math.inf

    @property
    def waiting(self) -> bool:
        """A question is open and not yet answered."""
        return self._answer is not None and not self._answer.done()

    def open(self, at: float) -> asyncio.Future[Press]:
        """Kaspar starts asking at `at`: presses are early until `last_words` or `asked`."""
        self.close(at)
        self._answer = asyncio.get_running_loop().create_future()
        self.question_start = at
        self.answers_from = self.question_end = math.inf
        self._acknowledged = False
        self._last_early_at = -math.inf
        self.handed_at = math.inf
        self._asked.append((at, math.inf))
        return self._answer

    def last_words(self, at: float) -> None:
        """Kaspar says the guess itself from `at`: a press from here is the answer."""
        self.answers_from = min(self.answers_from, at)

    def asked(self, at: float) -> None:
        """The question is finished at `at` (its question_end): a press answers it."""
        self.question_end = at
        self.answers_from = min(self.answers_from, at)

    def hand_to_researcher(self, at: float) -> None:
        """Kaspar asks for a grown-up from `at`: a press still answers, a hold begun from
        then on is a command."""
        self.handed_at = min(self.handed_at, at)

    def press(self, button: str, at: float, stage: str, now: float | None = None) -> Outcome:
        """Take a press that went down at `at` and is certain at `now` (`at` if not given):
        the answer of the open question, or what to record instead."""
        answer, last = self._answer, self._last_answer_at
        taken = at if now is None else max(at, now)
        if answer is not None and not answer.done():
            if at >= self.answers_from and at - self._last_early_at > SAME_GESTURE_S:
                answer.set_result((button, at))
                self._taken_at = taken
                self._end_asking(taken + self.extra_press_gap_s)
                return Outcome(None)
            first = not self._acknowledged
            self._acknowledged = True
            self._last_early_at = at
            record = PressRecord(
                button=button,
                at=at,
                ignored=EARLY,
                early=True,
                acknowledged=True if first else UNSET,
            )
            return Outcome(record, acknowledge=first)
        if last is not None and at - last <= self.extra_press_gap_s:
            return Outcome(self.extra(button, at))
        return Outcome(PressRecord(button=button, at=at, ignored=f"no question open ({stage})"))

    def held(self, button: str, at: float, gesture: str, stage: str) -> PressRecord:
        """The record of a hold begun at `at` that reached the researcher's hold and is no
        command: never the answer; the open question stays open."""
        last = self._last_answer_at
        if self.waiting:
            return PressRecord(button=button, at=at, gesture=gesture, ignored=HELD)
        if last is not None and at - last <= self.extra_press_gap_s:
            return self.extra(button, at, gesture=gesture)
        return PressRecord(
            button=button, at=at, gesture=gesture, ignored=f"no question open ({stage})"
        )

    def extra(self, button: str, at: float, gesture: str | None = None) -> PressRecord:
        """The record of an extra: a press (or what the answer's press went on to be)."""
        return PressRecord(
            button=button,
            at=at,
            gesture=UNSET if gesture is None else gesture,
            extra=True,
            trial=UNSET if self._last_answer_trial is None else self._last_answer_trial,
        )

    def asking_at(self, at: float) -> bool:
        """Whether the children were being asked at `at` (a gesture begun then is theirs).

        False once Kaspar has handed the open question to the researcher.
        """
        if self.waiting and at >= self.handed_at:
            return False
        return any(start <= at <= end for start, end in self._asked)

    def answered(self, at: float, trial: int | None) -> None:
        """The answer pressed at `at` was recorded (as trial `trial`; None for a pose)."""
        self._last_answer_at = max(at, self._taken_at)
        self._last_answer_trial = trial

    def forget_answer(self) -> None:
        """The last answer was taken back: a press after it is no extra."""
        self._last_answer_at = None

    def close(self, at: float, grace: bool = True) -> None:
        """The question is abandoned at `at` (its step was left): nobody waits for its answer.

        With `grace`, a gesture begun within `extra_press_gap_s` after is still the
        children's (a child mid-press as a fault stops the step), as after an answer;
        without (the researcher's own command on the keyfob left it: they held the
        keyfob), their next hold is theirs at once.
        """
        if self._answer is not None and not self._answer.done():
            self._answer.cancel()
            self._end_asking(at + (self.extra_press_gap_s if grace else 0.0))
        self._answer = None

    def _end_asking(self, at: float) -> None:
        if self._asked and self._asked[-1][1] == math.inf:
            self._asked[-1] = (self._asked[-1][0], at)
