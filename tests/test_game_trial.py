"""One guess's arithmetic, without a robot: kasparctl.game.trial plans and scores."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import msgspec
import numpy as np
import pytest

from kasparctl.config import GameSettings, SessionPlan
from kasparctl.game.jsonl import read_records
from kasparctl.game.phrases import load_phrasebook
from kasparctl.game.records import StepRecord, TrialRecord
from kasparctl.game.scripts import SCRIPTS
from kasparctl.game.session import RECORDS_FILE, state_to_plain
from kasparctl.game.state import GameState
from kasparctl.game.trial import Answer, TrialPlan, plan_trial, score_answer
from kasparctl.learning.learner import LearnerParams, choose, softmax
from kasparctl.sim.demo import demo_config, with_variant
from kasparctl.vocabulary import MAX_CHILDREN

SETTINGS = GameSettings()  # names, six toys, two greens in a row
PARAMS = LearnerParams()  # alpha 0.6, beta 8, gamma 0
PLAN = SessionPlan(group="T", speak_uncertainty=True)
BOOK = load_phrasebook("en")
V1 = Path(__file__).resolve().parent / "data" / "sessions-v1" / "state" / "sessions"


def guessing(seed: int = 1, settings: GameSettings = SETTINGS) -> GameState:
    state = GameState.new(settings, PARAMS, seed)
    state.apply(StepRecord(to="guessing"), settings)
    return state


def plan(state: GameState, session_plan: SessionPlan = PLAN, group_size: int = 3) -> TrialPlan:
    return plan_trial(state, PARAMS, SETTINGS, session_plan, group_size, BOOK, SCRIPTS["paper"])


def answer(button: str, at: float = 5.0) -> Answer:
    return Answer(spoken=("I think", "is it the lion?"), question_end=4.0, button=button, pressed_at=at)  # type: ignore[arg-type]


def play(state: GameState, button: str, session_plan: SessionPlan = PLAN) -> TrialRecord:
    """Plan, score and apply one trial, as the game does; returns its record."""
    planned = plan(state, session_plan)
    record = score_answer(planned, answer(button), state, PARAMS, SETTINGS, session_plan)
    state.apply(record, SETTINGS)
    return record


def test_planning_changes_nothing_and_asks_the_same_question_again() -> None:
    state = guessing()
    before = json.dumps(state_to_plain(state))
    first, second = plan(state), plan(state)
    assert json.dumps(state_to_plain(state)) == before
    assert first.choice == second.choice and first.learner_rng == second.learner_rng
    assert first.trial == 1 and first.problem_trial == 1 and first.target == 0


def test_the_generator_moves_on_only_with_the_record() -> None:
    """Planned and applied trial by trial, the choices are the learner's own draws in turn."""
    state = guessing(seed=7)
    mirror = np.random.default_rng(7)
    for _ in range(5):
        planned = plan(state)
        probabilities = softmax(state.learner.table[state.target], PARAMS.beta, state.candidates)
        assert planned.choice == choose(probabilities, mirror)
        assert planned.learner_rng == mirror.bit_generator.state
        state.apply(score_answer(planned, answer("red"), state, PARAMS, SETTINGS, PLAN), SETTINGS)
        assert state.learner.rng.bit_generator.state == mirror.bit_generator.state


def test_the_first_question_is_over_every_toy_at_the_most_uncertain() -> None:
    planned = plan(guessing())
    assert planned.candidates == SETTINGS.toys
    assert planned.probabilities.tolist() == pytest.approx([1 / 6] * 6)
    assert planned.entropy == pytest.approx(math.log2(6))
    assert planned.band == "no_idea"
    assert planned.toy == SETTINGS.toys[planned.choice] and planned.target_name == "bag 1"


def test_silent_plans_have_no_band() -> None:
    silent = msgspec.structs.replace(PLAN, speak_uncertainty=False)
    assert plan(guessing(), silent).band is None


def test_children_take_turns_by_word_or_by_name() -> None:
    state = guessing()
    named = msgspec.structs.replace(PLAN, children=("Amira", "Ben"))
    children = []
    for _ in range(4):
        children.append((plan(state).child, plan(state, named, group_size=2).child))
        play(state, "red")
    # Without first names, the phrase book's names.child.
    assert [c for c, _ in children] == ["child 1", "child 2", "child 3", "child 1"]
    assert [n for _, n in children] == ["Amira", "Ben", "Amira", "Ben"]
    assert plan(state, named, group_size=2).child_index == 0
    assert MAX_CHILDREN == 6


def test_a_green_is_rewarded_by_eq_1_and_two_in_a_row_learn_the_name() -> None:
    state = guessing(seed=3)
    first = play(state, "green")
    assert first.reward == 1.0
    assert first.q_after[first.choice_index] == pytest.approx(0.6)
    assert first.q_before == [0.0] * 6 and not first.learned
    # Asked again (same target), the learner now prefers that toy; say yes again.
    planned = plan(state)
    forced = dataclasses.replace(planned, choice=first.choice_index, toy=first.choice)
    second = score_answer(forced, answer("green"), state, PARAMS, SETTINGS, PLAN)
    assert second.learned and second.q_after[first.choice_index] == pytest.approx(0.84)
    assert not second.perseverative and not second.win_shift
    state.apply(second, SETTINGS)
    assert state.target == 1 and not state.offered[first.choice_index]
    assert plan(state).candidates == tuple(t for t in SETTINGS.toys if t != first.choice)
    assert plan(state).probabilities[first.choice_index] == 0.0


