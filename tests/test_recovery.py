"""A game that recovers from a wrongly learned name (kasparctl.game.recovery).

The pure rules (what stands rejected, when Kaspar is confused, what a re-open does
and how an undo takes it back, the alert), the state they change replayed the same,
a whole simulated game where a wrongly learned name is re-opened and the game ends
with it right, a resume in the middle of it, the CSV columns, the live view and
STATUS=, and the simulator.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
from pathlib import Path
from typing import Any

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st
from still_body import still_body

from kasparctl.cli import main
from kasparctl.config import GameSettings
from kasparctl.game import recovery
from kasparctl.game.events import GameEvent
from kasparctl.game.records import (
    AlertRecord,
    ConfusedRecord,
    ReopenRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.session import Session, state_from_plain, state_to_plain
from kasparctl.game.state import GameState, StateError, restore
from kasparctl.learning.learner import LearnerParams
from kasparctl.service.status import recovery_words, status_line
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, build, demo_config, run_demo
from kasparctl.sim.simulate import iter_groups
from kasparctl.sim.teacher import Teacher
from kasparctl.view.fold import session_view

GAME = GameSettings()  # names: six bags, six toys, two greens in a row
PARAMS = LearnerParams()
# Children who now and then press green for a wrong guess: with seed 4 the demo learns
# one name wrong, Kaspar is confused two bags later, and the researcher re-opens it.
FOOLED = Teacher(p_wrong_green=0.15)
SEED = 4


# -- the pure rules ------------------------------------------------------------------


@given(st.lists(st.tuples(st.integers(0, 5), st.booleans()), max_size=40))
def test_rejected_are_the_labels_whose_last_answer_is_red(answers: list[tuple[int, bool]]) -> None:
    rejected: list[int] = []
    for choice, green in answers:
        rejected = recovery.rejected_after(rejected, choice, green)
    last = dict(answers)
    assert rejected == sorted(label for label, green in last.items() if not green)


@given(st.lists(st.booleans(), min_size=1, max_size=8), st.sets(st.integers(0, 7)))
def test_all_rejected_means_every_offered_label_was_rejected(
    offered: list[bool], rejected: set[int]
) -> None:
    names = {i for i, on in enumerate(offered) if on}
    assert recovery.all_rejected(offered, sorted(rejected)) == (bool(names) and names <= rejected)


def test_the_researcher_reopens_down_to_the_name_learned_wrong() -> None:
    answers = [0, 1, 2, 3]
    assert recovery.to_reopen([(0, 0), (1, 1)], answers) == 0
    assert recovery.to_reopen([(0, 0), (1, 1), (2, 5)], answers) == 1
    assert recovery.to_reopen([(0, 4), (1, 1), (2, 2)], answers) == 3


def trial(state: GameState, choice: int, green: bool, recovering: bool = True) -> TrialRecord:
    """The next trial record on the state's target, as score_answer computes what apply reads."""
    target = state.target
    q_row = state.learner.table[target].copy()
    reward = PARAMS.reward(green)
    q_row[choice] += PARAMS.alpha * (reward - q_row[choice])
    progress = state_from_plain(state_to_plain(state)).progress[target]
    progress.record(choice, green)
    before = [] if state.rejected is msgspec.UNSET else state.rejected[target]
    return TrialRecord(
        trial=state.trials + 1,
        problem_trial=state.progress[target].trials + 1,
        step="guessing",
        target=GAME.targets[target],
        target_index=target,
        child="child one",
        child_index=0,
        candidates=[toy for toy, on in zip(GAME.toys, state.offered, strict=True) if on],
        probabilities=[1 / 6] * 6,
        entropy=1.0,
        band=None,
        spoken=[],
        choice=GAME.toys[choice],
        choice_index=choice,
        feedback="green" if green else "red",
        question_end=0.0,
        feedback_at=1.0,
        reaction_time=1.0,
        reward=reward,
        q_before=state.learner.table[target].tolist(),
        q_after=q_row.tolist(),
        learner_rng=state.learner.rng.bit_generator.state,
        perseverative=False,
        win_shift=False,
        correct=None,
        feedback_right=None,
        learned=progress.learned is not None,
        rejected=recovery.rejected_after(before, choice, green) if recovering else msgspec.UNSET,
    )


