"""The state directory failing mid-session: full, unwritable, removed; a session that cannot
be created.

The daemon (tests/fault_rig.py, simulated time) on a real tmpfs of 256 KiB that the test
fills to the last byte, or whose state directory it removes, and with every write refused
(EROFS) where a real read-only remount is not possible under open files. Each time:
the game stops in its fault stage, STATUS= says CANNOT SAVE and what to do, Kaspar says
the disk's line (fault.storage), nothing is played unsaved, nothing on disk is lost, the
game never loops (no "I'm awake again" while it waits), and once the disk takes records
again long red resumes it with every trial numbered once and the records the disk refused
written in order (not only in the journal).
"""

from __future__ import annotations

import errno
import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from edge_fixtures import fill, root, small_tmpfs  # noqa: F401  (root: a fixture)
from fault_rig import FaultRig, phrase_said, run_daemon

from kasparctl.game.events import GameEvent
from kasparctl.game.session import EVENTS_FILE, RECORDS_FILE


def lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def session_records(state_dir: Path) -> list[dict[str, Any]]:
    (directory,) = (state_dir / "sessions").iterdir()
    return lines(directory / RECORDS_FILE)


def assert_whole(records: list[dict[str, Any]]) -> None:
    """Every seq once and in order, every trial once and in order, from 1."""
    seqs = [r["seq"] for r in records]
    assert seqs == list(range(1, len(seqs) + 1)), seqs
    trials = [r["trial"] for r in records if r["kind"] == "trial"]
    undone = {r["trial"] for r in records if r["kind"] == "undo"}
    assert [t for t in trials if t not in undone] == sorted(set(trials) - undone)
    assert trials[0] == 1


async def cannot_save(rig: FaultRig, since_said: int = 0) -> str:
    """The game stopped for the disk, shown and said; the STATUS= it showed."""
    await rig.until("the fault stage", lambda: rig.stage == "fault")
    status = await rig.until(
        "STATUS= saying it cannot save",
        lambda: next((s for s in reversed(rig.notifier.statuses) if "CANNOT SAVE" in s), None),
    )
    assert "stop the session ('stop') or free the disk" in status
    assert "'pause' resumes once it saves again" in status
    await rig.until("Kaspar saying so", lambda: phrase_said(rig, "fault", "storage", since_said))
    return str(status)


async def waits_without_looping(rig: FaultRig, seconds: float = 120.0) -> None:
    """Left alone, the game stays in its fault stage: no new game, no resumed line."""
    import asyncio

    resumed_before = sum(e is GameEvent.RESUMED for e, _ in rig.events)
    said_before = len(rig.said())
    await asyncio.sleep(seconds)
    assert rig.stage == "fault"
    assert sum(e is GameEvent.RESUMED for e, _ in rig.events) == resumed_before
    assert not phrase_said(rig, "session", "resumed", said_before)


@pytest.mark.usefixtures("root")
def test_a_full_disk_mid_session_stops_the_game_keeps_the_records_and_resumes_once_freed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    state_dir = tmp_path / "state"
    trials_at_fill: list[int] = []

    async def scenario(rig: FaultRig) -> None:
        await rig.press("long green")
        await rig.event(GameEvent.ANSWERED, lambda info: info["trial"] >= 2, since=0)
        trials_at_fill.append(len([r for r in session_records(state_dir) if r["kind"] == "trial"]))
        filler = fill(state_dir)
        status = await cannot_save(rig)
        assert "No space left on device" in status
        await waits_without_looping(rig)
        # Nothing is played unsaved: a child's green and the researcher's resume are refused.
        await rig.press("long red")
        await rig.until("still in its fault stage", lambda: rig.stage == "fault")
        filler.unlink()
        await rig.press("long red")
        await rig.until("resumed", lambda: rig.stage in ("guessing", "farewell", "finished"))
        await rig.stage_is("finished")
        await rig.stage_is("idle")

    with small_tmpfs(state_dir):
        run_daemon(tmp_path, monkeypatch, scenario, variant="pilot")
        records = session_records(state_dir)
    assert_whole(records)
    assert records[-1]["kind"] == "step" and records[-1]["to"] == "finished"
    assert trials_at_fill[0] >= 2
    # The storage fault the disk refused at first is on disk now, in order.
    assert any(r["kind"] == "fault" and r["fault"] == "storage" for r in records)