def test_perseverative_and_win_shift_flags() -> None:
    state = guessing(seed=5)
    wrong = play(state, "red")
    again = dataclasses.replace(plan(state), choice=wrong.choice_index, toy=wrong.choice)
    perseverative = score_answer(again, answer("red"), state, PARAMS, SETTINGS, PLAN)
    assert perseverative.perseverative and not perseverative.win_shift
    state.apply(perseverative, SETTINGS)
    right = play(state, "green")
    other = (right.choice_index + 1) % 6
    shifted = dataclasses.replace(plan(state), choice=other, toy=SETTINGS.toys[other])
    win_shift = score_answer(shifted, answer("red"), state, PARAMS, SETTINGS, PLAN)
    assert win_shift.win_shift and not win_shift.perseverative


def test_the_answer_key_grades_the_guess_and_the_children_only() -> None:
    state = guessing(seed=2)
    planned = plan(state)
    keyed = msgspec.structs.replace(PLAN, answer_key=tuple(SETTINGS.toys))
    for button in ("green", "red"):
        graded = score_answer(planned, answer(button), state, PARAMS, SETTINGS, keyed)
        plain = score_answer(planned, answer(button), state, PARAMS, SETTINGS, PLAN)
        right = planned.choice == 0
        assert graded.correct is right and graded.feedback_right is (right == (button == "green"))
        assert plain.correct is None and plain.feedback_right is None
        # The learner's values do not depend on the key.
        assert (graded.q_after, graded.reward, graded.learned) == (
            plain.q_after,
            plain.reward,
            plain.learned,
        )


def test_a_done_target_updates_towards_the_next_open_one() -> None:
    """Eq. 1's s_{t+1}: with gamma > 0, the last answer on a target looks at the next target."""
    params = LearnerParams(gamma=0.5)
    state = GameState.new(SETTINGS, params, seed=1)
    state.apply(StepRecord(to="guessing"), SETTINGS)
    state.learner.table[1, 4] = 2.0  # what the next target already promises
    state.progress[0].streak, state.progress[0].streak_label = 1, 3
    planned = dataclasses.replace(
        plan_trial(state, params, SETTINGS, PLAN, 3, BOOK, SCRIPTS["paper"]),
        choice=3,
        toy=SETTINGS.toys[3],
    )
    record = score_answer(planned, answer("green"), state, params, SETTINGS, PLAN)
    assert record.learned
    assert record.q_after[3] == pytest.approx(0.6 * (1.0 + 0.5 * 2.0))


def test_timing_fields_come_from_the_answer() -> None:
    state = guessing()
    record = score_answer(plan(state), answer("green", at=6.5), state, PARAMS, SETTINGS, PLAN)
    assert (record.question_end, record.feedback_at) == (4.0, 6.5)
    assert record.reaction_time == pytest.approx(2.5)
    assert record.spoken == ["I think", "is it the lion?"] and record.step == "guessing"


@pytest.mark.parametrize("directory", sorted(V1.iterdir()), ids=lambda d: d.name)
def test_every_recorded_trial_is_what_plan_and_score_make(directory: Path) -> None:
    """The sessions recorded before this module existed: each trial, replanned from the
    state its earlier records built and scored with the recorded answer, comes out the same.

    They were planned before scripts existed: the varied script's bands are theirs. A
    child without a first name was then called by an English word ("child one"); the
    phrase book's names.child calls them now, so that one field is compared by its number.
    """
    meta = json.loads((directory / "plan.json").read_text())
    config = with_variant(demo_config(), meta["variant"])
    session_plan = msgspec.convert(meta["plan"], type=SessionPlan)
    params = config.profile(session_plan.profile)
    state = GameState.new(config.game, params, meta["seed"])
    checked = 0
    for record in read_records(directory / RECORDS_FILE).records:
        if isinstance(record, TrialRecord):
            size = config.group_size(session_plan)
            planned = plan_trial(
                state, params, config.game, session_plan, size, BOOK, SCRIPTS["varied"]
            )
            heard = Answer(
                tuple(record.spoken), record.question_end, record.feedback, record.feedback_at
            )
            again = score_answer(planned, heard, state, params, config.game, session_plan)
            if not session_plan.children:
                assert again.child == f"child {record.child_index + 1}"
                again = msgspec.structs.replace(again, child=record.child)
            stamps = {"seq": record.seq, "time": record.time, "clock": record.clock}
            assert msgspec.structs.replace(again, **stamps) == record
            checked += 1
        state.apply(record, config.game)
    assert checked == state.trials > 0
