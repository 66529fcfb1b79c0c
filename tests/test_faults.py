"""Every fault in every stage: recorded, logged at its level, shown, said, and survived.

The table of docs/faults.md: each (stage, fault) pair is one test, named
test_fault_in_every_stage[STAGE-FAULT]. The daemon plays on simulated hardware
in simulated time (tests/fault_rig.py); the test brings the game to STAGE,
breaks FAULT there, makes the game do what shows it (the next line Kaspar says,
the next record written) where nothing shows it at once, and checks:

- recorded: in the session when one is open, else in the event log (a storage
  fault, which the disk refuses, is in the journal whole and reaches the disk
  once it takes records again);
- logged: a line at warning (the keyfob) or error (everything else) names it;
- shown: a STATUS= names the part that is not working;
- said: Kaspar says what is wrong (but for the voice itself);
- survived: once it is fixed the researcher's long red resumes, the game plays
  on (a session starts or goes on), and "both" stops it; the daemon exits 0
  when told to, every trial numbered once.
"""

from __future__ import annotations

import asyncio
import errno
import io
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from fault_rig import NO_CARD, FaultRig, phrase_said, run_daemon

from hal.servos.api import FaultKind
from kasparctl.game.events import GameEvent
from kasparctl.game.records import FaultSource
from kasparctl.service.status import PROBLEM_WORDS

STAGES = (
    "idle",
    "placing",
    "teaching",
    "revealing",
    "guessing",
    "farewell",
    "paused",
    "fault",
    "stopped",
    "finished",
    "speaking",
)
FAULTS = ("servo", "bus_lost", "keyfob", "voice", "software", "disk_full", "unwritable")
PART = {
    "servo": FaultSource.SERVO,
    "bus_lost": FaultSource.SERVO,
    "keyfob": FaultSource.KEYFOB,
    "voice": FaultSource.VOICE,
    "software": FaultSource.SOFTWARE,
    "disk_full": FaultSource.STORAGE,
    "unwritable": FaultSource.STORAGE,
}
# The stages played in the pilot (straight to guessing); the others in the names game.
PILOT_STAGES = ("guessing", "farewell", "paused", "fault", "stopped", "finished")
# What makes a fault show where it waits for something: the voice and a bug wait for
# the next line Kaspar says, the disk for the next record. None: the game does it.
LINE_COMES_WITH = {
    "idle": "long green",
    "placing": "long green",
    "revealing": "long green",
    "paused": "long red",
    "fault": "long red",
    "finished": "long green",
}
RECORD_COMES_WITH = {
    "idle": "green",
    "placing": "green",
    "revealing": "green",
    "paused": "green",
    "fault": "green",
    "stopped": "green",
    "finished": "green",
    "speaking": "green",
}
STOPPABLE = ("placing", "teaching", "revealing", "guessing", "farewell", "paused", "fault")
STEP_STAGES = ("placing", "teaching", "revealing", "guessing", "farewell", "speaking")


def stops(stage: str, fault: str) -> bool | None:
    """Whether the fault puts the game in its fault stage (now, or the next game at its
    start); None where it is there already. A lost keyfob stops a running step only; a
    line or a bug in the goodbye of a stopped session has nothing left to stop."""
    if stage == "fault":
        return None
    if fault == "keyfob":
        return stage in STEP_STAGES
    return not (stage == "stopped" and fault in ("voice", "software"))


async def reach(rig: FaultRig, stage: str, fault: str, breaking: Callable[[], None]) -> None:
    """Bring the game to `stage` and call `breaking` there: at once where the game stays,
    as it enters a stage it passes through (farewell, stopped, finished), and as a
    line begins for "speaking"."""
    if stage in ("farewell", "stopped", "finished"):
        rig.at_state[stage] = breaking
    if stage == "speaking":

        def mid_line(text: str) -> None:
            if rig.stage == "placing" and rig.voice.on_line is not None:
                rig.voice.on_line = None
                breaking()  # the greeting has begun, and is still being said

        rig.voice.on_line = mid_line
    if stage in ("placing", "speaking", "guessing", "paused", "fault", "stopped"):
        await rig.press("long green")
        if stage != "speaking":  # the greeting begins at once: the fault may come first
            await rig.stage_is("placing" if stage == "placing" else "guessing")
    if stage in ("teaching", "revealing"):
        await rig.press("long green")
        await rig.stage_is("placing")
        await rig.press("long green")
        await rig.stage_is(stage)  # the children teach every bag; revealing comes by itself
    if stage == "paused":
        await rig.event(GameEvent.QUESTION)
        await rig.press("long red")
        await rig.stage_is("paused")
    if stage == "fault":
        await rig.event(GameEvent.QUESTION)
        if fault == "software":
            rig.servos.inject_fault("smile", FaultKind.OVERHEATING)
            await rig.stage_is("fault")
            rig.servos.inject_fault("smile", None)  # the researcher's resume will rearm it
        else:
            rig.breakage.bug_armed = True  # a bug in the next line stops the game
            await rig.stage_is("fault")
    if stage == "stopped":
        await rig.event(GameEvent.QUESTION)
        await rig.press("both")
    if stage in ("farewell", "finished"):
        await rig.press("long green")  # the children play the pilot to its end
    if stage in ("farewell", "stopped", "finished"):
        await rig.until(f"the game in {stage}", lambda: stage not in rig.at_state)
    elif stage == "speaking":
        await rig.until("a line begun in placing", lambda: rig.voice.on_line is None)
    else:
        breaking()


