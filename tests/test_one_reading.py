"""The records read one way: the game's state, STATUS=, the live view and the research agree.

The disagreements issue 23 found, each reproduced on a whole simulated game: Kaspar
confused about a bag it has given up (STATUS= said no, the view kept drawing it), and
the report counting as a win-shift the first guess on a bag after its name was
re-opened (the CSV's win_shift column did not).
"""

from __future__ import annotations

import asyncio
import csv
import io
import itertools
import json
import random
import tempfile
import time
import typing
from pathlib import Path
from typing import Any

import msgspec
import pytest
from fault_rig import FaultRig, run_daemon, seated
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from reading_check import Readers, research_agrees
from research_fixtures import Scenario, cut_after_trial
from rig_events import on_event
from still_body import still_body

from hal.servos.api import FaultKind
from kasparctl.cli import main
from kasparctl.config import Config, GameSettings, SessionPlan, load_config
from kasparctl.game import recovery
from kasparctl.game.events import GameEvent
from kasparctl.game.fold import Reading
from kasparctl.game.jsonl import encode_record
from kasparctl.game.phrases import load_phrasebook
from kasparctl.game.records import (
    STATE_CHANGING,
    AnyRecord,
    ButtonCheckRecord,
    ClockRecord,
    CommandRecord,
    Confirmation,
    ConfusedRecord,
    FaultRecord,
    FaultSource,
    HalEvent,
    HalRecord,
    PoseRecord,
    PressRecord,
    PromptRecord,
    QuestionRecord,
    ReopenRecord,
    RotationRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.recovery import RECOVERY_VERSION
from kasparctl.game.scripts import script
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE, Session, state_to_plain
from kasparctl.game.state import GameState, restore
from kasparctl.game.trial import Answer, TrialPlan, plan_trial, question_record, score_answer
from kasparctl.game.wallclock import ClockWatch
from kasparctl.learning.learner import LearnerParams
from kasparctl.service.status import recovery_words
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, DemoRig, build, demo_config, run_demo
from kasparctl.sim.teacher import Messiness, Teacher
from kasparctl.view.fold import SessionFold
from kasparctl.vocabulary import Command


def played(state_dir: Path, config: Config, seed: int, teacher: Teacher) -> Path:
    result = run_demo(
        config,
        DemoOptions(state_dir=state_dir, seed=seed, teacher=teacher, out=io.StringIO()),
        fast=True,
    )
    assert result.finished
    return state_dir


def session_records(state_dir: Path) -> tuple[dict[str, Any], list[AnyRecord]]:
    (directory,) = (state_dir / "sessions").iterdir()
    session, _ = Session.open(directory)
    records = session.records()
    session.close()
    return session.plan, records


def with_limit(limit: int) -> Config:
    config = demo_config()
    game = msgspec.structs.replace(config.game, max_trials_per_target=limit)
    return msgspec.structs.replace(config, game=game)


# -- Kaspar confused about a bag given up -------------------------------------------------


@pytest.fixture(scope="module")
def given_up(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`max_trials_per_target = 9`, `demo --p-wrong-red 1.0 --seed 3`: every right guess is
    answered red, so every bag is confused about, then given up."""
    with still_body():  # as a test's games (tests/still_body.py)
        return played(
            tmp_path_factory.mktemp("given-up"), with_limit(9), 3, Teacher(p_wrong_red=1.0)
        )


def test_status_and_the_view_agree_on_the_confusion_after_a_give_up(given_up: Path) -> None:
    """Told the session's limit (as the game is), the view reads the give-up at its answer."""
    config = with_limit(9)
    plan, records = session_records(given_up)
    state = GameState.new(config.game, config.profile(plan["plan"]["profile"]), plan["seed"])
    fold = SessionFold(plan, limit=9)
    seen_give_up = False
    for record in records:
        if isinstance(record, STATE_CHANGING):
            state.apply(record, config.game)
        fold.apply(record)
        seen_give_up = seen_give_up or any(p.given_up for p in state.progress)
        status = recovery_words(state, config.game)
        shown = fold.view.confused
        assert (status is None) == (shown is None), (record.seq, status, shown)
        if isinstance(state.confused, int) and shown is not None:
            assert shown.startswith(f"{config.game.targets[state.confused]}: ")
    assert seen_give_up, "the children's reds gave a bag up"


def test_without_the_limit_the_view_sees_the_give_up_when_the_next_bag_is_asked(
    given_up: Path,
) -> None:
    """Before, the view drew bag 1 CONFUSED all through bag 2."""
    plan, records = session_records(given_up)
    fold = SessionFold(plan)
    gave_up: str | None = None
    for record in records:
        fold.apply(record)
        if isinstance(record, TrialRecord) and record.problem_trial == 9:
            gave_up = record.target  # the answer that gave the bag up
        elif isinstance(record, QuestionRecord) and gave_up is not None:
            assert record.target != gave_up
            assert gave_up in fold.view.given_up
            confused = fold.view.confused
            assert confused is None or not confused.startswith(f"{gave_up}: "), record.seq
            gave_up = None
    assert fold.view.given_up == with_limit(9).game.targets  # every bag, in order


# -- the first guess after a re-open ----------------------------------------------------------

# Children who now and then press green for a wrong guess: with seed 4 the demo learns a
# name wrong, Kaspar is confused, the researcher re-opens it, and the re-opened bag's
# first guess is another toy than the one its green had taught.
FOOLED = Teacher(p_wrong_green=0.15)


@pytest.fixture(scope="module")
def reopened(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with still_body():  # as a test's games (tests/still_body.py)
        return played(tmp_path_factory.mktemp("reopened"), demo_config(), 4, FOOLED)


def test_the_report_counts_the_win_shifts_the_csv_marks(reopened: Path, tmp_path: Path) -> None:
    _, records = session_records(reopened)
    reopen = next(r for r in records if isinstance(r, ReopenRecord))
    trials = [r for r in records if isinstance(r, TrialRecord)]
    learned = next(t for t in trials if t.learned and t.target_index == reopen.target_index)
    again = next(
        t for t in trials if t.target_index == reopen.target_index and t.trial > reopen.trial
    )
    # The case: a green, then (after the re-open and other bags) another toy on this bag.
    assert learned.green and again.choice_index != learned.choice_index
    out = tmp_path / "trials.csv"
    assert main(["export", "--state-dir", str(reopened), "--csv", str(out)]) == 0
    rows = [row for row in csv.DictReader(out.open(newline="")) if row["undone"] == "FALSE"]
    row = next(row for row in rows if int(row["trial"]) == again.trial)
    assert row["win_shift"] == "FALSE"  # it follows no guess: the green was taken back
    assert main(["report", "--state-dir", str(reopened), "--out", str(tmp_path / "report")]) == 0
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    for column, count in (("win_shift", "win_shifts"), ("perseverative", "perseverative_errors")):
        marked = sum(row[column] == "TRUE" for row in rows)
        assert summary["all"][count] == marked, column


# -- every reader agrees, after every record of whole simulated games ---------------------


def replayed(state_dir: Path, config: Config) -> list[Readers]:
    """Every session of `state_dir` applied record by record to the game's state and to
    every reader (reading_check.Readers asserts they agree after each), the live game's
    last snapshot the same state, and the research reading it the same way."""
    checked = []
    for directory in sorted((state_dir / "sessions").iterdir()):
        session, _ = Session.open(directory)
        records, plan = session.records(), session.plan
        snapshot, later = session.load_state()
        session.close()
        params = config.profile(plan["plan"]["profile"])
        readers = Readers(config.game, params, plan["seed"], plan)
        for record in records:
            readers.apply(record)
        live = restore(snapshot, later, config.game, params, plan["seed"])
        assert state_to_plain(live) == state_to_plain(readers.state)
        research_agrees(directory, readers)
        checked.append(readers)
    return checked


def play_scenario(
    state_dir: Path, config: Config, options: DemoOptions, scenario: Scenario | None = None
) -> None:
    async def main() -> None:
        rig = build(config, options)
        side = asyncio.create_task(scenario(rig)) if scenario else None
        await asyncio.wait_for(rig.run(), timeout=20_000)
        if side is not None:
            side.cancel()
            await asyncio.gather(side, return_exceptions=True)

    simtime.run(main(), virtual=True)


async def researcher_and_breakage(rig: DemoRig) -> None:
    """The researcher's undo of an answer and of a re-open, a child taken out of the rotation
    and brought back, a pause, a servo fault, the keyfob lost and back: each at a question
    of its own (the game resumes each time)."""

    async def at_question(trial: int) -> None:
        await on_event(rig, "question", lambda info: info["trial"] == trial)

    async def take_back_the_first_reopen() -> None:
        await on_event(rig, "reopened")
        await rig.command("undo")

    taking_back = asyncio.create_task(take_back_the_first_reopen())
    try:
        await at_question(4)
        await rig.command("undo")  # trial 3's answer
        await at_question(5)
        await rig.command("away")  # the child asked leaves: the next child is asked
        await at_question(7)  # one cycle on, right after the child's turn was passed over
        await rig.command("away")  # they are back, and asked
        await at_question(7)
        await rig.command("pause")
        await asyncio.sleep(3)
        await rig.command("pause")  # resumes
        await at_question(9)
        fault = on_event(rig, "fault")
        rig.servos.inject_fault("head_yaw", FaultKind.OVERHEATING)
        await fault
        await asyncio.sleep(1)
        rig.servos.inject_fault("head_yaw", None)  # cooled down; the researcher resumes
        await at_question(12)
        await rig.keyfob.perform("lost")
        await asyncio.sleep(2)
        await rig.keyfob.perform("back")
        await asyncio.Event().wait()
    finally:
        taking_back.cancel()


def stepping_clock() -> ClockWatch:
    """A wall clock 2 h behind (fake-hwclock after a power cut) that steps 3 years ahead
    mid-game (a network appears), on a robot without timesyncd."""
    readings = itertools.count()

    def wall() -> float:
        return time.time() - 7200 + (3 * 365 * 86400 if next(readings) > 40 else 0)

    return ClockWatch(run=lambda command: None, wall=wall, boot=lambda: "")


MESSY = Teacher(p_wrong_green=0.15, p_wrong_red=0.05, p_no_answer=0.1)
# Children whose presses are messy too: held, doubled, squeezed, too early.
HANDS = Messiness(p_hold=0.05, p_double=0.1, p_both=0.05, p_early=0.1)


@pytest.fixture(scope="module")
def games(tmp_path_factory: pytest.TempPathFactory, given_up: Path, reopened: Path) -> list[Readers]:
    """Whole games: bags given up, a name re-opened and learned right, and one game with
    the researcher's commands (undo, a re-open taken back, pause), a servo fault, the
    keyfob lost, messy presses, and a power cut after trial 14 that the robot resumes."""
    checked = replayed(given_up, with_limit(9)) + replayed(reopened, demo_config())
    state_dir = tmp_path_factory.mktemp("messy")
    config = demo_config()
    options = DemoOptions(
        state_dir=state_dir,
        seed=2,
        teacher=MESSY,
        messiness=HANDS,
        out=io.StringIO(),
        clock=stepping_clock(),
    )
    # The live body: its motions' times are what make a child's silence long enough for a
    # prompt in this game, and the test asks for every kind of record.
    play_scenario(state_dir, config, options, researcher_and_breakage)
    (session_dir,) = (state_dir / "sessions").iterdir()
    cut_after_trial(session_dir, 14)
    play_scenario(state_dir, config, options)  # the robot restarts and resumes it
    return checked + replayed(state_dir, config)


def test_every_reader_agrees_after_every_record_of_whole_games(games: list[Readers]) -> None:
    """Readers.apply asserted it after each record; here: the games had everything."""
    records = [record for readers in games for record in readers.records]
    kinds = {type(record) for record in records}
    assert kinds == set(typing.get_args(AnyRecord)), set(typing.get_args(AnyRecord)) - kinds
    assert any(isinstance(r, ReopenRecord) and r.taken_back is True for r in records)
    assert any(isinstance(r, SessionRecord) and r.event is SessionEvent.RESUMED for r in records)
    # The clock's state at the start and resume, and its jump of 3 years, noticed.
    assert any(isinstance(r, ClockRecord) and r.step > 3 * 365 * 86400 - 60 for r in records)
    assert any(isinstance(r, FaultRecord) and r.joint == "head_yaw" for r in records)
    assert any(isinstance(r, HalRecord) and r.event is HalEvent.KEYFOB_LOST for r in records)
    changes = [r.event for r in records if isinstance(r, RotationRecord)]
    assert {"away", "skipped", "back"} <= set(changes), changes
    # Each game's new session began with Kaspar's check of the buttons.
    assert sum(isinstance(r, ButtonCheckRecord) for r in records) >= 4
    facts = [readers.reading.facts for readers in games]
    assert any(f.given_up for f in facts) and any(f.reopens for f in facts)
    assert any(g.confused for readers in games for g in readers.guesses.values())
    # The reader not told the limit lagged, and only as far as a give-up.
    assert any(readers.lagged for readers in games)


def test_every_reader_agrees_on_who_answered_with_a_keyfob_per_child(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two seats, a press out of turn taken (answer_out_of_turn = "take") and credited to
    who pressed, and a child taken out of the rotation and brought back: the game's state,
    the reading, the view and the CSV read the same records the same way."""

    async def scenario(rig: FaultRig) -> None:
        question = rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 2)
        await rig.press("long green")
        info = await question
        await asyncio.sleep(0.3)
        await rig.seats[0].perform("green")  # the first child, out of turn: taken
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 3)
        await rig.command("away")  # the first child leaves
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 5)
        await rig.command("away")  # right after their skipped turn: back
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 7)
        await rig.press("both")
        await rig.stage_is("idle")
        assert info["child_index"] == 1

    config_path = seated(tmp_path, "take")
    rig = run_daemon(tmp_path, monkeypatch, scenario, config=config_path)
    (readers,) = replayed(rig.state_dir, load_config(str(config_path)))
    kinds = {type(record) for record in readers.records}
    assert RotationRecord in kinds
    credited = {trial: guess.credited for trial, guess in readers.guesses.items()}
    asked = {r.trial: r.child_index for r in readers.records if isinstance(r, TrialRecord)}
    assert credited[2] == 0 and asked[2] == 1  # taken out of turn, credited to who pressed
    assert all(guess.seat in (1, 2) for guess in readers.guesses.values())
    changes = [r.event for r in readers.records if isinstance(r, RotationRecord)]
    assert changes[0] == "away" and "back" in changes and "skipped" in changes
    given = [
        (r.confirm, r.child_index)
        for r in readers.records
        if isinstance(r, CommandRecord) and r.command is Command.AWAY
    ]
    assert given == [(Confirmation.AWAY, 0), (Confirmation.BACK, 0)]


# -- record sequences of any shape, made by the game's own rules ------------------------------

# A small game, so that names are learned, rejected, re-opened and given up within a few
# dozen answers: four bags, five guesses each at most.
SMALL = msgspec.structs.replace(
    demo_config().game, toys=("lion", "elephant", "giraffe", "monkey"), max_trials_per_target=5
)
PARAMS = LearnerParams()
BOOK = load_phrasebook("en")  # only to call a child without a name "child one"...
KEY = ("giraffe", "lion", "monkey", "elephant")
ACTIONS = (
    "right", "wrong", "green", "red", "undo", "reopen", "pause", "stop", "crash", "fault",
    "keyfob", "press", "prompt",
)  # fmt: skip


class Played:
    """A session played with the game's own pure rules (kasparctl.game.trial and recovery),
    each record written as the machine writes it, and every reader checked after it."""

    def __init__(self, game: GameSettings, seed: int) -> None:
        self.game = game
        self.seed = seed
        self.session_plan = SessionPlan(group="H", answer_key=KEY)
        self.plan: dict[str, Any] = {
            "session": "20260302T094107-H",
            "created": "2026-03-02T09:41:07+00:00",
            "group": "H",
            "condition": self.session_plan.condition,
            "variant": game.variant,
            "seed": seed,
            "recovery": RECOVERY_VERSION,
            "plan": msgspec.to_builtins(self.session_plan.resolved()),
        }
        self.readers = Readers(game, PARAMS, seed, self.plan)
        self.asked: TrialPlan | None = None
        self.write(SessionRecord(event=SessionEvent.START, plan=self.plan))
        self.write(StepRecord(to="placing"))
        # Kaspar checks the buttons: a prompt, a green, a red; no trial, no answer.
        self.write(PromptRecord(line="buttons.green", waited=8.0))
        self.write(ButtonCheckRecord(asked="green", pressed="green", at=0.0))
        self.write(ButtonCheckRecord(asked="red", pressed="red", at=0.0))
        self.write(StepRecord(to="teaching"))
        for bag in range(len(game.targets)):
            self.write(
                PoseRecord(bag=bag, round=0, pose={"right_elbow": 10.0 * bag}, at=0, rule="median")
            )
        for step in ("revealing", "guessing"):
            self.write(StepRecord(to=step))

    @property
    def state(self) -> GameState:
        return self.readers.state

    @property
    def over(self) -> bool:
        return self.state.step in ("farewell", "finished")

    def write(self, record: AnyRecord) -> AnyRecord:
        seq = len(self.readers.records) + 1
        self.readers.apply(msgspec.structs.replace(record, seq=seq, clock=float(seq)))
        return self.readers.records[-1]

    def command(self, command: Command, confirm: Confirmation) -> None:
        self.write(
            CommandRecord(
                command=command,
                gesture=f"command {command}",
                at=0.0,
                state=self.state.step,
                applied=True,
                confirm=confirm,
                source="researcher",
            )
        )

    def ask(self) -> TrialPlan:
        if self.asked is None:
            self.asked = plan_trial(
                self.state, PARAMS, self.game, self.session_plan, 3, BOOK, script("paper")
            )
            self.write(question_record(self.asked))
        return self.asked

    def answer(self, how: str) -> None:
        plan = self.ask()
        right = KEY[plan.target] == plan.toy
        green = {"right": right, "wrong": not right, "green": True, "red": False}[how]
        heard = Answer(("guess",), 1.0, "green" if green else "red", 2.0)
        scored = score_answer(
            plan, heard, self.state, PARAMS, self.game, self.session_plan, recovery=True
        )
        record = self.write(scored)
        assert isinstance(record, TrialRecord)
        self.asked = None
        for alert in recovery.alerts(self.state, record, self.game, KEY):
            self.write(alert)
        confused = recovery.confusion(self.state, record, self.game)
        if confused is not None:
            self.write(confused)
        if self.state.all_done:
            self.write(StepRecord(to="farewell"))

    def act(self, action: str) -> None:
        """One thing that happens while Kaspar guesses; what cannot happen now is skipped."""
        state = self.state
        if action in ("right", "wrong", "green", "red"):
            self.answer(action)
        elif action == "undo" and state.undo is not None:
            self.command(Command.UNDO, Confirmation.UNDO)
            back = recovery.taken_back(state, self.game)
            self.write(back if back is not None else UndoRecord(trial=state.undo.trial))
            self.asked = None  # asked anew
        elif action == "reopen" and (reopen := recovery.reopen_record(state, self.game)):
            self.command(Command.REOPEN, Confirmation.REOPEN)
            self.write(reopen)
            self.asked = None
        elif action == "pause":
            self.command(Command.PAUSE, Confirmation.PAUSE)
            self.command(Command.PAUSE, Confirmation.RESUME)
            self.asked = None
        elif action == "stop":
            # Stopped, then reopened by the researcher's "next": the step carries on.
            self.command(Command.STOP, Confirmation.STOP)
            self.write(StepRecord(to="stopped"))
            self.command(Command.NEXT, Confirmation.START)
            self.write(StepRecord(to="guessing"))
            self.asked = None
        elif action == "crash":
            # The daemon killed: what is left is the records, and the resume replays them.
            resumed = restore(None, self.readers.records, self.game, PARAMS, self.seed)
            assert state_to_plain(resumed) == state_to_plain(state)
            self.readers.state = resumed
            self.write(SessionRecord(event=SessionEvent.RESUMED, step="guessing", trials=state.trials))
            self.asked = None
        elif action == "fault":
            self.write(
                FaultRecord(
                    fault=FaultSource.SERVO, detail="overheating", state="guessing", joint="head_yaw"
                )
            )
            self.command(Command.PAUSE, Confirmation.RESUME)
            self.asked = None
        elif action == "keyfob":
            self.write(HalRecord(event=HalEvent.KEYFOB_LOST, reason="unplugged"))
            self.write(FaultRecord(fault=FaultSource.KEYFOB, detail="lost", state="guessing", joint=None))
            self.write(HalRecord(event=HalEvent.KEYFOB_BACK, device="/dev/input/event3"))
            self.command(Command.PAUSE, Confirmation.RESUME)
            self.asked = None
        elif action == "press" and state.trials:
            self.write(PressRecord(button="green", at=0.0, extra=True, trial=state.trials))
        elif action == "prompt":
            self.ask()
            self.write(PromptRecord(line="prompt.answer_again", waited=8.0))

    def finish(self) -> None:
        """The children answer right from here on, until every bag is done."""
        while not self.over:
            self.answer("right")
        self.write(StepRecord(to="finished"))

    def saved(self, directory: Path) -> Path:
        directory.mkdir()
        (directory / PLAN_FILE).write_text(json.dumps(self.plan))
        lines = [encode_record(record) + b"\n" for record in self.readers.records]
        (directory / RECORDS_FILE).write_bytes(b"".join(lines))
        return directory


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(st.sampled_from(ACTIONS), min_size=5, max_size=80),
    st.sampled_from(["names", "never"]),
    st.integers(0, 2**16),
)
# Found on Debian 12: a name re-opened and never asked again, the game ended; the
# report counted it learned (its last trial said so) where the records do not.
@example(actions=["right", "right", "wrong", "wrong", "wrong", "reopen"], exclude="names", seed=253)
def test_every_reader_agrees_after_every_record_of_any_game(
    actions: list[str], exclude: str, seed: int
) -> None:
    game = msgspec.structs.replace(SMALL, exclude_learned_rule=exclude)
    played = Played(game, seed)
    for action in actions:
        if played.over:
            break
        played.act(action)
    played.finish()
    with tempfile.TemporaryDirectory() as scratch:
        research_agrees(played.saved(Path(scratch) / "session"), played.readers)


def test_every_reader_agrees_after_every_record_of_many_random_games() -> None:
    """The same, on 300 games of seeded random events (reproducible, and more of the
    longer games than the examples above)."""
    for number in range(300):
        rng = random.Random(number)
        game = msgspec.structs.replace(SMALL, exclude_learned_rule=rng.choice(["names", "never"]))
        played = Played(game, number)
        for action in rng.choices(ACTIONS, k=rng.randint(0, 60)):
            if played.over:
                break
            played.act(action)
        played.finish()


def test_a_stop_after_a_reopen_carries_on_with_the_bag_being_asked() -> None:
    """The re-opened bag waits until the one being asked is done, a stop between or not
    (entering guessing again jumped to it, leaving the bag asked half-way)."""
    played = Played(SMALL, 1)
    while played.state.progress[0].learned is None:
        played.answer("right")
    played.answer("red")
    assert played.state.target == 1 and played.state.previous is not None
    played.act("reopen")
    played.act("stop")
    assert played.state.target == 1 and played.state.previous is not None
    assert played.ask().target == 1


def test_records_that_do_not_fit_change_nothing_and_raise_nothing() -> None:
    """The research reads sessions it did not write: an undo of an answer that is not the
    last, a re-open taken back that was never made, a target no game has."""
    played = Played(SMALL, 2)
    played.answer("red")
    played.answer("red")
    reading = Reading(SMALL.max_trials_per_target)
    for record in played.readers.records:
        reading.apply(record)
    facts = reading.facts
    stray = ReopenRecord(trial=2, target="bag 3", target_index=2, name="lion", name_index=0)
    for record in (
        UndoRecord(trial=1),  # not the last answer
        msgspec.structs.replace(stray, taken_back=True),  # never re-opened
        ConfusedRecord(
            trial=2,
            target="bag 9",
            target_index=-1,
            reason="all_rejected",
            rejected=[],
            reopen_target=None,
            reopen_name=None,
        ),
        msgspec.structs.replace(stray, target_index=10**9),
    ):
        reading.apply(record)
        assert reading.facts == facts, record
