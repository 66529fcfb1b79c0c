"""The game's parts that outlive one game (the recorder, the problems) and the routing of
gestures, each on its own: what a game hands on to the next, and whose a gesture is."""

from __future__ import annotations

from pathlib import Path

import pytest
from fault_rig import Breakage

from hal.errors import ServoFaultError
from hal.keyfob.gestures import ANSWERS_ONLY, Gesture, GestureKind
from hal.keyfob.settings import ResearcherSettings
from kasparctl.config import SessionPlan, resolve_session
from kasparctl.game.faults import HardwareFault, Problems, error_fault, step_fault
from kasparctl.game.jsonl import read_records
from kasparctl.game.opening import open_new, planned
from kasparctl.game.recorder import UNWRITTEN_LIMIT, Recorder
from kasparctl.game.records import FaultSource, PromptRecord, SessionEvent, SessionRecord
from kasparctl.game.routing import (
    ChildGesture,
    ChildPress,
    HeldPress,
    NoCommand,
    ResearcherCommand,
    Router,
)
from kasparctl.game.session import EventLog, Session
from kasparctl.game.speech import VoiceFailed
from kasparctl.game.storage import StorageFailed
from kasparctl.sim.demo import demo_config
from kasparctl.vocabulary import Command

CONFIG = demo_config()


def prompt(line: str) -> PromptRecord:
    return PromptRecord(line=line, waited=1.0)


# -- the problems -------------------------------------------------------------------------


def test_problems_tell_the_game_playing_now_and_keep_what_outlives_it() -> None:
    problems = Problems()
    told: list[dict[FaultSource, str]] = []
    problems.follow(told.append)
    for kind in FaultSource:
        problems.set(kind, f"{kind} broken")
    problems.set(FaultSource.SERVO, "servo broken")  # the same again: no news
    assert len(told) == len(FaultSource)
    assert told[-1] == {kind: f"{kind} broken" for kind in FaultSource}
    told[-1].clear()  # a copy: the listener cannot change the problems
    assert len(problems) == len(FaultSource)

    problems.game_ended()
    # The keyfob and the researcher's device still away, the voice and the disk until a
    # line is heard or a record written; a servo and a bug were that game's fault stage.
    assert dict(problems) == {
        kind: f"{kind} broken"
        for kind in (FaultSource.KEYFOB, FaultSource.RESEARCHER, FaultSource.VOICE, FaultSource.STORAGE)
    }
    problems.set(FaultSource.VOICE, None)
    assert FaultSource.VOICE not in problems
    assert len(told) == len(FaultSource)  # the game that ended is told nothing more


def test_where_the_disk_failed_is_forgotten_as_a_game_ends(tmp_path: Path) -> None:
    problems = Problems()
    problems.storage_failed(
        StorageFailed("events.jsonl: full", tmp_path / "events.jsonl", in_event_log=True)
    )
    assert problems.storage_in_event_log and FaultSource.STORAGE in problems
    problems.game_ended()
    assert not problems.storage_in_event_log and FaultSource.STORAGE in problems


def test_a_failed_step_is_the_fault_of_the_part_that_failed_or_a_bug() -> None:
    assert step_fault("guessing", VoiceFailed("no sink")).kind is FaultSource.VOICE
    refused = StorageFailed("records.jsonl: full", Path("records.jsonl"))
    assert step_fault("guessing", refused) == HardwareFault(
        FaultSource.STORAGE, str(refused), error=refused
    )
    bug = step_fault("teaching", KeyError("bag"))
    assert bug.kind is FaultSource.SOFTWARE and bug.detail == "teaching: KeyError('bag')"


def test_an_error_escaping_an_input_handler_is_the_part_that_failed_or_a_bug() -> None:
    # The soak met it: a stop's rest refused while a servo's silence was latched was
    # recorded as a software error (a crash) rather than the servo fault it is.
    refused = ServoFaultError("motion refused while faults are latched: head_pitch: silent")
    assert error_fault(refused, "the stop") == HardwareFault(FaultSource.SERVO, str(refused))
    bug = error_fault(KeyError("bag"), "a press")
    assert bug.kind is FaultSource.SOFTWARE
    assert bug.detail == "KeyError: 'bag' (while a press)"


# -- the recorder ---------------------------------------------------------------------------


async def test_records_the_disk_refused_are_kept_and_written_first_in_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    breakage = Breakage(monkeypatch)
    problems = Problems()
    events = EventLog(tmp_path)
    recorder = Recorder(events, problems)
    refused: list[StorageFailed] = []
    recorder.attach(refused.append)

    assert recorder.record(prompt("first")) is not None
    breakage.disk()
    assert recorder.record(prompt("second")) is None
    assert recorder.record(prompt("third")) is None
    with pytest.raises(StorageFailed):
        recorder.write(prompt("a change"))  # record first, or not at all: not kept
    assert recorder.unwritten == 2
    assert len(refused) == 2 and FaultSource.STORAGE in problems
    assert recorder.flush() == 2  # the disk still refuses

    breakage.disk(None)
    recorder.write(prompt("fourth"))
    assert recorder.unwritten == 0
    read = read_records(events.path).records
    assert [r.line for r in read if isinstance(r, PromptRecord)] == [
        "first", "second", "third", "fourth",
    ]
    assert [r.seq for r in read] == [1, 2, 3, 4]
    # The event log failed, and it takes records again: the disk works.
    assert FaultSource.STORAGE not in problems