def inject(rig: FaultRig, fault: str) -> None:
    """Break `fault` now (the keyfob is unplugged by a task, as a hand does it)."""
    if fault == "servo":
        rig.servos.inject_fault("head_yaw", FaultKind.OVERHEATING)
    elif fault == "bus_lost":
        for joint in rig.servos.joints:
            rig.servos.inject_fault(joint, FaultKind.BUS_LOST)
    elif fault == "keyfob":
        asyncio.get_running_loop().create_task(rig.press("lost"))
    elif fault == "voice":
        rig.voice.inject_fault(NO_CARD)
    elif fault == "software":
        rig.breakage.bug_armed = True
    elif fault == "disk_full":
        rig.breakage.disk(errno.ENOSPC)
    elif fault == "unwritable":
        rig.breakage.disk(errno.EROFS)


async def repair(rig: FaultRig, fault: str) -> None:
    if fault == "servo":
        rig.servos.inject_fault("head_yaw", None)
    elif fault == "bus_lost":
        for joint in rig.servos.joints:
            rig.servos.inject_fault(joint, None)
    elif fault == "keyfob":
        await rig.press("back")
    elif fault == "voice":
        rig.voice.inject_fault(None)
    elif fault in ("disk_full", "unwritable"):
        rig.breakage.disk(None)


def recorded(records: list[dict[str, Any]], fault: str) -> bool:
    if fault == "servo":
        return any(r["kind"] == "fault" and r.get("joint") == "head_yaw" for r in records)
    if fault == "bus_lost":
        return any(r["kind"] == "fault" and "bus_lost" in r["detail"] for r in records)
    if fault == "keyfob":
        events = [r["event"] for r in records if r["kind"] == "hal"]
        return "keyfob_lost" in events and "keyfob_back" in events
    if fault == "voice":
        return any(
            r["kind"] == "hal" and r["event"] == "voice" and "cannot find card '0'" in r["error"]
            for r in records
        )
    return any(r["kind"] == "fault" and r["fault"] == PART[fault].value for r in records)


def logged(rig: FaultRig, fault: str) -> bool:
    part = PART[fault].value
    level = "warning" if fault == "keyfob" else "error"
    return any(
        line["level"] == level and part in (line.get("fault"), line.get("part"))
        for line in rig.log_lines()
    )


