"""GameState changes only by applying records; a snapshot plus later records is the same state."""

from __future__ import annotations

import json

import pytest

from kasparctl.config import GameSettings
from kasparctl.game.state import GameState, StateError, restore
from kasparctl.learning.learner import LearnerParams

GAME = GameSettings()  # names variant, 6 toys, 2 greens in a row
PARAMS = LearnerParams()


def trial(state: GameState, number: int, choice: int, green: bool) -> dict:
    rng_state = state.learner.rng.bit_generator.state
    q_row = state.learner.table[state.target].copy()
    reward = PARAMS.reward(green)
    q_row[choice] += PARAMS.alpha * (reward - q_row[choice])
    return {
        "kind": "trial",
        "trial": number,
        "target_index": state.target,
        "choice_index": choice,
        "feedback": "green" if green else "red",
        "q_after": q_row.tolist(),
        "learner_rng": rng_state,
    }


def plain_roundtrip(state: GameState) -> GameState:
    return GameState.from_plain(json.loads(json.dumps(state.to_plain())))


def test_learning_a_name_withdraws_it_and_moves_on() -> None:
    state = GameState.new(GAME, PARAMS, seed=1)
    state.apply({"kind": "step", "to": "guessing"}, GAME)
    for number, (choice, green) in enumerate([(3, False), (2, True), (2, True)], start=1):
        state.apply(trial(state, number, choice, green), GAME)
    assert state.trials == 3 and state.turn == 3
    assert state.progress[0].learned == 2
    assert state.offered == [True, True, False, True, True, True]
    assert state.target == 1 and state.previous is None
    assert state.learner.table[0, 3] == pytest.approx(-0.6)
    assert state.learner.table[0, 2] == pytest.approx(0.84)


def test_undo_takes_back_the_last_answer_only() -> None:
    state = GameState.new(GAME, PARAMS, seed=1)
    state.apply({"kind": "step", "to": "guessing"}, GAME)
    state.apply(trial(state, 1, 2, True), GAME)
    before = plain_roundtrip(state)
    state.apply(trial(state, 2, 2, True), GAME)  # learned: bag 2 is next, name 2 withdrawn
    assert state.target == 1
    state.apply({"kind": "undo", "trial": 2}, GAME)
    assert state.target == 0 and state.offered == before.offered
    assert state.learner.table.tolist() == before.learner.table.tolist()
    assert state.progress[0] == before.progress[0]
    assert state.turn == before.turn
    assert state.trials == 2  # numbers are never reused
    with pytest.raises(StateError, match="undo of trial 2: it is not the last answer"):
        state.apply({"kind": "undo", "trial": 2}, GAME)


def test_snapshot_plus_later_records_equals_the_live_state() -> None:
    live = GameState.new(GAME, PARAMS, seed=4)
    records = [{"kind": "step", "to": "teaching"}]
    records += [
        {"kind": "pose", "bag": b, "round": 0, "pose": {"elbow": float(b)}} for b in range(6)
    ]
    records += [{"kind": "step", "to": "guessing"}]
    snapshot = None
    for index, record in enumerate(records):
        live.apply(record, GAME)
        if index == 3:
            snapshot = live.to_plain()
    for number, (choice, green) in enumerate([(1, False), (4, True)], start=1):
        record = trial(live, number, choice, green)
        records.append(record)
        live.apply(record, GAME)
    live.apply({"kind": "command", "command": "pause", "applied": True, "confirm": "pause"}, GAME)
    records.append({"kind": "command", "command": "pause", "applied": True, "confirm": "pause"})
    restored = restore(json.loads(json.dumps(snapshot)), records[4:], GAME, PARAMS, seed=4)
    assert restored.to_plain() == live.to_plain()
    assert restored.teach_round == 1 and restored.poses["bag 6"] == {"elbow": 5.0}
    assert restored.paused
    from_nothing = restore(None, records, GAME, PARAMS, seed=4)
    assert from_nothing.to_plain() == live.to_plain()


def test_a_record_for_another_target_is_refused() -> None:
    state = GameState.new(GAME, PARAMS, seed=1)
    record = trial(state, 1, 0, True) | {"target_index": 3}
    with pytest.raises(StateError, match="trial 1: for target 3, state is at 0"):
        state.apply(record, GAME)


def test_a_damaged_snapshot_is_a_named_error() -> None:
    with pytest.raises(StateError, match="unusable game state snapshot"):
        GameState.from_plain({"step": "guessing"})
