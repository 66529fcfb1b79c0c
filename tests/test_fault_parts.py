"""The parts the fault handling stands on, one by one.

A failed program's telling lines; the simulated voice's injected faults; the fifo
keyfob that comes late and goes; the event log (typed records, fsynced, numbered
on, private, never mistaken for a session by the research commands); a record the
disk refuses never left half written; the journal's priority prefix; STATUS=.
"""

from __future__ import annotations

import asyncio
import errno
import io
import json
import os
import stat
from pathlib import Path

import pytest
from fault_rig import ALSA_NO_CARD

from hal.clock import LoopClock
from hal.errors import VoiceError
from hal.keyfob.api import KeyfobBack, KeyfobLost
from hal.keyfob.sim import FifoKeyfob
from hal.voice.api import SpokenStatus
from hal.voice.processes import run, telling_lines
from hal.voice.settings import VoiceSettings
from hal.voice.sim import SimVoice
from hal.voice.speaker import Voice
from kasparctl.cli import main
from kasparctl.game import storage as storage_module
from kasparctl.game.jsonl import read_records
from kasparctl.game.records import FaultRecord, FaultSource, HalEvent, HalRecord
from kasparctl.game.session import EVENTS_FILE, EventLog, Session
from kasparctl.game.storage import RecordLog, StorageFailed
from kasparctl.log import JournalPriority, configure_logging, connected_to_journal
from kasparctl.service.status import STATUS_WORDS, status_line

# -- a failed program's telling lines ----------------------------------------------------


def test_telling_lines_keep_the_first_and_the_last_and_count_the_rest() -> None:
    told = telling_lines(ALSA_NO_CARD)
    assert told.startswith("ALSA lib confmisc.c:855:(parse_card) cannot find card '0' | ")
    assert told.endswith("aplay: main:831: audio open error: No such file or directory")
    assert "... 4 more lines ..." in told
    assert told.count(" | ") == 5  # three first, the count, two last


def test_telling_lines_are_bounded_whatever_was_written() -> None:
    flood = "\n".join("x" * 5000 for _ in range(10_000))
    told = telling_lines(flood)
    assert len(told) <= 6 * 160 + 5 * 3
    assert telling_lines("one line\n\n") == "one line"
    assert telling_lines("") == ""


async def test_a_failed_player_is_named_with_its_first_line(tmp_path: Path) -> None:
    player = tmp_path / "aplay"
    (tmp_path / "alsa.txt").write_text(ALSA_NO_CARD)
    player.write_text(f"#!/bin/sh\ncat {tmp_path / 'alsa.txt'} >&2\nexit 1\n")
    player.chmod(0o755)
    with pytest.raises(VoiceError) as failed:
        await run([str(player), "x.wav"], what="player")
    assert "player exited with 1: ALSA lib confmisc.c:855:(parse_card) cannot find card '0'" in str(
        failed.value
    )
    # The real voice: both engines fail at the player, each with its telling line.
    voice = Voice(VoiceSettings(player=(str(player), "-q"), timeout=20.0))
    try:
        spoken = await asyncio.wait_for(voice.say("Hello."), 30)
    finally:
        await voice.close()
    assert spoken.status is SpokenStatus.FAILED
    assert spoken.error is not None and spoken.error.count("cannot find card '0'") == 2


# -- the simulated voice's faults ---------------------------------------------------------


async def test_sim_voice_fails_at_once_and_cuts_the_line_being_said() -> None:
    out = io.StringIO()
    voice = SimVoice(out, LoopClock())
    speaking = asyncio.create_task(voice.say("A long line that takes its time to say, word by word."))
    await asyncio.sleep(0.05)
    voice.inject_fault("player exited with 1: cannot find card '0'")
    cut = await speaking
    assert (cut.status, cut.error) == (SpokenStatus.FAILED, "player exited with 1: cannot find card '0'")
    assert cut.via is None
    next_line = await voice.say("Hello.")
    assert next_line.status is SpokenStatus.FAILED
    voice.inject_fault(None)
    assert (await voice.say("Hello.")).status is SpokenStatus.FINISHED


async def test_sim_voice_hangs_until_its_timeout() -> None:
    loop = asyncio.get_running_loop()
    voice = SimVoice(io.StringIO(), LoopClock(), timeout=0.2)
    voice.inject_fault("no end", hang=True)
    started = loop.time()
    spoken = await voice.say("Hello.")
    assert spoken.status is SpokenStatus.TIMED_OUT and spoken.error == "no end after 0.2 s"
    assert loop.time() - started >= 0.2
    voice.cancel()  # a hung line is cut by a cancel as any other