async def test_no_more_than_the_limit_is_kept(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    Breakage(monkeypatch).disk()
    recorder = Recorder(EventLog(tmp_path), Problems())
    for number in range(UNWRITTEN_LIMIT + 5):
        recorder.record(prompt(str(number)))
    assert recorder.unwritten == UNWRITTEN_LIMIT


async def test_a_session_opened_again_carries_on_its_kept_records_from_its_seq_on_disk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    breakage = Breakage(monkeypatch)
    opened = open_new(tmp_path, CONFIG, SessionPlan(group="g"), seed=1)
    recorder = Recorder(EventLog(tmp_path), Problems())
    recorder.to(opened.session)
    recorder.record(SessionRecord(event=SessionEvent.START))
    breakage.disk()
    recorder.record(prompt("kept"))
    opened.session.close()  # that game ended

    breakage.disk(None)
    again, _ = Session.open(opened.session.directory)
    again.record(SessionRecord(event=SessionEvent.RESUMED), 0.0)  # the next game's first
    recorder.to(again)
    assert recorder.flush() == 0
    records = again.records()
    assert [r.seq for r in records] == [1, 2, 3]
    assert isinstance(records[-1], PromptRecord) and records[-1].line == "kept"


def test_the_one_way_to_open_a_session_writes_its_plan_and_its_first_state(
    tmp_path: Path,
) -> None:
    plan = SessionPlan(group="g")
    opened = open_new(tmp_path, CONFIG, plan, seed=7)
    expected = planned(CONFIG, plan, 7)
    assert {key: opened.session.plan[key] for key in expected} == expected
    # The plan it plays is the planned one with its uncertainty, script and life written out.
    assert opened.plan == resolve_session(CONFIG, plan).plan and opened.plan.group == "g"
    assert (opened.plan.uncertainty, opened.plan.script, opened.plan.alive) == (
        "spoken", "paper", True,
    )  # fmt: skip
    assert opened.state.trials == 0 and opened.state.step == "idle"


# -- whose a gesture is ---------------------------------------------------------------------


class Device:
    """The researcher's own device, there or away."""

    def __init__(self, connected: bool) -> None:
        self.connected = connected


def gesture(kind: GestureKind, button: str, first: str | None = None) -> Gesture:
    return Gesture(kind=kind, button=button, at=5.0, decided=5.0, first=first)


def never_asking(at: float) -> bool:
    return False


def router(source: str = "device", device: Device | None = None) -> Router:
    settings = ResearcherSettings(source=source)  # type: ignore[arg-type]
    return Router(settings, CONFIG.game.commands, device)  # type: ignore[arg-type]


def test_a_childs_green_or_red_is_always_theirs() -> None:
    for routes in (router("keyfob"), router("device", Device(True)), router("keypad")):
        press = routes.from_keyfob(gesture(GestureKind.PRESS, "red"), never_asking)
        assert press == ChildPress("red", 5.0)


def test_holds_are_the_researchers_only_on_the_keyfob_and_only_while_nobody_is_asked() -> None:
    pause = {name for name, command in CONFIG.game.commands.items() if command == "pause"}
    assert "long red" in pause
    hold = gesture(GestureKind.LONG, "red")
    device = Device(True)
    with_device = router("device", device)
    assert with_device.keyfob_needs() == ANSWERS_ONLY
    # A hold that reached the researcher's hold is never an answer, nor (no command on
    # the keyfob now) a command.
    assert with_device.from_keyfob(hold, never_asking) == HeldPress("red", "long red", 5.0)
    device.connected = False  # away: the researcher's commands are holds meanwhile
    assert with_device.commands_on_keyfob() and with_device.keyfob_needs() != ANSWERS_ONLY
    assert with_device.from_keyfob(hold, never_asking) == ResearcherCommand(
        Command.PAUSE, "long red", 5.0, "keyfob"
    )
    # Begun while the children were asked: no command, and no answer either.
    assert with_device.from_keyfob(hold, lambda at: True) == HeldPress("red", "long red", 5.0)
    chord = router("keyfob").from_keyfob(gesture(GestureKind.BOTH, "both", "red"), lambda at: True)
    assert chord == HeldPress("red", "both", 5.0)
    # A double (never a command) is the children's: its first tap is a press.
    double = gesture(GestureKind.DOUBLE, "green")
    assert router("keyfob").from_keyfob(double, lambda at: True) == ChildGesture(
        "green", "double green", 5.0
    )


def test_command_keys_say_where_they_came_from_and_a_key_of_no_command_is_recorded() -> None:
    key = gesture(GestureKind.COMMAND, "undo")
    assert router("keypad").from_keyfob(key, never_asking) == ResearcherCommand(
        Command.UNDO, "undo", 5.0, "keypad"
    )
    assert router("device", Device(True)).from_device(key) == ResearcherCommand(
        Command.UNDO, "undo", 5.0, "researcher"
    )
    for routed in (
        router("device", Device(True)).from_keyfob(key, never_asking),  # not a keypad
        router("device", Device(True)).from_device(gesture(GestureKind.COMMAND, "dance")),
    ):
        assert isinstance(routed, NoCommand) and routed.record.ignored == "no command"
