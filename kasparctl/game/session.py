"""Crash-safe sessions: a plan, a state snapshot, and append-only records.

One directory per session under <state_dir>/sessions/<id>/:

- plan.json      the session's plan entry and condition, written once;
- records.jsonl  every trial, researcher command, fault and HAL event, one
                 JSON object a line, each flushed and fsynced before the robot
                 reacts to it (a crash can lose the reaction, never the trial);
- state.json     the game state after the last record, replaced atomically
                 (temporary file, fsync, rename, fsync of the directory).

The records are the truth and the snapshot a cache: each snapshot names the
last record it includes, and a resume replays any record written after it.
A torn last line (a power cut in the middle of a write) is moved aside to
records.jsonl.torn and cut from the log, with a warning: kept, never parsed
as a record and never a crash. Files are private to the service's user.
"""

from __future__ import annotations

import datetime as dt
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import structlog

log = structlog.get_logger(__name__)

PLAN_FILE = "plan.json"
STATE_FILE = "state.json"
RECORDS_FILE = "records.jsonl"
TORN_SUFFIX = ".torn"
PRIVATE_FILE = 0o600
PRIVATE_DIR = 0o700

_encoder = msgspec.json.Encoder()


class SessionError(Exception):
    """A session directory that cannot be written or read back, with the path."""