# -- the fifo keyfob --------------------------------------------------------------------------


async def test_the_fifo_keyfob_missing_at_start_comes_goes_and_comes_back(tmp_path: Path) -> None:
    path = tmp_path / "keys"
    keyfob = FifoKeyfob(str(path), LoopClock())
    await keyfob.start()
    try:
        lost = await asyncio.wait_for(keyfob.next_event(), 5)
        assert isinstance(lost, KeyfobLost) and "not available at start" in lost.reason
        assert not keyfob.connected
        os.mkfifo(path, 0o600)
        back = await asyncio.wait_for(keyfob.next_event(), 5)
        assert isinstance(back, KeyfobBack) and back.device == str(path)
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        os.write(fd, b"g")
        os.close(fd)  # the writer going is no unplug: the keyfob holds the fifo itself
        press = await asyncio.wait_for(keyfob.next_event(), 5)
        assert (press.kind.value, press.button) == ("press", "green")  # type: ignore[union-attr]
        path.unlink()  # unplugged
        assert isinstance(await asyncio.wait_for(keyfob.next_event(), 5), KeyfobLost)
        os.mkfifo(path, 0o600)
        assert isinstance(await asyncio.wait_for(keyfob.next_event(), 5), KeyfobBack)
    finally:
        await keyfob.close()


async def test_a_file_that_is_no_fifo_is_no_keyfob(tmp_path: Path) -> None:
    path = tmp_path / "keys"
    path.write_text("g")
    keyfob = FifoKeyfob(str(path), LoopClock())
    await keyfob.start()
    try:
        lost = await asyncio.wait_for(keyfob.next_event(), 5)
        assert isinstance(lost, KeyfobLost) and "is not a fifo" in lost.reason
    finally:
        await keyfob.close()


# -- the event log -----------------------------------------------------------------------------


def test_the_event_log_is_made_at_its_first_record_private_and_numbered_on(tmp_path: Path) -> None:
    state_dir = tmp_path / "state"
    log = EventLog(state_dir)
    assert not state_dir.exists()  # nothing made until something happens
    old_umask = os.umask(0o022)
    try:
        first = log.record(HalRecord(event=HalEvent.KEYFOB_LOST, reason="not there"), 1.5)
    finally:
        os.umask(old_umask)
    log.record(FaultRecord(fault=FaultSource.SERVO, detail="hot", state="idle", joint="x"), 2.0)
    log.close()
    assert (first.seq, first.clock) == (1, 1.5)
    assert stat.S_IMODE((state_dir / EVENTS_FILE).stat().st_mode) == 0o600
    assert stat.S_IMODE(state_dir.stat().st_mode) == 0o700
    # A torn last line (a power cut mid-write) is moved aside; numbering goes on.
    with open(state_dir / EVENTS_FILE, "ab") as file:
        file.write(b'{"kind": "hal", "se')
    again = EventLog(state_dir)
    third = again.record(HalRecord(event=HalEvent.KEYFOB_BACK, device="d"), 3.0)
    again.close()
    assert third.seq == 3
    read = read_records(state_dir / EVENTS_FILE)
    assert [r.seq for r in read.records] == [1, 2, 3] and not read.warnings
    assert (state_dir / f"{EVENTS_FILE}.torn").exists()