class Played:
    """A state and the records that made it, applied as the game applies them."""

    def __init__(self) -> None:
        self.state = GameState.new(GAME, PARAMS, seed=3)
        self.state.step = "guessing"
        self.records: list[Any] = []

    def apply(self, record: Any) -> Any:
        self.records.append(record)
        self.state.apply(record, GAME)
        return record

    def answer(self, choice: int, green: bool) -> TrialRecord:
        return self.apply(trial(self.state, choice, green))

    def same_when_replayed(self) -> None:
        replayed = restore(None, self.records, GAME, PARAMS, 3)
        replayed_plain = state_to_plain(replayed)
        replayed_plain["step"] = "guessing"
        assert replayed_plain == state_to_plain(self.state)
        assert state_to_plain(state_from_plain(state_to_plain(self.state))) == state_to_plain(
            self.state
        )


# Bag 1's toy is toy 0, bag 2's toy 3: the children say green twice for toy 3 on bag 1.
KEY = tuple(GAME.toys[i] for i in (0, 3, 1, 2, 4, 5))


def wrongly_learned() -> tuple[Played, TrialRecord]:
    played = Played()
    played.state.step = "guessing"
    played.answer(3, True)
    learned = played.answer(3, True)
    assert played.state.progress[0].learned == 3 and not played.state.offered[3]
    return played, learned


def test_a_name_withdrawn_while_it_is_an_open_bags_right_toy_is_an_alert() -> None:
    played, learned = wrongly_learned()
    (alert,) = recovery.alerts(played.state, learned, GAME, KEY)
    assert (alert.target, alert.toy, alert.learned_for) == (
        GAME.targets[1],
        GAME.toys[3],
        GAME.targets[0],
    )
    assert recovery.alerts(played.state, learned, GAME, ()) == []  # no answer key, no alert


def test_every_name_left_rejected_confuses_kaspar_once_and_reopen_undoes_the_wrong_name() -> None:
    played, _ = wrongly_learned()
    state = played.state
    assert state.target == 1
    for choice in (0, 1, 2, 4):
        assert recovery.confusion(state, played.answer(choice, False), GAME) is None
    last = played.answer(5, False)
    confused = recovery.confusion(state, last, GAME)
    assert confused is not None and confused.reason == recovery.ALL_REJECTED
    assert (confused.reopen_target, confused.reopen_name) == (GAME.targets[0], GAME.toys[3])
    played.apply(confused)
    assert state.confused == 1
    assert recovery.confusion(state, played.answer(5, False), GAME) is None  # said once
    played.same_when_replayed()

    reopen = recovery.reopen_record(state, GAME)
    assert reopen is not None and (reopen.target_index, reopen.name_index) == (0, 3)
    played.apply(reopen)
    assert state.offered[3] and state.progress[0].learned is None and state.confused is None
    assert state.learned_targets() == [] and state.target == 1
    played.same_when_replayed()

    # The researcher's undo takes the re-open back: the name is learned again.
    back = recovery.taken_back(state, GAME)
    assert back is not None and back.taken_back is True
    played.apply(back)
    assert not state.offered[3] and state.progress[0].learned == 3 and state.confused == 1
    played.same_when_replayed()
    played.apply(recovery.reopen_record(state, GAME))

    # Now bag 2 is learned right, then bag 1 is asked again and learned right.
    played.answer(3, True)
    played.answer(3, True)
    assert state.progress[1].learned == 3 and state.target == 0
    played.answer(3, False)
    played.answer(0, True)
    played.answer(0, True)
    assert state.progress[0].learned == 0 and state.learned_targets() == [1, 0]
    played.same_when_replayed()


def test_an_undone_answer_takes_its_rejection_and_learning_back() -> None:
    played = Played()
    played.answer(2, False)
    played.answer(1, True)
    state = played.state
    rejected, learned = list(state.rejected[0]), state.learned_targets()
    played.answer(1, True)  # learned: withdrawn, on to bag 2
    played.answer(4, False)
    assert state.learned_targets() == [0] and state.rejected[1] == [4]
    played.apply(UndoRecord(trial=4))
    played.apply(trial(state, 4, True))  # asked again: the next trial's number
    played.apply(UndoRecord(trial=5))
    assert state.rejected[1] == [] and state.learned_targets() == [0]
    played.same_when_replayed()
    other = Played()
    other.answer(2, False)
    other.answer(1, True)
    other.answer(1, True)
    other.apply(UndoRecord(trial=3))
    assert other.state.rejected[0] == rejected and other.state.learned_targets() == learned
    assert other.state.progress[0].learned is None and other.state.offered[1]


def test_a_reopen_of_a_name_not_learned_last_is_refused() -> None:
    played, _ = wrongly_learned()
    wrong = ReopenRecord(trial=2, target="bag 2", target_index=1, name=GAME.toys[0], name_index=0)
    with pytest.raises(StateError, match="not the one learned last"):
        played.state.apply(wrong, GAME)