def write_atomic(path: Path, data: bytes) -> None:
    """Replace `path` with `data` so a crash leaves the old or the new file, never half."""
    temporary = path.with_name(f".{path.name}.tmp")
    fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, PRIVATE_FILE)
    try:
        _write_all(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(temporary, path)
    _fsync_directory(path.parent)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        written = os.write(fd, view)
        view = view[written:]


def _fsync_directory(directory: Path) -> None:
    # A rename or a new file is durable only once its directory entry is.
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@dataclass(frozen=True, slots=True)
class RecordsRead:
    records: list[dict[str, Any]]
    # Human-readable reasons for anything not taken as a record.
    warnings: list[str] = field(default_factory=list)


def read_records(path: Path, repair: bool = False) -> RecordsRead:
    """Every whole record in a log. With `repair`, a torn tail is moved aside and cut.

    A torn tail is the last line when it lacks its newline or is not JSON: the
    only damage a crash between write and fsync can do to an append-only file.
    A damaged line in the middle is reported and skipped, and left in place.
    """
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return RecordsRead([])
    lines = data.split(b"\n")
    tail = lines.pop()  # after the last newline: b"" when the file ends cleanly
    records: list[dict[str, Any]] = []
    warnings: list[str] = []
    good_end = 0
    position = 0
    for number, line in enumerate(lines, start=1):
        position += len(line) + 1
        try:
            record = msgspec.json.decode(line)
            if not isinstance(record, dict):
                raise msgspec.DecodeError("not a JSON object")
        except msgspec.DecodeError as error:
            if number == len(lines) and not tail:
                tail = line + b"\n"
                break
            warnings.append(f"{path}: line {number}: skipped, not a JSON record ({error})")
            good_end = position
            continue
        records.append(record)
        good_end = position
    if tail:
        where = f"moved to {path.name}{TORN_SUFFIX}" if repair else "left in place, not read"
        warnings.append(
            f"{path}: the last line was torn ({len(tail)} bytes, a crash during a write); {where}"
        )
        if repair:
            _move_torn_tail(path, tail, good_end)
    return RecordsRead(records, warnings)


def _move_torn_tail(path: Path, tail: bytes, good_end: int) -> None:
    torn = path.with_name(path.name + TORN_SUFFIX)
    fd = os.open(torn, os.O_WRONLY | os.O_CREAT | os.O_APPEND, PRIVATE_FILE)
    try:
        _write_all(fd, tail if tail.endswith(b"\n") else tail + b"\n")
        os.fsync(fd)
    finally:
        os.close(fd)
    # Only after the bytes are safe elsewhere is the log cut back to its last whole line.
    os.truncate(path, good_end)
    _fsync_directory(path.parent)


class RecordLog:
    """Append-only JSON lines; `append` returns once the record is on disk."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, PRIVATE_FILE)

    def append(self, record: dict[str, Any]) -> None:
        _write_all(self._fd, _encoder.encode(record) + b"\n")
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def _utc_now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds")


class Session:
    """One group's session on disk: its plan, its records and its latest state."""

    def __init__(self, directory: Path, plan: dict[str, Any], last_seq: int) -> None:
        self.directory = directory
        self.plan = plan
        self.id: str = plan["session"]
        self.last_seq = last_seq
        self._log = RecordLog(directory / RECORDS_FILE)

    # -- creating and finding -------------------------------------------------

    @classmethod
    def create(
        cls, state_dir: Path, plan: dict[str, Any], now: dt.datetime | None = None
    ) -> Session:
        """A new session directory for `plan` (a dict with at least `group`)."""
        sessions = _sessions_dir(state_dir)
        stamp = (now or dt.datetime.now(dt.UTC)).strftime("%Y%m%dT%H%M%S")
        base = f"{stamp}-{_safe_name(plan['group'])}"
        session_id, suffix = base, 1
        while (sessions / session_id).exists():
            suffix += 1
            session_id = f"{base}-{suffix}"
        directory = sessions / session_id
        try:
            directory.mkdir(mode=PRIVATE_DIR)
            full_plan = {"session": session_id, "created": _utc_now(), **plan}
            write_atomic(directory / PLAN_FILE, _encoder.encode(full_plan))
        except OSError as error:
            raise SessionError(f"{directory}: cannot create the session: {error}") from error
        return cls(directory, full_plan, last_seq=0)

    @classmethod
    def open(cls, directory: Path) -> tuple[Session, list[str]]:
        """Reopen a session to carry on; returns it and any repair warnings."""
        try:
            plan = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
        except (OSError, msgspec.DecodeError) as error:
            raise SessionError(f"{directory / PLAN_FILE}: cannot read the plan: {error}") from error
        read = read_records(directory / RECORDS_FILE, repair=True)
        for warning in read.warnings:
            log.warning("session records repaired", detail=warning)
        last_seq = max((int(r.get("seq", 0)) for r in read.records), default=0)
        return cls(directory, plan, last_seq), read.warnings

    # -- state ----------------------------------------------------------------

    def load_state(self) -> tuple[dict[str, Any] | None, list[dict[str, Any]]]:
        """The last snapshot's state, and the records written after it (to replay)."""
        snapshot = self._read_snapshot()
        included = int(snapshot["seq"]) if snapshot else 0
        later = [
            record
            for record in read_records(self.directory / RECORDS_FILE).records
            if int(record.get("seq", 0)) > included
        ]
        return (snapshot["state"] if snapshot else None), later

    def _read_snapshot(self) -> dict[str, Any] | None:
        path = self.directory / STATE_FILE
        try:
            snapshot = msgspec.json.decode(path.read_bytes())
        except FileNotFoundError:
            return None
        except (OSError, msgspec.DecodeError) as error:
            # Atomic replacement makes this a disk fault, not a crash; the records
            # still hold everything, so start from them and say so.
            log.error(
                "session snapshot unreadable, replaying all records",
                path=str(path),
                error=str(error),
            )
            return None
        if not isinstance(snapshot, dict) or "seq" not in snapshot or "state" not in snapshot:
            log.error("session snapshot malformed, replaying all records", path=str(path))
            return None
        return snapshot

    def save_state(self, state: dict[str, Any], finished: bool = False) -> None:
        snapshot = {"seq": self.last_seq, "finished": finished, "saved": _utc_now(), "state": state}
        write_atomic(self.directory / STATE_FILE, _encoder.encode(snapshot))

    @property
    def finished(self) -> bool:
        return is_finished(self.directory)

    # -- records --------------------------------------------------------------

    def record(self, kind: str, clock: float, **fields: Any) -> dict[str, Any]:
        """Append one record and return it once it is on disk."""
        record = {
            "seq": self.last_seq + 1,
            "kind": kind,
            "time": _utc_now(),
            "clock": clock,
            **fields,
        }
        self._log.append(record)
        self.last_seq += 1
        return record

    def records(self) -> list[dict[str, Any]]:
        return read_records(self.directory / RECORDS_FILE).records

    def close(self) -> None:
        self._log.close()


def _sessions_dir(state_dir: Path) -> Path:
    sessions = state_dir / "sessions"
    try:
        state_dir.mkdir(mode=PRIVATE_DIR, parents=True, exist_ok=True)
        sessions.mkdir(mode=PRIVATE_DIR, exist_ok=True)
    except OSError as error:
        raise SessionError(f"{sessions}: cannot create the state directory: {error}") from error
    return sessions


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("._") or "group"


def session_dirs(state_dir: Path) -> Iterator[Path]:
    """Every session directory, oldest first (ids start with their UTC start time)."""
    sessions = state_dir / "sessions"
    if sessions.is_dir():
        yield from sorted(p for p in sessions.iterdir() if (p / PLAN_FILE).is_file())


def is_finished(directory: Path) -> bool:
    """Whether a session's last snapshot says it ended (finished or stopped)."""
    try:
        snapshot = msgspec.json.decode((directory / STATE_FILE).read_bytes())
    except (OSError, msgspec.DecodeError):
        return False
    return isinstance(snapshot, dict) and bool(snapshot.get("finished"))


def find_unfinished(state_dir: Path) -> Path | None:
    """The most recent session that did not finish, if any: it is resumed, not restarted."""
    unfinished = None
    for directory in session_dirs(state_dir):
        if not is_finished(directory):
            unfinished = directory
    return unfinished