def test_the_research_commands_read_a_state_directory_with_an_event_log(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    state_dir = tmp_path / "state"
    assert main(["demo", "--fast", "--seed", "2", "--variant", "pilot", "--state-dir", str(state_dir)]) == 0
    capsys.readouterr()
    baseline = {}
    for name, arguments in (
        ("sessions", ["sessions", "--json"]),
        ("export", ["export", "--csv", str(tmp_path / "before.csv")]),
    ):
        assert main([*arguments, "--state-dir", str(state_dir)]) == 0
        baseline[name] = capsys.readouterr().out
    log = EventLog(state_dir)
    log.record(FaultRecord(fault=FaultSource.STORAGE, detail="full", state="idle"), 1.0)
    log.close()
    assert main(["sessions", "--json", "--state-dir", str(state_dir)]) == 0
    assert capsys.readouterr().out == baseline["sessions"]
    assert main(["export", "--csv", str(tmp_path / "after.csv"), "--state-dir", str(state_dir)]) == 0
    capsys.readouterr()
    assert (tmp_path / "after.csv").read_bytes() == (tmp_path / "before.csv").read_bytes()
    assert main(["report", "--out", str(tmp_path / "report"), "--state-dir", str(state_dir)]) == 0


# -- a record the disk refuses --------------------------------------------------------------


def test_a_record_the_disk_refuses_is_never_left_half_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    log = RecordLog(tmp_path / "records.jsonl")
    log.append(b'{"seq": 1}')
    original = storage_module._write_all

    def half_then_full(fd: int, data: bytes) -> None:
        os.write(fd, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(storage_module, "_write_all", half_then_full)
    with pytest.raises(OSError):
        log.append(b'{"seq": 2, "a long record": "' + b"x" * 100 + b'"}')
    monkeypatch.setattr(storage_module, "_write_all", original)
    log.append(b'{"seq": 2}')
    log.close()
    assert (tmp_path / "records.jsonl").read_bytes() == b'{"seq": 1}\n{"seq": 2}\n'


def test_a_session_the_disk_refuses_is_named_and_leaves_nothing_behind(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def full(fd: int, data: bytes) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(storage_module, "_write_all", full)
    with pytest.raises(StorageFailed, match="cannot create the session: No space left on device"):
        Session.create(tmp_path, {"group": "A"})
    assert list((tmp_path / "sessions").iterdir()) == []
    log = EventLog(tmp_path)
    with pytest.raises(StorageFailed) as failed:
        log.record(HalRecord(event=HalEvent.KEYFOB_BACK, device="d"), 0.0)
    assert failed.value.in_event_log and failed.value.path == tmp_path / EVENTS_FILE
    assert log.last_seq == 0  # the seq of a record not written is given again


# -- the journal's priorities -----------------------------------------------------------------


def test_lines_carry_their_priority_only_on_the_journals_stream(tmp_path: Path) -> None:
    with open(tmp_path / "stream", "w") as stream:
        status = os.fstat(stream.fileno())
        here = {"JOURNAL_STREAM": f"{status.st_dev}:{status.st_ino}"}
        assert connected_to_journal(stream, here)
        assert not connected_to_journal(stream, {"JOURNAL_STREAM": f"{status.st_dev}:1"})
        assert not connected_to_journal(stream, {})
    assert not connected_to_journal(io.StringIO(), here)
    stream = io.StringIO()
    configure_logging("debug", "json", stream, journal=True)
    import structlog

    logger = structlog.get_logger()
    logger.debug("d")
    logger.info("i")
    logger.warning("w")
    logger.error("e")
    logger.critical("c")
    try:
        raise ValueError("boom")
    except ValueError:
        logger.exception("x")
    lines = stream.getvalue().splitlines()
    assert [line[:3] for line in lines] == ["<7>", "<6>", "<4>", "<3>", "<2>", "<3>"]
    for line in lines:
        json.loads(line[3:])  # each one line of JSON after its prefix, tracebacks included
    console = io.StringIO()
    configure_logging("info", "console", console, journal=True)
    structlog.get_logger().warning("w")
    assert not console.getvalue().startswith("<")  # the console renderer is never prefixed
    assert JournalPriority(lambda *_: "x")(None, "info", {"level": "nonsense"}) == "<6>x"


def test_the_standard_librarys_warnings_and_errors_keep_their_level() -> None:
    import logging

    stream = io.StringIO()
    configure_logging("info", "json", stream, journal=True)
    logging.getLogger("asyncio").error("Task exception was never retrieved")
    logging.getLogger("transitions").warning("a warning")
    logging.getLogger("quiet").info("not forwarded: below warning")
    lines = stream.getvalue().splitlines()
    assert [line[:3] for line in lines] == ["<3>", "<4>"]
    assert json.loads(lines[0][3:])["event"] == "Task exception was never retrieved"
    assert json.loads(lines[1][3:])["logger"] == "transitions"


# -- STATUS= ------------------------------------------------------------------------------------


def test_status_names_every_problem_on_one_bounded_line() -> None:
    assert status_line("idle") == STATUS_WORDS["idle"]
    line = status_line(
        "fault",
        {FaultSource.KEYFOB: "not available at start: ENOENT", FaultSource.VOICE: "x\n" * 500},
    )
    assert line.startswith(STATUS_WORDS["fault"] + " | keyfob not connected: not available at start")
    assert "\n" not in line and len(line) <= 600
    assert "voice failing: x x x" in line