@pytest.mark.parametrize("fault", FAULTS)
@pytest.mark.parametrize("stage", STAGES)
def test_fault_in_every_stage(
    stage: str, fault: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: dict[str, Any] = {}

    async def scenario(rig: FaultRig) -> None:
        marks: dict[str, int] = {}

        def breaking() -> None:
            marks["said"], marks["statuses"] = len(rig.said()), len(rig.notifier.statuses)
            marks["events"] = len(rig.events)
            inject(rig, fault)

        await reach(rig, stage, fault, breaking)
        said_before, statuses_before = marks["said"], marks["statuses"]
        storage = PART[fault] is FaultSource.STORAGE
        provoke = (RECORD_COMES_WITH if storage else LINE_COMES_WITH).get(stage)
        if fault in ("voice", "software", "disk_full", "unwritable") and provoke:
            await rig.press(provoke)
        words = PROBLEM_WORDS[PART[fault]]
        await rig.until(
            f"STATUS= showing {words}",
            lambda: any(words in s for s in rig.notifier.statuses[statuses_before:]),
        )
        seen["status"] = next(s for s in rig.notifier.statuses[statuses_before:] if words in s)
        if fault != "voice":
            # No joint is named to the children: a servo is "part of my body", the disk "storage".
            key = {
                "keyfob": "keyfob_lost",
                "disk_full": "storage",
                "unwritable": "storage",
                "servo": "servo",
                "bus_lost": "servo",
            }.get(fault, "problem")
            await rig.until(f"Kaspar saying fault.{key}", lambda: phrase_said(rig, "fault", key, said_before))
        if storage:
            # While the disk refuses, the journal holds what could not be written, whole.
            await rig.until(
                "the unwritten fault record in the journal",
                lambda: any(
                    line["event"] == "record not written"
                    and isinstance(line["record"], dict)
                    and line["record"].get("fault") == "storage"
                    for line in rig.log_lines()
                ),
            )
        def entered_fault() -> bool:
            return any(
                event is GameEvent.STATE and info["state"] == "fault"
                for event, info in rig.events[marks["events"] :]
            )

        if stops(stage, fault):
            await rig.until("the fault stage", entered_fault)
        seen["stopped the game"] = entered_fault()
        await repair(rig, fault)
        # Fixed: the researcher resumes; the game plays on and stops when told.
        if fault == "keyfob":
            await rig.until("the keyfob back", lambda: FaultSource.KEYFOB not in rig.daemon.game.problems)
        if rig.stage != "fault" and fault in ("servo", "bus_lost", "software", "disk_full", "unwritable"):
            # A fault that came as a session ended stops the next game, at its start.
            await rig.stage_is("fault", *STOPPABLE, "idle")
        if rig.stage == "fault":
            await rig.press("long red")
            await rig.until("the resume", lambda: rig.stage != "fault")
        seen["resumed to"] = rig.stage
        if rig.stage not in STOPPABLE:
            await rig.stage_is("idle")
            await rig.press("long green")
            await rig.stage_is("placing", "guessing")
        mark = len(rig.events)
        await rig.press("both")
        await rig.event(GameEvent.STATE, lambda i: i["state"] == "stopped", since=mark)
        await rig.stage_is("idle")
        seen["records"] = rig.records()

    variant = "pilot" if stage in PILOT_STAGES else "names"
    rig = run_daemon(tmp_path, monkeypatch, scenario, variant)
    records = seen["records"]
    assert recorded(records, fault), f"no record of {fault} in {stage}"
    assert logged(rig, fault), f"no {fault} line at its level"
    assert PROBLEM_WORDS[PART[fault]] in seen["status"]
    if stops(stage, fault) is False:
        assert not seen["stopped the game"], f"{fault} in {stage} stopped the game"
    if os.environ.get("KASPAR_FAULT_TABLE"):
        where = "session" if any(recorded(r, fault) for r in rig.session_records()) else "events"
        with open(os.environ["KASPAR_FAULT_TABLE"], "a") as table:
            print(json.dumps({"stage": stage, "fault": fault, "where": where,
                              "stopped": seen["stopped the game"], "resumed": seen["resumed to"]}),
                  file=table)  # fmt: skip
    for trials in rig.session_records():
        numbers = [r["trial"] for r in trials if r["kind"] == "trial"]
        assert numbers == list(range(1, len(numbers) + 1)), numbers
        seqs = [r["seq"] for r in trials]
        assert seqs == list(range(1, len(seqs) + 1))


def test_a_hung_voice_keeps_no_gesture_waiting(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A player that hangs: the first line is waited for to its timeout (nothing knew yet);
    from then on the voice counts as failing, and pause, resume and stop are applied at
    once, their lines said in the background."""
    took: dict[str, float] = {}

    async def scenario(rig: FaultRig) -> None:
        loop = asyncio.get_running_loop()
        await rig.press("long green")
        await rig.event(GameEvent.WAITING_FOR_RESEARCHER, lambda i: i["step"] == "placing")
        rig.voice.inject_fault("player: no end", hang=True)
        for action, stage in (("long green", "teaching"), ("long red", "paused"),
                              ("long red", "teaching"), ("both", "stopped")):  # fmt: skip
            mark, started = len(rig.events), loop.time()
            await rig.press(action)
            await rig.event(GameEvent.STATE, lambda i, s=stage: i["state"] == s, since=mark)
            took[f"{action} to {stage}"] = loop.time() - started
        assert "voice failing" in rig.status() or any("voice failing" in s for s in rig.notifier.statuses)

    rig = run_daemon(tmp_path, monkeypatch, scenario)
    timeout = rig.daemon.config.voice.timeout
    # The first gesture's confirmation was the line that showed the voice hangs.
    assert took["long green to teaching"] >= timeout
    hold = 1.2  # a long press is held this long before it is one
    for gesture in ("long red to paused", "long red to teaching", "both to stopped"):
        assert took[gesture] < hold + 1.0, took
    records = rig.records()
    timed_out = [r for r in records if r["kind"] == "hal" and r.get("status") == "timed_out"]
    assert timed_out and timed_out[0]["error"] == f"no end after {timeout} s"


def test_the_real_keyfob_reader_plugged_in_after_the_start_starts_the_session(
    tmp_path: Path,
) -> None:
    """The evdev reader itself (hal.keyfob.reader, real inotify on a directory of device
    nodes, each a pipe-backed evdev device: there is no /dev/uinput here): nothing at the
    start, then the node appears, and a long green starts the session with no restart."""
    from evdev import ecodes
    from evdev_pipe import PipeBank
    from fault_rig import RecordedNotifier, write_config
    from service_fixtures import status_is

    from hal import Hardware
    from hal.clock import LoopClock
    from hal.keyfob.reader import Keyfob
    from hal.keyfob.settings import KeyfobSettings
    from hal.servos.sim import SimServos
    from hal.voice.sim import SimVoice
    from kasparctl.config import load_config
    from kasparctl.service.daemon import Daemon, DaemonOptions
    from kasparctl.service.status import STATUS_WORDS
    from kasparctl.sim import simtime

    bank = PipeBank(tmp_path / "input")
    bank.directory.mkdir()
    config_path = write_config(tmp_path)
    statuses: list[str] = []

    async def main() -> None:
        clock = LoopClock()
        config = load_config(str(config_path))
        keyfob = Keyfob(
            KeyfobSettings(device=str(bank.directory / "event7")), clock,
            opener=bank.open, input_dir=str(bank.directory),
        )  # fmt: skip
        changed = asyncio.Event()
        notifier = RecordedNotifier(changed.set)
        daemon = Daemon(
            DaemonOptions(str(config_path), sim=True, state_dir=str(tmp_path / "state")),
            notifier,
            hardware=Hardware(SimServos(config.servos, clock), keyfob, SimVoice(io.StringIO(), clock)),
        )
        running = asyncio.create_task(daemon.run())

        async def status(wanted: Callable[[str], bool]) -> str:
            async with asyncio.timeout(60):
                while not any(wanted(s) for s in notifier.statuses):
                    changed.clear()
                    await changed.wait()
            return next(s for s in notifier.statuses if wanted(s))

        try:
            absent = await status(lambda s: "keyfob not connected" in s)
            statuses.append(absent)
            device = bank.plug("event7")  # plugged in: the node appears
            # Idle, the problem gone: it names the group "next" starts (compared without
            # the battery's voltage and the clock's warning, as every service test does).
            idle = status_is("waiting: 'next' starts group demo, session 1")
            await status(lambda s: idle(s) and notifier.statuses[-1] == s)
            # No researcher's device in this bundle: their "next" is green held 3 s on
            # the children's keyfob (asked for nothing meanwhile).
            device.down(ecodes.KEY_PAGEDOWN)
            await asyncio.sleep(3.2)  # held: the stimulus itself, in simulated time
            device.up(ecodes.KEY_PAGEDOWN, gap=3.2)
            statuses.append(await status(status_is(STATUS_WORDS["placing"])))
        finally:
            daemon.request_stop("the test is over")
            assert await running == 0
            bank.dispose()

    simtime.run(main(), virtual=True)
    assert statuses[0].startswith("waiting: 'next' starts group demo") and "ENOENT" in statuses[0]
    assert len(list((tmp_path / "state" / "sessions").iterdir())) == 1


def test_a_session_whose_start_cannot_be_written_is_not_left_half_open(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The disk fills between the session's directory and its first record: no session is
    left without its start; once the disk takes records, long green opens a whole one."""
    from kasparctl.game.records import SessionRecord
    from kasparctl.game.session import Session
    from kasparctl.game.storage import StorageFailed

    original = Session.record
    refused: list[str] = []

    def record(self: Session, record: Any, clock: float) -> Any:
        if not refused and isinstance(record, SessionRecord):
            refused.append(self.id)
            path = self.directory / "records.jsonl"
            raise StorageFailed(f"{path}: cannot write record 1: No space left on device", path)
        return original(self, record, clock)

    monkeypatch.setattr(Session, "record", record)

    async def scenario(rig: FaultRig) -> None:
        await rig.press("long green")
        await rig.stage_is("fault")
        assert list((rig.state_dir / "sessions").iterdir()) == []
        await rig.press("long red")
        await rig.stage_is("idle")
        await rig.press("long green")
        await rig.stage_is("placing")

    rig = run_daemon(tmp_path, monkeypatch, scenario)
    (records,) = list(rig.session_records())
    assert (records[0]["kind"], records[0]["event"]) == ("session", "start")
    faults = [r for r in rig.records() if r["kind"] == "fault"]
    assert faults[0]["fault"] == "storage" and faults[0]["state"] == "idle"
