"""The session's first check of the children's keyfob: Kaspar asks for a green, then a red.

At the start of every session (after the greeting: step 1 of the names game, or the
pilot's first words) Kaspar asks the children to press green, then red, and thanks
them. Each press is recorded as a `button_check` record (never a trial, never an
answer: the learner, the game's state and the research exports count no such
thing), and the check is played once in a game (a pause or a fault during it asks
again, from green). The researcher's "next" while it runs skips what is left of
it (a "next" before it begins moves on from the step, as ever). Nobody
pressing is met like an unanswered question: a prompt, then Kaspar asks for a
grown-up (and a keyfob silent through that while the researcher's device works is
reported as a flat battery, suspected: kasparctl.game.machine).

This module holds the check's state for a game's life and its records; the step
plays it (kasparctl.game.steps) and the machine skips it on "next".
"""

from __future__ import annotations

import asyncio

from kasparctl.game.records import Button, ButtonCheckRecord

# The buttons asked for, in order.
ASKED: tuple[Button, ...] = ("green", "red")


class ButtonCheck:
    """Whether this game has checked the buttons, and the researcher's skip while it runs."""

    def __init__(self) -> None:
        """Not checked yet, and not running."""
        self.done = False
        self._skip: asyncio.Event | None = None

    @property
    def running(self) -> bool:
        """Kaspar is checking the buttons now: the researcher's "next" skips the check
        (before it begins, during the greeting, "next" moves on from the step as ever)."""
        return self._skip is not None and not self.done

    def begin(self) -> asyncio.Event:
        """The check starts: the event the researcher's skip sets."""
        self._skip = asyncio.Event()
        return self._skip

    def skip(self) -> None:
        """The researcher's "next" while it runs: the rest of the check is skipped."""
        if self._skip is not None:
            self._skip.set()

    def end(self) -> None:
        """The check is over (every button pressed, or skipped): not played again."""
        self.done = True
        self._skip = None

    def left(self) -> None:
        """The check was cut off (a pause, a fault, a stop): asked again from the start."""
        self._skip = None


def pressed(asked: Button, button: str, at: float) -> ButtonCheckRecord:
    """The record of the press that answered the request for `asked`."""
    return ButtonCheckRecord(asked=asked, pressed=button, at=at)


def skipped(asked: Button) -> ButtonCheckRecord:
    """The record of a check skipped by the researcher while `asked` was asked for."""
    return ButtonCheckRecord(asked=asked, skipped=True)