def test_a_name_learned_elsewhere_answered_green_confuses_kaspar_where_names_stay() -> None:
    game = msgspec.structs.replace(GAME, exclude_learned_rule="never")
    state = GameState.new(game, PARAMS, seed=1)
    state.step = "guessing"
    state.apply(trial(state, 2, True), game)
    state.apply(trial(state, 2, True), game)
    assert state.progress[0].learned == 2 and state.offered[2]
    green = trial(state, 2, True)
    state.apply(green, game)
    confused = recovery.confusion(state, green, game)
    assert confused is not None and confused.reason == recovery.LEARNED_ELSEWHERE
    assert (confused.name, confused.learned_for) == (game.toys[2], game.targets[0])


def test_sessions_planned_before_recovery_are_never_confused() -> None:
    played = Played()
    for choice in range(6):
        record = played.apply(trial(played.state, choice, False, recovering=False))
        assert recovery.confusion(played.state, record, GAME) is None
    assert played.state.rejected is msgspec.UNSET and played.state.learned_order is msgspec.UNSET


# -- a whole game on the simulated robot ----------------------------------------------


def session_of(state_dir: Path) -> tuple[Session, list[Any], GameState]:
    (directory,) = (state_dir / "sessions").iterdir()
    session, _ = Session.open(directory)
    records = session.records()
    state, _ = session.load_state()
    session.close()
    assert state is not None
    return session, records, state


@pytest.fixture(scope="module")
def recovered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    state_dir = tmp_path_factory.mktemp("recovered")
    out = io.StringIO()
    with still_body():  # as a test's games (tests/still_body.py)
        result = run_demo(
            demo_config(),
            DemoOptions(state_dir=state_dir, seed=SEED, teacher=FOOLED, out=out),
            fast=True,
        )
    assert result.finished
    (state_dir / "transcript.txt").write_text(out.getvalue())
    return state_dir


def test_a_wrongly_learned_name_is_reopened_and_the_game_ends_with_it_right(
    recovered: Path,
) -> None:
    session, records, state = session_of(recovered)
    key = [GAME.toys.index(toy) for toy in session.plan["plan"]["answer_key"]]
    trials = [r for r in records if isinstance(r, TrialRecord)]
    wrong = [t for t in trials if t.learned and t.correct is False]
    assert wrong, "the children's false greens taught a wrong name"
    kinds = [type(r) for r in records]
    alert, confused, reopen = (
        next(r for r in records if isinstance(r, kind))
        for kind in (AlertRecord, ConfusedRecord, ReopenRecord)
    )
    assert kinds.index(AlertRecord) < kinds.index(ConfusedRecord) < kinds.index(ReopenRecord)
    assert confused.reason == recovery.ALL_REJECTED and confused.reopen_name == reopen.name
    assert reopen.target_index == wrong[0].target_index and reopen.name == wrong[0].choice
    assert alert.toy == wrong[0].choice
    # Every bag learned, each with its right name, the re-opened one included.
    assert [p.learned for p in state.progress] == key
    relearned = [t for t in trials if t.target_index == reopen.target_index and t.learned]
    assert relearned[-1].correct is True
    assert session.plan["recovery"] == recovery.RECOVERY_VERSION


def test_kaspar_says_once_that_it_is_confused_asks_and_confirms_the_reopen(
    recovered: Path,
) -> None:
    said = (recovered / "transcript.txt").read_text()
    _, records, _ = session_of(recovered)
    reopen = next(r for r in records if isinstance(r, ReopenRecord))
    confused = said.index("I am confused. I need help with this one.")
    asked = said.index("A grown-up can help me think again.", confused)
    assert said.index(f"Okay. Maybe I was wrong about the {reopen.name}.", asked)
    assert said.count("I am confused.") == sum(isinstance(r, ConfusedRecord) for r in records)


