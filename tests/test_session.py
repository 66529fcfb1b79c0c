"""Crash-safe sessions: records on disk before the robot reacts, torn lines kept aside."""

from __future__ import annotations

import datetime as dt
import json
import stat
from pathlib import Path

import pytest

from kasparctl.config import GameSettings
from kasparctl.game.jsonl import read_json_lines, read_records
from kasparctl.game.records import (
    CommandRecord,
    FaultRecord,
    FaultSource,
    StepRecord,
    UndoRecord,
)
from kasparctl.game.resume import find_unfinished
from kasparctl.game.session import RECORDS_FILE, STATE_FILE, Session, state_to_plain
from kasparctl.game.state import GameState, StateError
from kasparctl.game.storage import SessionError, write_atomic
from kasparctl.learning.learner import LearnerParams
from kasparctl.vocabulary import Command

NOON = dt.datetime(2026, 11, 22, 12, 0, 0, tzinfo=dt.UTC)


def a_state(trials: int = 0) -> GameState:
    state = GameState.new(GameSettings(), LearnerParams(), seed=1)
    state.trials = trials
    return state


def new_session(tmp_path: Path, group: str = "A1") -> Session:
    return Session.create(tmp_path, {"group": group, "condition": "paper/spoken"}, now=NOON)


def test_records_are_numbered_and_on_disk_at_once(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    written = session.record(StepRecord(to="guessing"), 1.5)
    session.record(UndoRecord(trial=3), 2.0)
    # Read back through a separate file handle, as a crash survivor would.
    lines = (session.directory / RECORDS_FILE).read_text().splitlines()
    records = [json.loads(line) for line in lines]
    assert [r["seq"] for r in records] == [1, 2]
    assert records[0]["kind"] == "step" and records[0]["to"] == "guessing"
    assert records[0]["clock"] == 1.5 and records[0]["time"].startswith("20")
    assert records[1] == {"kind": "undo", "seq": 2, "time": records[1]["time"], "clock": 2.0, "trial": 3}
    assert written.seq == 1 and written.time == records[0]["time"]


def test_session_ids_are_unique_and_readable(tmp_path: Path) -> None:
    first = new_session(tmp_path, "A 1/x")
    second = new_session(tmp_path, "A 1/x")
    assert first.id == "20261122T120000-A_1_x"
    assert second.id == "20261122T120000-A_1_x-2"
    assert json.loads((second.directory / "plan.json").read_text())["group"] == "A 1/x"


def test_files_are_private(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record(StepRecord(to="guessing"), 0.0)
    session.save_state(a_state())
    assert stat.S_IMODE((tmp_path / "sessions").stat().st_mode) == 0o700
    assert stat.S_IMODE(session.directory.stat().st_mode) == 0o700
    for name in ("plan.json", RECORDS_FILE, STATE_FILE):
        assert stat.S_IMODE((session.directory / name).stat().st_mode) == 0o600, name


def test_snapshot_and_replay_of_later_records(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record(UndoRecord(trial=1), 0.0)
    session.save_state(a_state(trials=1))
    # A crash after this record and before the snapshot leaves it to replay.
    session.record(UndoRecord(trial=2), 1.0)
    session.close()
    reopened, warnings = Session.open(session.directory)
    assert warnings == []
    state, later = reopened.load_state()
    assert state is not None and state_to_plain(state) == state_to_plain(a_state(trials=1))
    assert later == [UndoRecord(trial=2, seq=2, time=later[0].time, clock=1.0)]
    assert reopened.last_seq == 2
    assert reopened.record(UndoRecord(trial=3), 2.0).seq == 3


def test_torn_last_line_is_moved_aside_and_cut(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record(UndoRecord(trial=1), 0.0)
    session.close()
    path = session.directory / RECORDS_FILE
    with path.open("ab") as handle:
        handle.write(b'{"seq": 2, "kind": "tri')  # the power went here
    reopened, warnings = Session.open(session.directory)
    assert len(warnings) == 1 and "torn" in warnings[0] and str(path) in warnings[0]
    assert (session.directory / (RECORDS_FILE + ".torn")).read_bytes() == b'{"seq": 2, "kind": "tri\n'
    assert [r.seq for r in reopened.records()] == [1]
    reopened.record(UndoRecord(trial=2), 1.0)
    assert [r.seq for r in reopened.records()] == [1, 2]
    assert path.read_bytes().count(b"\n") == 2


def test_torn_line_that_ends_in_newline_but_is_not_json(tmp_path: Path) -> None:
    path = tmp_path / RECORDS_FILE
    path.write_bytes(b'{"seq": 1}\n{"seq": 2, "ki\n')
    read = read_json_lines(path)
    assert [r["seq"] for r in read.records] == [1]
    assert "torn" in read.warnings[0]
    assert path.read_bytes() == b'{"seq": 1}\n{"seq": 2, "ki\n'  # reading alone changes nothing


def test_damaged_middle_line_is_skipped_and_left_in_place(tmp_path: Path) -> None:
    path = tmp_path / RECORDS_FILE
    original = b'{"seq": 1}\nxx garbage\n{"seq": 3}\n'
    path.write_bytes(original)
    read = read_json_lines(path, repair=True)
    assert [r["seq"] for r in read.records] == [1, 3]
    assert read.lines == [1, 3]
    assert read.warnings == [f"{path}: line 2: skipped, not a JSON record (JSON is malformed: invalid character (byte 0))"]
    assert path.read_bytes() == original


def test_unreadable_snapshot_falls_back_to_the_records(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record(UndoRecord(trial=1), 0.0)
    (session.directory / STATE_FILE).write_bytes(b"{not json")
    state, later = session.load_state()
    assert state is None and [r.seq for r in later] == [1]
    # A snapshot file that is JSON but no snapshot: the same.
    (session.directory / STATE_FILE).write_bytes(b'{"saved": "today"}')
    state, later = session.load_state()
    assert state is None and [r.seq for r in later] == [1]


def test_a_snapshot_whose_state_is_damaged_is_a_state_error(tmp_path: Path) -> None:
    session = new_session(tmp_path)
    session.record(UndoRecord(trial=1), 0.0)
    (session.directory / STATE_FILE).write_bytes(b'{"seq": 1, "state": {"step": "guessing"}}')
    with pytest.raises(StateError, match="unusable game state snapshot"):
        session.load_state()


def test_a_line_that_is_no_record_is_reported_with_its_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / RECORDS_FILE
    good = b'{"kind": "undo", "seq": 1, "time": "t", "clock": 0.0, "trial": 1}'
    path.write_bytes(
        good + b"\n"
        + b'{"kind": "dance", "seq": 2}\n'  # a kind this code does not know
        + b'{"kind": "step", "seq": 3, "time": "t", "clock": 1.0}\n'  # "to" missing
        + b'{"kind": "undo", "seq": 4, "time": "t", "clock": 2.0, "trial": "two"}\n'
        + good.replace(b'"seq": 1', b'"seq": 5') + b"\n"
    )
    read = read_records(path)
    assert [r.seq for r in read.records] == [1, 5]
    assert len(read.warnings) == 3
    for line, warning in zip((2, 3, 4), read.warnings, strict=True):
        assert warning.startswith(f"{path}: line {line}: skipped, not a valid record"), warning
    assert "`to`" in read.warnings[1] and "`$.trial`" in read.warnings[2]


def test_records_read_back_exactly_as_written(tmp_path: Path) -> None:
    """A field a record does not have is absent on disk, a null stays null: both read back."""
    session = new_session(tmp_path)
    written = [
        session.record(
            FaultRecord(fault=FaultSource.SERVO, detail="x", state="guessing", joint=None), 0.0
        ),
        session.record(FaultRecord(fault=FaultSource.SERVO, detail="rest", state="stopped"), 1.0),
        session.record(
            CommandRecord(
                command=Command.UNDO, gesture="double red", at=2.0, state="idle", applied=False,
                ignored="does not apply",
            ),
            2.0,
        ),
    ]
    lines = [json.loads(line) for line in (session.directory / RECORDS_FILE).read_text().splitlines()]
    assert lines[0]["joint"] is None and "joint" not in lines[1]
    assert "confirm" not in lines[2] and lines[2]["ignored"] == "does not apply"
    assert session.records() == written


def test_find_unfinished_takes_the_latest_unfinished(tmp_path: Path) -> None:
    assert find_unfinished(tmp_path) is None
    done = Session.create(tmp_path, {"group": "A"}, now=NOON)
    done.save_state(a_state(), finished=True)
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
