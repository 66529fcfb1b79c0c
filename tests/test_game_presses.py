"""The children's keys: an answer, an early press, an extra, a press with no question."""

from __future__ import annotations

import asyncio

import pytest

from kasparctl.game.presses import ChildPresses
from kasparctl.game.records import PressRecord


async def test_a_press_before_the_question_is_finished_is_early_and_ignored() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    answer = presses.open()
    assert presses.press("green", 3.0, "guessing") == PressRecord(
        button="green", at=3.0, ignored="before the question was finished"
    )
    presses.asked(4.0)
    assert presses.press("red", 4.0, "guessing") is None
    assert await answer == ("red", 4.0)


async def test_an_extra_press_follows_an_answer_within_the_gap() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    presses.open(question_end=0.0)
    assert presses.press("green", 2.0, "guessing") is None
    presses.answered(2.0, trial=7)
    assert presses.press("green", 3.0, "guessing") == PressRecord(
        button="green", at=3.0, extra=True, trial=7
    )
    assert presses.press("red", 3.5, "guessing") == PressRecord(
        button="red", at=3.5, ignored="no question open (guessing)"
    )
    presses.answered(4.0, trial=8)
    presses.forget_answer()  # undone: a press now has no question, it is no extra
    assert presses.press("red", 4.5, "guessing") == PressRecord(
        button="red", at=4.5, ignored="no question open (guessing)"
    )


async def test_closing_abandons_the_question() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    answer = presses.open(question_end=0.0)
    presses.close()
    with pytest.raises(asyncio.CancelledError):
        await answer
    assert presses.press("green", 1.0, "paused") == PressRecord(
        button="green", at=1.0, ignored="no question open (paused)"
    )
