"""The children's green and red keys: the answer to the open question, or a press to record.

A question is open from the moment Kaspar starts asking; a press before the
question is finished is early, recorded and ignored (a child pressing while
Kaspar still speaks has not heard the question). A press soon after an answer
is an extra (a second child a moment too late), recorded with the trial it
followed. Any other press has no question to answer.
"""

from __future__ import annotations

import asyncio
import math

from kasparctl.game.records import PressRecord

Press = tuple[str, float]  # the key ("green" or "red") and when it went down


class ChildPresses:
    """The one open question's answer, and what every other press was."""

    def __init__(self, extra_press_gap_s: float) -> None:
        """A press this close after an answer is an extra, not a press without a question."""
        self.extra_press_gap_s = extra_press_gap_s
        self._answer: asyncio.Future[Press] | None = None
        self.question_end = 0.0
        self._last_answer_at: float | None = None
        self._last_answer_trial = 0

    def open(self, question_end: float = math.inf) -> asyncio.Future[Press]:
        """Open a question; presses before `question_end` (set later by `asked`) are early."""
        self._answer = asyncio.get_running_loop().create_future()
        self.question_end = question_end
        return self._answer

    def asked(self, at: float) -> None:
        """The question is finished: from `at` on, a press answers it."""
        self.question_end = at

    def press(self, button: str, at: float, stage: str) -> PressRecord | None:
        """Take a press: None if it answered the open question, else the record to write."""
        answer, last = self._answer, self._last_answer_at
        if answer is not None and not answer.done():
            if at >= self.question_end:
                answer.set_result((button, at))
                return None
            reason = "before the question was finished"
        elif last is not None and at - last <= self.extra_press_gap_s:
            return PressRecord(button=button, at=at, extra=True, trial=self._last_answer_trial)
        else:
            reason = f"no question open ({stage})"
        return PressRecord(button=button, at=at, ignored=reason)

    def answered(self, at: float, trial: int) -> None:
        """The answer pressed at `at` was recorded as trial `trial`."""
        self._last_answer_at, self._last_answer_trial = at, trial

    def forget_answer(self) -> None:
        """The last answer was taken back: a press after it is no extra."""
        self._last_answer_at = None

    def close(self) -> None:
        """The question is abandoned (its step was left): nobody waits for its answer."""
        if self._answer is not None and not self._answer.done():
            self._answer.cancel()
        self._answer = None
