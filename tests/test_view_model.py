"""The view's picture as a pure function of the records: no terminal, no files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from view_records import PLAN, TOYS, Stamper, question, trial

from kasparctl.game.jsonl import read_records
from kasparctl.game.records import (
    CommandRecord,
    Confirmation,
    FaultRecord,
    FaultSource,
    HalEvent,
    HalRecord,
    PoseRecord,
    PressRecord,
    PromptRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    UndoRecord,
)
from kasparctl.game.session import RECORDS_FILE
from kasparctl.research.catalogue import load_session
from kasparctl.view.fold import daemon_events, session_view
from kasparctl.vocabulary import Command

V1_SESSIONS = Path(__file__).resolve().parent / "data" / "sessions-v1" / "state" / "sessions"


def command(confirm: Confirmation | None, state: str, applied: bool = True, **more: object):
    kind = {
        Confirmation.PAUSE: Command.PAUSE,
        Confirmation.RESUME: Command.PAUSE,
        Confirmation.START: Command.NEXT,
        Confirmation.NEXT_STEP: Command.NEXT,
        Confirmation.STOP: Command.STOP,
        None: Command.PAUSE,
    }[confirm]
    fields = {"confirm": confirm} if confirm is not None else {}
    return CommandRecord(
        command=kind, gesture="long red", at=0.0, state=state, applied=applied, **fields, **more
    )


def fold(*records):
    stamp = Stamper()
    return session_view(PLAN, [stamp(record) for record in records])


def test_the_plan_names_the_session_group_and_condition() -> None:
    view = fold()
    assert (view.session, view.group, view.condition, view.variant, view.profile) == (
        "20260302T090000-G7",
        "G7",
        "paper/spoken",
        "names",
        "paper",
    )
    assert view.stage == "idle" and view.question is None and view.trials == 0


def test_an_open_question_shows_every_toy_and_whose_turn_it_is() -> None:
    asked = question(1, choice="giraffe", child="Amira")
    view = fold(StepRecord(to="guessing"), asked)
    q = view.question
    assert q is not None and q.open and view.whose_turn == "Amira"
    assert [bar.toy for bar in q.bars] == TOYS
    assert [bar.probability for bar in q.bars] == asked.probabilities
    assert [bar.toy for bar in q.bars if bar.chosen] == ["giraffe"]
    assert q.entropy == asked.entropy and q.max_entropy == pytest.approx(math.log2(6))
    assert q.band == "no_idea" and view.toys == tuple(TOYS)


def test_the_answer_closes_the_question_and_counts_a_trial() -> None:
    asked = question(1)
    view = fold(StepRecord(to="guessing"), asked, trial(asked, "red", reaction_time=2.25))
    q = view.question
    assert q is not None and not q.open and q.answer == "red" and q.reaction_time == 2.25
    assert view.whose_turn is None and view.trials == 1
    assert [(a.trial, a.feedback) for a in view.answers] == [(1, "red")]


def test_a_learned_toy_is_shown_in_its_place_but_not_offered() -> None:
    first = question(1, choice="monkey")
    second = question(2, target=1, offered=[t for t in TOYS if t != "monkey"], choice="lion")
    view = fold(
        StepRecord(to="guessing"), first, trial(first, learned=True, problem_trial=2), second
    )
    q = view.question
    assert q is not None and q.trial == 2
    assert [bar.toy for bar in q.bars] == TOYS
    assert [bar.toy for bar in q.bars if not bar.offered] == ["monkey"]
    assert q.max_entropy == pytest.approx(math.log2(5))
    assert [(item.target, item.toy) for item in view.learned] == [("bag 1", "monkey")]


def test_a_child_who_gives_a_wrong_red_is_seen() -> None:
    asked = question(1)
    view = fold(asked, trial(asked, "red", correct=True, feedback_right=False))
    assert view.answers[-1].wrong == "wrong red"


def test_prompts_and_early_presses_are_counted_on_the_open_question() -> None:
    view = fold(
        question(1),
        PressRecord(button="green", at=0.0, ignored="before the question was finished"),
        PromptRecord(line="prompt.nobody_first", waited=8.0),
        PromptRecord(line="prompt.nobody_second", waited=8.0),
    )
    assert view.question is not None
    assert (view.question.prompts, view.question.early_presses) == (2, 1)


def test_pause_and_resume_return_to_the_step_left() -> None:
    view = fold(StepRecord(to="placing"), command(Confirmation.PAUSE, "placing"))
    assert (view.stage, view.step) == ("paused", "placing")
    view = fold(
        StepRecord(to="placing"),
        command(Confirmation.PAUSE, "placing"),
        command(Confirmation.RESUME, "paused"),
    )
    assert (view.stage, view.step) == ("placing", "placing")
    assert [c.outcome for c in view.commands] == ["pause", "resume"]


def test_a_fault_the_game_stopped_for_is_pending_until_the_resume() -> None:
    fault = FaultRecord(
        fault=FaultSource.SERVO, detail="timeout: no reply", joint="right_elbow", state="guessing"
    )
    refused = command(None, "fault", applied=False, ignored="the hardware is still faulty")
    view = fold(StepRecord(to="guessing"), fault, refused)
    assert view.stage == "fault" and view.step == "guessing"
    (pending,) = view.pending_faults
    assert (pending.source, pending.joint, pending.detail) == (
        "servo",
        "right_elbow",
        "timeout: no reply",
    )
    assert view.commands[-1].outcome == "the hardware is still faulty"
    view = fold(StepRecord(to="guessing"), fault, command(Confirmation.RESUME, "fault"))
    assert view.stage == "guessing" and view.pending_faults == () and len(view.faults) == 1


def test_a_failure_that_stopped_nothing_is_history_only() -> None:
    after_stop = FaultRecord(fault=FaultSource.SERVO, detail="rest after stop: x", state="stopped")
    voice = HalRecord(event=HalEvent.VOICE, status="timeout", text="Hello", error=None)
    view = fold(StepRecord(to="stopped"), after_stop, voice)
    assert view.stage == "stopped" and view.pending_faults == ()
    assert [f.source for f in view.faults] == ["servo", "voice"]
    assert "Hello" in view.faults[-1].detail


def test_the_keyfob_lost_until_it_is_back() -> None:
    lost = HalRecord(event=HalEvent.KEYFOB_LOST, reason="unplugged")
    fault = FaultRecord(fault=FaultSource.KEYFOB, detail="unplugged", joint=None, state="placing")
    view = fold(StepRecord(to="placing"), lost, fault)
    assert view.keyfob_lost and view.stage == "fault"
    assert view.pending_faults[0].source == "keyfob"
    view = fold(StepRecord(to="placing"), lost, fault, HalRecord(event=HalEvent.KEYFOB_BACK))
    assert not view.keyfob_lost


def test_a_shutdown_waits_for_the_resume_and_the_resume_starts_afresh() -> None:
    fault = FaultRecord(fault=FaultSource.VOICE, detail="espeak hung", joint=None, state="guessing")
    shutdown = SessionRecord(event=SessionEvent.SHUTDOWN, reason="SIGTERM", state="fault")
    view = fold(StepRecord(to="guessing"), fault, shutdown)
    assert view.shutdown == "SIGTERM" and view.stage == "fault"
    resumed = SessionRecord(event=SessionEvent.RESUMED, step="guessing", trials=0)
    view = fold(StepRecord(to="guessing"), question(1), fault, shutdown, resumed)
    assert view.shutdown is None and view.resumes == 1
    assert view.stage == "guessing" and view.pending_faults == ()
    # The question it stopped in will be asked again: nobody's turn until then.
    assert view.question is not None and view.question.interrupted and view.whose_turn is None
    view = fold(StepRecord(to="guessing"), question(1), resumed, question(1))
    assert view.question is not None and view.question.open and view.whose_turn == "child one"


def test_an_undone_answer_no_longer_counts() -> None:
    first = question(1, choice="lion")
    view = fold(first, trial(first, learned=True), UndoRecord(trial=1))
    assert view.trials == 0 and view.undone == 1 and view.learned == ()
    assert view.answers[0].undone and view.question is not None and view.question.undone


def test_teaching_counts_the_poses() -> None:
    view = fold(
        StepRecord(to="teaching"),
        PoseRecord(bag=0, round=0, pose={"right_elbow": 10.0}, at=1.0),
        PressRecord(button="green", at=2.0, teach_retry=1, outside=["right_elbow"]),
        PoseRecord(bag=1, round=0, pose={"right_elbow": 12.0}, at=3.0),
    )
    assert (view.teaching.poses, view.teaching.bag, view.teaching.retries) == (2, 2, 1)


def test_the_session_as_recorded_before_question_records_existed() -> None:
    """The v1 sessions have no question records: each trial shows what was asked."""
    for directory in sorted(V1_SESSIONS.iterdir()):
        plan = json.loads((directory / "plan.json").read_text())
        read = read_records(directory / RECORDS_FILE)
        view = session_view(plan, read.records)
        known = load_session(directory)
        counted, every = list(known.trials()), list(known.all_trials())
        assert view.trials == len(counted)
        assert view.undone == len(every) - len(counted)
        last = every[-1]
        assert view.question is not None and view.question.trial == last.trial
        assert [bar.probability for bar in view.question.bars] == last.probabilities
        assert sorted(item.toy for item in view.learned) == sorted(
            t.choice for t in counted if t.learned
        )


def test_daemon_events_of_kinds_this_code_does_not_know() -> None:
    events = daemon_events(
        [
            {
                "kind": "fault",
                "fault": "servo",
                "time": "2026-03-02T09:00:00+00:00",
                "detail": "bus body: adapter missing",
            },
            {"kind": "start", "time": "2026-03-02T09:00:01+00:00"},
            {"event": "shutdown", "reason": "SIGTERM"},
        ]
    )
    assert [(e.name, e.fault, e.detail) for e in events] == [
        ("servo", True, "bus body: adapter missing"),
        ("start", False, ""),
        ("shutdown", False, "SIGTERM"),
    ]


def test_the_researchers_device_away_is_a_failure_that_stopped_nothing() -> None:
    lost = HalRecord(event=HalEvent.RESEARCHER_LOST, reason="not available at start: ENOENT")
    view = fold(StepRecord(to="placing"), lost, HalRecord(event=HalEvent.RESEARCHER_BACK))
    (fault,) = view.faults
    assert (fault.source, fault.detail, fault.stopped_game) == (
        "researcher",
        "not available at start: ENOENT",
        False,
    )
    assert view.stage == "placing"
