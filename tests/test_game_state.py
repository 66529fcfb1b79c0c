"""GameState changes only by applying records; a snapshot plus later records is the same state."""

from __future__ import annotations

import json

import msgspec
import pytest

from kasparctl.config import GameSettings
from kasparctl.game.records import (
    CommandRecord,
    Confirmation,
    PoseRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.session import state_from_plain, state_to_plain
from kasparctl.game.state import GameState, StateError, restore
from kasparctl.learning.learner import LearnerParams
from kasparctl.vocabulary import Command

GAME = GameSettings()  # names variant, 6 toys, 2 greens in a row
PARAMS = LearnerParams()


def trial(state: GameState, number: int, choice: int, green: bool) -> TrialRecord:
    """A trial record with the fields apply reads computed, the others plausible."""
    rng_state = state.learner.rng.bit_generator.state
    q_row = state.learner.table[state.target].copy()
    reward = PARAMS.reward(green)
    q_row[choice] += PARAMS.alpha * (reward - q_row[choice])
    return TrialRecord(
        trial=number,
        problem_trial=1,
        step="guessing",
        target=GAME.targets[state.target],
        target_index=state.target,
        child="child one",
        child_index=0,
        candidates=list(GAME.toys),
        probabilities=[1 / 6] * 6,
        entropy=2.585,
        band=None,
        spoken=[],
        choice=GAME.toys[choice],
        choice_index=choice,
        feedback="green" if green else "red",
        question_end=0.0,
        feedback_at=1.0,
        reaction_time=1.0,
        reward=reward,
        q_before=state.learner.table[state.target].tolist(),
        q_after=q_row.tolist(),
        learner_rng=rng_state,
        perseverative=False,
        win_shift=False,
        correct=None,
        feedback_right=None,
        learned=False,
    )


PAUSED = CommandRecord(
    command=Command.PAUSE,
    gesture="long red",
    at=0.0,
    state="guessing",
    applied=True,
    confirm=Confirmation.PAUSE,
)


def plain_roundtrip(state: GameState) -> GameState:
    return state_from_plain(json.loads(json.dumps(state_to_plain(state))))


def test_learning_a_name_withdraws_it_and_moves_on() -> None:
    state = GameState.new(GAME, PARAMS, seed=1)
    state.apply(StepRecord(to="guessing"), GAME)
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
    state.apply(StepRecord(to="guessing"), GAME)
    state.apply(trial(state, 1, 2, True), GAME)
    before = plain_roundtrip(state)
    state.apply(trial(state, 2, 2, True), GAME)  # learned: bag 2 is next, name 2 withdrawn
    assert state.target == 1
    state.apply(UndoRecord(trial=2), GAME)
    assert state.target == 0 and state.offered == before.offered
    assert state.learner.table.tolist() == before.learner.table.tolist()
    assert state.progress[0] == before.progress[0]
    assert state.turn == before.turn
    assert state.trials == 2  # numbers are never reused
    with pytest.raises(StateError, match="undo of trial 2: it is not the last answer"):
        state.apply(UndoRecord(trial=2), GAME)


def test_snapshot_plus_later_records_equals_the_live_state() -> None:
    live = GameState.new(GAME, PARAMS, seed=4)
    records: list = [StepRecord(to="teaching")]
    records += [PoseRecord(bag=b, round=0, pose={"elbow": float(b)}, at=0.0) for b in range(6)]
    records += [StepRecord(to="guessing")]
    snapshot = None
    for index, record in enumerate(records):
        live.apply(record, GAME)
        if index == 3:
            snapshot = state_to_plain(live)
    for number, (choice, green) in enumerate([(1, False), (4, True)], start=1):
        record = trial(live, number, choice, green)
        records.append(record)
        live.apply(record, GAME)
    live.apply(PAUSED, GAME)
    records.append(PAUSED)
    from_snapshot = state_from_plain(json.loads(json.dumps(snapshot)))
    restored = restore(from_snapshot, records[4:], GAME, PARAMS, seed=4)
    assert state_to_plain(restored) == state_to_plain(live)
    assert restored.teach_round == 1 and restored.poses["bag 6"] == {"elbow": 5.0}
    assert restored.paused
    from_nothing = restore(None, records, GAME, PARAMS, seed=4)
    assert state_to_plain(from_nothing) == state_to_plain(live)


def test_a_record_for_another_target_is_refused() -> None:
    state = GameState.new(GAME, PARAMS, seed=1)
    record = msgspec.structs.replace(trial(state, 1, 0, True), target_index=3)
    with pytest.raises(StateError, match="trial 1: for target 3, state is at 0"):
        state.apply(record, GAME)


def test_a_damaged_snapshot_is_a_named_error() -> None:
    with pytest.raises(StateError, match="unusable game state snapshot"):
        state_from_plain({"step": "guessing"})


def test_the_undo_entry_and_previous_answer_survive_a_snapshot() -> None:
    state = GameState.new(GAME, PARAMS, seed=1)
    state.apply(StepRecord(to="guessing"), GAME)
    state.apply(trial(state, 1, 2, False), GAME)
    restored = plain_roundtrip(state)
    assert restored.undo == state.undo and restored.undo is not None
    assert restored.undo.previous is None and restored.previous == (2, False)
    assert json.loads(json.dumps(state_to_plain(restored))) == json.loads(
        json.dumps(state_to_plain(state))
    )
