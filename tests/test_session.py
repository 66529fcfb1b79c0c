"""Crash-safe sessions: records on disk before the robot reacts, torn lines kept aside."""

from __future__ import annotations

import datetime as dt
import json
import stat
from pathlib import Path

import pytest

from kasparctl.game.session import (
    RECORDS_FILE,
    STATE_FILE,
    Session,
    SessionError,
    find_unfinished,
    read_records,
    write_atomic,
)

NOON = dt.datetime(2026, 11, 22, 12, 0, 0, tzinfo=dt.UTC)


def new_session(tmp_path: Path, group: str = "A1") -> Session:
    return Session.create(tmp_path, {"group": group, "condition": "paper/spoken"}, now=NOON)


def test_records_are_numbered_and_on_disk_at_once(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record("trial", 1.5, trial=1, choice=3)
    session.record("command", 2.0, command="pause")
    # Read back through a separate file handle, as a crash survivor would.
    lines = (session.directory / RECORDS_FILE).read_text().splitlines()
    records = [json.loads(line) for line in lines]
    assert [r["seq"] for r in records] == [1, 2]
    assert records[0]["kind"] == "trial" and records[0]["choice"] == 3
    assert records[0]["clock"] == 1.5 and records[0]["time"].startswith("20")


def test_session_ids_are_unique_and_readable(tmp_path: Path) -> None:
    first = new_session(tmp_path, "A 1/x")
    second = new_session(tmp_path, "A 1/x")
    assert first.id == "20261122T120000-A_1_x"
    assert second.id == "20261122T120000-A_1_x-2"
    assert json.loads((second.directory / "plan.json").read_text())["group"] == "A 1/x"


def test_files_are_private(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record("trial", 0.0)
    session.save_state({"step": "guessing"})
    assert stat.S_IMODE((tmp_path / "sessions").stat().st_mode) == 0o700
    assert stat.S_IMODE(session.directory.stat().st_mode) == 0o700
    for name in ("plan.json", RECORDS_FILE, STATE_FILE):
        assert stat.S_IMODE((session.directory / name).stat().st_mode) == 0o600, name


def test_snapshot_and_replay_of_later_records(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record("trial", 0.0, trial=1)
    session.save_state({"trials": 1})
    # A crash after this record and before the snapshot leaves it to replay.
    session.record("trial", 1.0, trial=2)
    session.close()
    reopened, warnings = Session.open(session.directory)
    assert warnings == []
    state, later = reopened.load_state()
    assert state == {"trials": 1}
    assert [r["trial"] for r in later] == [2]
    assert reopened.last_seq == 2
    assert reopened.record("trial", 2.0, trial=3)["seq"] == 3


def test_torn_last_line_is_moved_aside_and_cut(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record("trial", 0.0, trial=1)
    session.close()
    path = session.directory / RECORDS_FILE
    with path.open("ab") as handle:
        handle.write(b'{"seq": 2, "kind": "tri')  # the power went here
    reopened, warnings = Session.open(session.directory)
    assert len(warnings) == 1 and "torn" in warnings[0] and str(path) in warnings[0]
    assert (session.directory / (RECORDS_FILE + ".torn")).read_bytes() == b'{"seq": 2, "kind": "tri\n'
    assert [r["seq"] for r in reopened.records()] == [1]
    reopened.record("trial", 1.0, trial=2)
    assert [r["seq"] for r in reopened.records()] == [1, 2]
    assert path.read_bytes().count(b"\n") == 2


def test_torn_line_that_ends_in_newline_but_is_not_json(tmp_path: Path) -> None:
    path = tmp_path / RECORDS_FILE
    path.write_bytes(b'{"seq": 1}\n{"seq": 2, "ki\n')
    read = read_records(path)
    assert [r["seq"] for r in read.records] == [1]
    assert "torn" in read.warnings[0]
    assert path.read_bytes() == b'{"seq": 1}\n{"seq": 2, "ki\n'  # reading alone changes nothing


def test_damaged_middle_line_is_skipped_and_left_in_place(tmp_path: Path) -> None:
    path = tmp_path / RECORDS_FILE
    original = b'{"seq": 1}\nxx garbage\n{"seq": 3}\n'
    path.write_bytes(original)
    read = read_records(path, repair=True)
    assert [r["seq"] for r in read.records] == [1, 3]
    assert read.warnings == [f"{path}: line 2: skipped, not a JSON record (JSON is malformed: invalid character (byte 0))"]
    assert path.read_bytes() == original


def test_unreadable_snapshot_falls_back_to_the_records(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record("trial", 0.0, trial=1)
    (session.directory / STATE_FILE).write_bytes(b"{not json")
    state, later = session.load_state()
    assert state is None and [r["trial"] for r in later] == [1]


def test_find_unfinished_takes_the_latest_unfinished(tmp_path: Path) -> None:
    assert find_unfinished(tmp_path) is None
    done = Session.create(tmp_path, {"group": "A"}, now=NOON)
    done.save_state({}, finished=True)
    open_one = Session.create(tmp_path, {"group": "B"}, now=NOON + dt.timedelta(minutes=1))
    assert done.finished and not open_one.finished
    assert find_unfinished(tmp_path) == open_one.directory


def test_write_atomic_replaces_whole(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    write_atomic(path, b"one")
    write_atomic(path, b"two")
    assert path.read_bytes() == b"two"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.json"]


def test_unwritable_state_dir_is_a_named_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(SessionError, match=r"file/sessions: cannot create the state directory"):
        Session.create(blocker, {"group": "A"})
