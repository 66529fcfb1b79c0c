"""Whose turn it is: children out of the rotation passed over, the researcher's one key "away"."""

from __future__ import annotations

from kasparctl.config import GameSettings
from kasparctl.game.records import RotationRecord
from kasparctl.game.rotation import away_command, skips
from kasparctl.game.state import GameState
from kasparctl.learning.learner import LearnerParams

NAMES = ("Amira", "Ben", "Cleo")


def name(index: int) -> str:
    return NAMES[index]


def state_at(turn: int) -> GameState:
    state = GameState.new(GameSettings(), LearnerParams(), seed=1)
    state.turn = turn
    return state


def apply(state: GameState, *records: RotationRecord) -> None:
    for record in records:
        state.apply(record, GameSettings())


def asked(state: GameState, absent: frozenset[int] = frozenset()) -> int:
    """The child the next question asks: after the turns passed over."""
    apply(state, *skips(state, 3, absent, name))
    return state.turn % 3


def test_away_takes_the_child_asked_out_and_the_rotation_keeps_its_order() -> None:
    state = state_at(1)  # Ben is asked
    taken = away_command(state, 3, name)
    assert taken is not None and (taken.event, taken.child_index) == ("away", 1)
    apply(state, taken)
    order = []
    for _ in range(4):  # four answers
        order.append(asked(state))
        state.turn += 1  # as an answer moves it on
    assert order == [2, 0, 2, 0]  # Cleo, Amira, Cleo, Amira: Ben's turns passed over


def test_away_right_after_a_skipped_turn_brings_that_child_back_and_asks_them() -> None:
    state = state_at(1)
    apply(state, away_command(state, 3, name))  # type: ignore[arg-type]
    assert asked(state) == 2  # Ben's turn passed over: Cleo
    back = away_command(state, 3, name)  # pressed again at once: a mistaken away undone
    assert back is not None and (back.event, back.child_index, back.turn) == ("back", 1, 1)
    apply(state, back)
    assert asked(state) == 1 and state.away == []


def test_one_cycle_later_away_brings_back_at_the_place_of_the_child_away() -> None:
    state = state_at(1)
    apply(state, away_command(state, 3, name))  # type: ignore[arg-type]
    assert asked(state) == 2
    state.turn += 1  # Cleo answers
    assert asked(state) == 0
    # Amira's question: the previous place is Cleo's, who is there: away takes Amira out.
    assert away_command(state, 3, name).event == "away"  # type: ignore[union-attr]
    state.turn += 1  # Amira answers
    assert asked(state) == 2  # Ben's place passed over again
    back = away_command(state, 3, name)
    assert back is not None and back.event == "back" and back.child_index == 1


def test_the_last_child_present_cannot_be_taken_out_and_a_child_alone_has_no_rotation() -> None:
    state = state_at(0)
    apply(
        state,
        RotationRecord(event="away", child="Ben", child_index=1, turn=0),
        RotationRecord(event="away", child="Cleo", child_index=2, turn=0),
    )
    assert away_command(state, 3, name) is None  # Amira is asked, and the only one left
    assert away_command(state_at(0), 1, name) is None


def test_a_seat_whose_keyfob_is_absent_is_passed_over_with_its_reason() -> None:
    state = state_at(1)
    (skipped,) = skips(state, 3, frozenset({1}), name, lambda child: child)
    assert (skipped.event, skipped.child_index, skipped.reason, skipped.seat) == (
        "skipped",
        1,
        "keyfob absent",
        2,
    )
    # Every child out: the question is asked all the same (nobody is passed over).
    assert skips(state, 3, frozenset({0, 1, 2}), name) == []
