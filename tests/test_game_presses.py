"""The children's keys: when a press is the answer, an early press, an extra, no question."""

from __future__ import annotations

import asyncio
import math

import pytest

from kasparctl.game.presses import EARLY, ChildPresses
from kasparctl.game.records import PressRecord


async def test_a_press_before_the_last_words_is_early_acknowledged_once_and_never_the_answer() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    answer = presses.open(1.0)
    first = presses.press("green", 2.0, "guessing")
    assert first.record == PressRecord(
        button="green", at=2.0, ignored=EARLY, early=True, acknowledged=True
    )
    assert first.acknowledge
    second = presses.press("red", 2.5, "guessing")
    assert second.record == PressRecord(button="red", at=2.5, ignored=EARLY, early=True)
    assert not second.acknowledge  # Kaspar says it once per question
    presses.last_words(3.0)  # the guess itself: "Sam, is it the lion?"
    assert presses.press("red", 3.4, "guessing").record is None
    presses.asked(4.0)
    assert await answer == ("red", 3.4)  # taken, with its own time (before question_end)
    assert presses.question_end == 4.0


async def test_a_request_without_last_words_answers_from_its_end() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    answer = presses.open(0.0)
    assert presses.press("green", 0.5, "teaching").record is not None  # still asking
    presses.asked(1.0)
    assert presses.press("green", 1.0, "teaching").record is None
    assert await answer == ("green", 1.0)


async def test_an_extra_press_follows_an_answer_within_the_gap() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    presses.open(0.0)
    presses.asked(0.0)
    assert presses.press("green", 2.0, "guessing").record is None
    presses.answered(2.0, trial=7)
    assert presses.press("green", 3.0, "guessing").record == PressRecord(
        button="green", at=3.0, extra=True, trial=7
    )
    assert presses.press("red", 3.5, "guessing").record == PressRecord(
        button="red", at=3.5, ignored="no question open (guessing)"
    )
    presses.answered(4.0, trial=8)
    presses.forget_answer()  # undone: a press now has no question, it is no extra
    assert presses.press("red", 4.5, "guessing").record == PressRecord(
        button="red", at=4.5, ignored="no question open (guessing)"
    )


async def test_what_an_answers_press_became_is_an_extra_of_its_trial() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    presses.open(0.0)
    presses.asked(1.0)
    presses.press("green", 2.0, "guessing")
    presses.answered(2.0, trial=3)
    assert presses.extra("green", 2.0, gesture="long green") == PressRecord(
        button="green", at=2.0, gesture="long green", extra=True, trial=3
    )


async def test_closing_abandons_the_question() -> None:
    presses = ChildPresses(extra_press_gap_s=1.0)
    answer = presses.open(0.0)
    presses.asked(0.5)
    presses.close(0.7)
    with pytest.raises(asyncio.CancelledError):
        await answer
    assert presses.press("green", 1.0, "paused").record == PressRecord(
        button="green", at=1.0, ignored="no question open (paused)"
    )


async def test_a_gesture_begun_while_the_children_are_asked_is_theirs() -> None:
    """The one-keyfob rule: a hold is a command only if it began while nobody was asked
    (from a question's start to the gap for extras after its answer), or once Kaspar has
    asked for a grown-up's help."""
    presses = ChildPresses(extra_press_gap_s=1.0)
    assert not presses.asking_at(0.5)  # nothing asked yet
    presses.open(1.0)
    assert presses.asking_at(1.0) and presses.asking_at(1.5)
    presses.asked(2.0)
    assert presses.asking_at(3.0)  # the question waits for its answer
    presses.press("green", 4.0, "guessing")  # answered: a hold begun here is still theirs,
    assert presses.asking_at(4.0)
    assert presses.asking_at(4.9)  # and one begun as a late extra (within the gap),
    assert not presses.asking_at(5.1)  # but not once Kaspar reacts: nobody is asked
    presses.open(6.0)
    presses.asked(7.0)
    assert presses.asking_at(8.0)
    presses.hand_to_researcher(20.0)  # "I need a grown-up to help me."
    assert presses.asking_at(19.0)  # a child's hold begun before is still theirs
    assert not presses.asking_at(30.0)
    assert presses.asking_at(4.0)  # the last question's answer is remembered
    presses.close(31.0)
    assert not presses.asking_at(math.inf)


async def test_a_held_answer_counts_its_extras_from_when_it_was_taken() -> None:
    """A hold decided 3 s after its key-down: a second child's press 0.5 s after that is
    an extra of it, not a press with no question."""
    presses = ChildPresses(extra_press_gap_s=1.0)
    presses.open(0.0)
    presses.asked(1.0)
    assert presses.press("green", 2.0, "guessing", now=5.0).record is None
    presses.answered(2.0, trial=4)
    assert presses.press("red", 5.5, "guessing").record == PressRecord(
        button="red", at=5.5, extra=True, trial=4
    )
    assert presses.asking_at(5.9) and not presses.asking_at(6.1)


async def test_a_squeeze_begun_early_is_early_whatever_its_second_button_meets() -> None:
    """Green early, red 0.05 s later as the guess begins: one squeeze, the first button's,
    so neither is the answer; a press well after it is."""
    presses = ChildPresses(extra_press_gap_s=1.0)
    answer = presses.open(0.0)
    assert presses.press("green", 2.95, "guessing").acknowledge
    presses.last_words(3.0)
    assert presses.press("red", 3.0, "guessing").record == PressRecord(
        button="red", at=3.0, ignored=EARLY, early=True
    )
    presses.asked(4.0)
    assert presses.press("green", 4.5, "guessing").record is None
    assert await answer == ("green", 4.5)


async def test_a_gesture_begun_just_after_a_question_was_abandoned_is_the_childrens() -> None:
    """A fault cuts a question off while a child is about to press: a hold begun within the
    gap for extras after is still theirs (on one keyfob, never a researcher's command)."""
    presses = ChildPresses(extra_press_gap_s=1.0)
    presses.open(10.0)
    presses.asked(12.0)
    presses.close(14.0)  # a fault, or a pause from the researcher's own device
    assert presses.asking_at(14.9)
    assert not presses.asking_at(15.1)
    # Cut off by the researcher's own hold on the keyfob: their next hold is theirs.
    presses.open(20.0)
    presses.close(24.0, grace=False)
    assert not presses.asking_at(24.1)