def test_an_unwritable_disk_as_the_session_ends_keeps_its_records_for_when_it_takes_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The session's end refused (EROFS): the next game resumes it, and what the disk refused
    at the end (kept in memory, not only in the journal) reaches the disk once it can."""

    def refuse() -> None:
        rig_box[0].breakage.disk(errno.EROFS)

    rig_box: list[FaultRig] = []

    async def scenario(rig: FaultRig) -> None:
        rig_box.append(rig)
        rig.at_state["finished"] = refuse
        await rig.press("long green")
        await rig.until("the end refused", lambda: "finished" not in rig.at_state)
        await cannot_save(rig)
        await waits_without_looping(rig)
        rig.breakage.disk(None)
        await rig.press("long red")
        await rig.until(
            "the session finished on disk",
            lambda: session_records(rig.state_dir)[-1].get("to") == "finished",
        )

    rig = run_daemon(tmp_path, monkeypatch, scenario, variant="pilot")
    records = session_records(rig.state_dir)
    assert_whole(records)
    faults = [r for r in records if r["kind"] == "fault" and r["fault"] == "storage"]
    assert faults and "Read-only file system" in faults[0]["detail"]
    unwritten = [line for line in rig.log_lines() if line["event"] == "record not written"]
    assert unwritten  # the journal had them too, whole


@pytest.mark.usefixtures("root")
def test_a_state_directory_removed_mid_session_is_a_fault_and_is_written_back_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    state_dir = tmp_path / "state"
    before: list[dict[str, Any]] = []

    async def scenario(rig: FaultRig) -> None:
        await rig.press("long green")
        await rig.event(GameEvent.ANSWERED, lambda info: info["trial"] >= 2, since=0)
        before.extend(session_records(state_dir))
        shutil.rmtree(state_dir / "sessions")
        status = await cannot_save(rig)
        assert "removed while in use" in status
        await waits_without_looping(rig)
        await rig.press("long red")
        await rig.stage_is("finished")
        await rig.stage_is("idle")  # the game over, the next one waiting

    run_daemon(tmp_path, monkeypatch, scenario, variant="pilot")
    records = session_records(state_dir)
    assert records[: len(before)] == before  # what was written before is there again, whole
    assert_whole(records)
    assert records[-1].get("to") == "finished"


def test_a_session_that_cannot_be_created_says_so_and_the_next_long_green_creates_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """sessions/ unusable (a file in its way, which stops even root): long green is refused
    aloud and in STATUS=, never "let's start" and then nothing."""

    async def scenario(rig: FaultRig) -> None:
        sessions = rig.state_dir / "sessions"
        shutil.rmtree(sessions, ignore_errors=True)
        sessions.write_text("not a directory")
        said = len(rig.said())
        await rig.press("long green")
        status = await cannot_save(rig, said)
        assert "cannot create" in status
        assert not phrase_said(rig, "session", "greeting", said)
        sessions.unlink()
        await rig.press("long red")
        await rig.stage_is("idle")
        await rig.press("long green")
        await rig.event(GameEvent.ANSWERED, since=0)

    rig = run_daemon(tmp_path, monkeypatch, scenario, variant="pilot")
    records = session_records(rig.state_dir)
    assert records[0]["event"] == "start"
    assert_whole(records)
    events = lines(rig.state_dir / EVENTS_FILE)
    assert any(r["kind"] == "fault" and "cannot create" in r["detail"] for r in events)