def test_the_csv_marks_the_rows_of_the_recovery(recovered: Path, tmp_path: Path) -> None:
    out = tmp_path / "trials.csv"
    events = tmp_path / "events.csv"
    assert (
        main(["export", "--state-dir", str(recovered), "--csv", str(out), "--events", str(events)])
        == 0
    )
    rows = list(csv.DictReader(out.open(newline="")))
    _, records, _ = session_of(recovered)
    reopen = next(r for r in records if isinstance(r, ReopenRecord))
    confused = next(r for r in records if isinstance(r, ConfusedRecord))
    for row in rows:
        trial = int(row["trial"])
        on_reopened = row["target"] == reopen.target and trial > reopen.trial
        assert row["reopened"] == ("TRUE" if on_reopened else "FALSE")
        offered = row["answer"] in row["candidates"].split(";")
        assert row["right_toy_offered"] == ("TRUE" if offered else "FALSE")
    confused_rows = [r for r in rows if r["confused"] == "TRUE"]
    assert all(
        r["target"] == confused.target and int(r["trial"]) > confused.trial for r in confused_rows
    )
    assert any(r["right_toy_offered"] == "FALSE" for r in rows)
    kinds = {row["kind"]: row for row in csv.DictReader(events.open(newline=""))}
    assert kinds["confused"]["name"] == recovery.ALL_REJECTED
    assert kinds["reopen"]["name"] == reopen.name
    assert kinds["alert"]["name"] == recovery.RIGHT_TOY_WITHDRAWN


def test_the_view_and_status_show_the_confusion_then_clear_it(recovered: Path) -> None:
    session, records, _ = session_of(recovered)
    cut = next(i for i, r in enumerate(records) if isinstance(r, ConfusedRecord))
    mid = session_view(session.plan, records[: cut + 1])
    reopen = next(r for r in records if isinstance(r, ReopenRecord))
    assert mid.confused is not None and reopen.name in mid.confused
    assert mid.alerts and mid.alerts[0].startswith(reopen.name)
    end = session_view(session.plan, records)
    assert end.confused is None and end.alerts == () and end.reopens >= 1
    assert len(end.learned) == 6
    # STATUS= while confused.
    played, _ = wrongly_learned()
    for choice in (0, 1, 2, 4, 5):
        last = played.answer(choice, False)
    played.apply(recovery.confusion(played.state, last, GAME))
    words = recovery_words(played.state, GAME)
    assert words == "Kaspar is confused about bag 2: reopen re-opens " + GAME.toys[3] + " (bag 1)"
    assert words in status_line("guessing", {}, None, words)


def test_stopped_mid_recovery_the_resume_has_the_same_state_and_finishes(tmp_path: Path) -> None:
    config = demo_config()
    options = DemoOptions(state_dir=tmp_path, seed=SEED, teacher=FOOLED, out=io.StringIO())
    captured: dict[str, Any] = {}

    async def until_reopened() -> None:
        rig = build(config, options)
        reopened = asyncio.Event()

        def listener(event: GameEvent, info: dict[str, Any]) -> None:
            if event is GameEvent.REOPENED and not captured:
                captured.update(state_to_plain(rig.game.session_state))
                reopened.set()

        rig.game.listeners.append(listener)
        playing = asyncio.create_task(rig.run())
        await reopened.wait()
        playing.cancel()  # the daemon stopped mid-recovery
        with contextlib.suppress(asyncio.CancelledError):
            await playing

    simtime.run(until_reopened(), virtual=True)
    assert captured and captured["learned_order"] is not None
    session, records, state = session_of(tmp_path)
    assert [type(r) for r in records].count(ReopenRecord) == 1
    assert state_to_plain(state) == captured
    # From the records alone, too.
    params = config.profile(session.plan["plan"]["profile"])
    replayed = restore(None, records, config.game, params, session.plan["seed"])
    assert state_to_plain(replayed) == captured
    # The resumed game finishes with every name right.
    result = run_demo(config, options, fast=True)
    assert result.resumed and result.finished
    session, _, state = session_of(tmp_path)
    key = [GAME.toys.index(toy) for toy in session.plan["plan"]["answer_key"]]
    assert [p.learned for p in state.progress] == key


# -- the simulator ---------------------------------------------------------------------


def test_the_simulator_recovers_where_the_game_without_recovery_learns_wrong() -> None:
    game = demo_config().game
    teacher = Teacher(p_wrong_green=0.1, p_wrong_red=0.05)

    def figures(recover: bool) -> tuple[int, int, int]:
        wrong = given_up = longest = 0
        for problems in iter_groups(300, game, PARAMS, teacher, 11, recover=recover):
            for problem in problems:
                wrong += problem.learned is not None and problem.learned != problem.answer
                given_up += problem.learned is None
                longest = max(longest, len(problem.trials))
        return wrong, given_up, longest

    before, after = figures(False), figures(True)
    assert before[0] > 0 and before[1] > 0 and before[2] == game.max_trials_per_target
    assert after[0] < before[0] / 4 and after[1] < before[1] / 4 and after[2] < before[2]
