"""kasparctl.game.storage is the one place a session's files reach the disk.

Every write, fsync, rename, truncation, new directory and removal that the
session files, the record format and the resume policy make is made by a
function of kasparctl.game.storage: the one module that decides what is durable.
"""

from __future__ import annotations

import errno
import os
import stat
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from kasparctl.config import GameSettings
from kasparctl.game.records import HalEvent, HalRecord, StepRecord, UndoRecord
from kasparctl.game.resume import resume_or_abandon
from kasparctl.game.session import RECORDS_FILE, STATE_FILE, EventLog, Session
from kasparctl.game.state import GameState
from kasparctl.game.storage import StorageFailed
from kasparctl.learning.learner import LearnerParams

# The os functions that change what is on disk, as the session code and pathlib/shutil reach them.
CHANGES = ("write", "fsync", "replace", "rename", "mkdir", "truncate", "ftruncate", "unlink", "rmdir")


def _innermost_kasparctl_module() -> str | None:
    frame = sys._getframe(2)
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if name.startswith("kasparctl."):
            return str(name)
        frame = frame.f_back
    return None


@pytest.fixture
def disk_changes(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[tuple[str, str]]]:
    """Each change to the disk the project makes, as (os function, the module that made it)."""
    seen: list[tuple[str, str]] = []

    def watched(name: str, real: Callable[..., Any]) -> Callable[..., Any]:
        def call(*args: Any, **kwargs: Any) -> Any:
            module = _innermost_kasparctl_module()
            if module is not None:
                seen.append((name, module))
            return real(*args, **kwargs)

        return call

    for name in CHANGES:
        monkeypatch.setattr(os, name, watched(name, getattr(os, name)))
    yield seen


def test_a_session_s_whole_life_reaches_the_disk_only_through_storage(
    tmp_path: Path, disk_changes: list[tuple[str, str]]
) -> None:
    session = Session.create(tmp_path, {"group": "A1"})
    session.record(StepRecord(to="guessing"), 1.0)
    session.save_state(GameState.new(GameSettings(), LearnerParams(), seed=1))
    session.close()
    # A torn tail, moved aside when the session is opened again.
    with (session.directory / RECORDS_FILE).open("ab") as records:
        records.write(b'{"kind": "undo", "se')
    reopened, warnings = Session.open(session.directory)
    assert warnings and (session.directory / f"{RECORDS_FILE}.torn").exists()
    reopened.record(UndoRecord(trial=1), 2.0)
    reopened.close()
    # A snapshot that is not JSON, moved aside when the session (its plan no session
    # plan) is abandoned.
    (session.directory / STATE_FILE).write_bytes(b"{not json")
    outcome = resume_or_abandon(tmp_path, GameSettings(), lambda name: LearnerParams())
    assert [abandoned.session_id for abandoned in outcome.abandoned] == [session.id]
    assert (session.directory / f"{STATE_FILE}.damaged").exists()
    EventLog(tmp_path).record(HalRecord(event=HalEvent.KEYFOB_BACK, device="d"), 3.0)

    made_by = {module for _, module in disk_changes}
    assert made_by == {"kasparctl.game.storage"}, disk_changes
    # Every kind of change was seen, so the check above is not vacuous.
    assert {"write", "fsync", "replace", "mkdir", "ftruncate", "rename"} <= {
        name for name, _ in disk_changes
    }


def test_a_half_made_session_is_removed_through_storage(
    tmp_path: Path, disk_changes: list[tuple[str, str]], monkeypatch: pytest.MonkeyPatch
) -> None:
    real_fsync = os.fsync

    def full(fd: int) -> None:
        real_fsync(fd)
        if stat.S_ISREG(os.fstat(fd).st_mode):  # the plan's bytes, not a directory's entries
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(StorageFailed, match="cannot create the session: No space left on device"):
        Session.create(tmp_path, {"group": "A1"})
    assert list((tmp_path / "sessions").iterdir()) == []
    assert "rmdir" in {name for name, _ in disk_changes}
    assert {module for _, module in disk_changes} == {"kasparctl.game.storage"}, disk_changes


def test_a_failed_session_write_is_not_the_event_log_s(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    session = Session.create(tmp_path, {"group": "A1"})
    events = EventLog(tmp_path)

    def refuse(fd: int, data: Any) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "write", refuse)
    with pytest.raises(StorageFailed) as in_session:
        session.record(StepRecord(to="guessing"), 1.0)
    with pytest.raises(StorageFailed) as in_events:
        events.record(HalRecord(event=HalEvent.KEYFOB_BACK, device="d"), 1.0)
    assert str(in_session.value).endswith("cannot write record 1: No space left on device")
    assert not in_session.value.in_event_log
    assert in_events.value.in_event_log and in_events.value.path == tmp_path / "events.jsonl"
