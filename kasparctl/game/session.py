"""Crash-safe sessions: a plan, a state snapshot, and append-only records.

One directory per session under <state_dir>/sessions/<id>/ (and, for what happens
while no session is open, the daemon's event log <state_dir>/events.jsonl: the
same typed records, written the same way; see EventLog):

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

This module is the one place where records (kasparctl.game.records) and the
snapshot (kasparctl.game.state.GameState) become bytes and back, with msgspec.
A line that is JSON but not a record is reported with its file and line and
left out; it never stops a reader.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import errno
import os
import re
import secrets
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import msgspec
import structlog

from hal.errors import KasparError
from kasparctl.config import (
    Config,
    GameSettings,
    ProfileSettings,
    SessionPlan,
    default_robot_id,
)
from kasparctl.game.records import AnyRecord, Record, SessionEvent, SessionRecord
from kasparctl.game.stages import STATES
from kasparctl.game.state import GameState, StateError, restore
from kasparctl.learning.learner import PLAIN_DATA_ERRORS, LearnerError, LearnerParams, LearnerState

log = structlog.get_logger(__name__)

PLAN_FILE = "plan.json"
STATE_FILE = "state.json"
RECORDS_FILE = "records.jsonl"
EVENTS_FILE = "events.jsonl"
TORN_SUFFIX = ".torn"
DAMAGED_SUFFIX = ".damaged"
PRIVATE_FILE = 0o600
PRIVATE_DIR = 0o700

_encoder = msgspec.json.Encoder()
# What decoding a file's bytes as JSON raises: msgspec's errors, and a byte that is not
# UTF-8 inside a string or a key (msgspec raises Python's own error for that).
UNDECODABLE = (msgspec.DecodeError, UnicodeDecodeError)
RecordT = TypeVar("RecordT", bound=Record)


class SessionError(KasparError):
    """A session directory that cannot be written or read back, with the path."""


class RecordsLost(StateError):
    """A session's records end before its snapshot does: records.jsonl emptied or cut."""


class StorageFailed(SessionError):
    """A record, snapshot or session directory could not be written (the disk full, the
    state directory unwritable); the message names the file and the system's reason."""

    def __init__(self, message: str, path: Path) -> None:
        """`message` says what failed and why; `path` is what could not be written."""
        super().__init__(message)
        self.path = path

    @property
    def in_event_log(self) -> bool:
        """Whether the daemon's event log failed (not a session's files)."""
        return self.path.name == EVENTS_FILE


def _storage_failed(path: Path, failed: str, error: OSError) -> StorageFailed:
    reason = error.strerror or str(error)
    return StorageFailed(f"{path}: {failed}: {reason}", path)


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
class JsonLines:
    """The JSON objects of a log, one per whole line, as plain data."""

    records: list[dict[str, Any]]
    # Human-readable reasons for anything not taken as a record.
    warnings: list[str] = field(default_factory=list)
    # The line number (from 1) of each record, in the same order.
    lines: list[int] = field(default_factory=list)
    # The warnings of lines left out in the middle (damage no crash makes), torn tail apart.
    damaged: list[str] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class RecordsRead:
    """The typed records of a log, and a warning (file and line) for each line left out."""

    records: list[AnyRecord]
    warnings: list[str] = field(default_factory=list)
    # The warnings of lines left out that are not a torn tail: JSON that is no record,
    # or a damaged line in the middle.
    damaged: list[str] = field(default_factory=list)


def read_json_lines(path: Path, repair: bool = False) -> JsonLines:
    """Every whole JSON object of a log. With `repair`, a torn tail is moved aside and cut.

    A torn tail is the last line when it lacks its newline or is not JSON: the
    only damage a crash between write and fsync can do to an append-only file.
    A damaged line in the middle is reported and skipped, and left in place.
    """
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return JsonLines([])
    lines = data.split(b"\n")
    tail = lines.pop()  # after the last newline: b"" when the file ends cleanly
    records: list[dict[str, Any]] = []
    numbers: list[int] = []
    warnings: list[str] = []
    damaged: list[str] = []
    good_end = 0
    position = 0
    for number, line in enumerate(lines, start=1):
        position += len(line) + 1
        try:
            record = msgspec.json.decode(line)
            if not isinstance(record, dict):
                raise msgspec.DecodeError("not a JSON object")
        except UNDECODABLE as error:
            if number == len(lines) and not tail:
                tail = line + b"\n"
                break
            warnings.append(f"{path}: line {number}: skipped, not a JSON record ({error})")
            damaged.append(warnings[-1])
            good_end = position
            continue
        records.append(record)
        numbers.append(number)
        good_end = position
    if tail:
        where = f"moved to {path.name}{TORN_SUFFIX}" if repair else "left in place, not read"
        warnings.append(
            f"{path}: the last line was torn ({len(tail)} bytes, a crash during a write); {where}"
        )
        if repair:
            _move_torn_tail(path, tail, good_end)
    return JsonLines(records, warnings, numbers, damaged)


def read_records(path: Path, repair: bool = False) -> RecordsRead:
    """Every record of a log, typed; torn and damaged lines as read_json_lines says.

    A line that is JSON but no record this code knows (an unknown kind, a field
    missing or of the wrong type) is left out with a warning naming the file and
    the line, never a crash: a reader goes on with the records it can read.
    """
    lines = read_json_lines(path, repair)
    records: list[AnyRecord] = []
    warnings = list(lines.warnings)
    damaged = list(lines.damaged)
    for number, plain in zip(lines.lines, lines.records, strict=True):
        try:
            records.append(decode_record(plain))
        except msgspec.ValidationError as error:
            warnings.append(f"{path}: line {number}: skipped, not a valid record ({error})")
            damaged.append(warnings[-1])
    return RecordsRead(records, warnings, damaged)


def decode_record(plain: dict[str, Any]) -> AnyRecord:
    """One record from its JSON object; msgspec.ValidationError when it is none."""
    record: AnyRecord = msgspec.convert(plain, type=AnyRecord)
    return record


def record_to_plain(record: AnyRecord) -> dict[str, Any]:
    """One record as its JSON object (plain data), "kind" included, absent fields left out."""
    plain: dict[str, Any] = msgspec.to_builtins(record)
    return plain


def encode_record(record: AnyRecord) -> bytes:
    """One record as its line of records.jsonl, without the newline."""
    return _encoder.encode(record)


# -- the snapshot ------------------------------------------------------------------


class _SnapshotOut(msgspec.Struct):
    seq: int
    finished: bool
    saved: str
    state: dict[str, Any]


class _SnapshotIn(msgspec.Struct):
    seq: int
    state: msgspec.Raw
    finished: bool = False
    saved: str = ""
    # Why the session was abandoned (it could not be resumed); absent for every other.
    abandoned: str | None = None


class _AbandonedOut(msgspec.Struct):
    seq: int
    finished: bool
    saved: str
    abandoned: str
    state: msgspec.Raw


def _learner_is_given(wanted: type, value: Any) -> Any:
    # Never called: state_from_plain passes the learner in already decoded.
    raise NotImplementedError(f"cannot decode {wanted.__name__} from {type(value).__name__}")


def state_to_plain(state: GameState) -> dict[str, Any]:
    """The snapshot's "state" object as plain data (JSON-ready).

    Every field by msgspec, but the learner: it has its own plain form
    (LearnerState.to_plain, {"q": table, "rng": generator state}).
    """
    plain: dict[str, Any] = msgspec.to_builtins(msgspec.structs.replace(state, learner=None))
    plain["learner"] = state.learner.to_plain()
    return plain


def state_from_plain(plain: Any) -> GameState:
    """A GameState from its plain data; StateError if the data is not one."""
    try:
        if not isinstance(plain, dict):
            raise TypeError(f"expected a JSON object, found {type(plain).__name__}")
        learner = LearnerState.from_plain(plain["learner"])
        return msgspec.convert(
            {**plain, "learner": learner}, type=GameState, dec_hook=_learner_is_given
        )
    except (msgspec.ValidationError, *PLAIN_DATA_ERRORS) as error:
        # (LearnerError is a ValueError: a bad learner table or generator lands here too.)
        raise StateError(f"unusable game state snapshot: {error!r}") from error


def _decode_state(raw: bytes) -> GameState:
    try:
        plain = msgspec.json.decode(raw)
    except UNDECODABLE as error:
        raise StateError(f"unusable game state snapshot: {error!r}") from error
    return state_from_plain(plain)


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
    """Append-only JSON lines; `append` returns once the record is on disk.

    The file is kept open. If it is removed while open (the state directory deleted
    under the service), its records would go on into a file nobody can see: the next
    append fails instead (ENOENT, "removed"), and the one after writes the file back
    whole at its path, from the open descriptor, before appending (`recreate` first
    makes its directory again). A log closed is opened again by the next append.
    """

    def __init__(self, path: Path, recreate: Callable[[], None] | None = None) -> None:
        """Open (or create) the log at `path` for appending."""
        self.path = path
        self._recreate = recreate or self._make_directory
        self._fd = -1
        self._removal_said = False
        self._open()

    def _open(self) -> None:
        # Read as well as write: a removed file is written back from this descriptor.
        self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_APPEND, PRIVATE_FILE)

    def _make_directory(self) -> None:
        self.path.parent.mkdir(mode=PRIVATE_DIR, parents=True, exist_ok=True)

    def append(self, line: bytes) -> None:
        """Write one encoded record and its newline, and fsync.

        An OSError (the disk full) is raised after cutting the file back to where
        it was: a record half written is never left in the log for the next to follow.
        """
        self.ensure_present()
        size = os.fstat(self._fd).st_size
        try:
            _write_all(self._fd, line + b"\n")
            os.fsync(self._fd)
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, size)
            raise

    @property
    def removed(self) -> bool:
        """Whether the open file has been removed from its directory."""
        return self._fd >= 0 and os.fstat(self._fd).st_nlink == 0

    def ensure_present(self) -> None:
        """The file is at its path: reopened if closed; OSError (ENOENT) the first time it is
        found removed; from then on written back whole, or OSError why it cannot be."""
        if self._fd < 0:
            self._open()
        if not self.removed:
            return
        if not self._removal_said:
            self._removal_said = True
            raise FileNotFoundError(
                errno.ENOENT,
                "removed while in use; what it held is kept and written back once its "
                "directory can be made again",
                str(self.path),
            )
        self._write_back()

    def _write_back(self) -> None:
        size = os.fstat(self._fd).st_size
        chunks, offset = [], 0
        while offset < size:
            chunk = os.pread(self._fd, min(1 << 20, size - offset), offset)
            if not chunk:
                break
            chunks.append(chunk)
            offset += len(chunk)
        self._recreate()
        # O_EXCL: a new file someone made at the path is never merged into or overwritten.
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_APPEND, PRIVATE_FILE)
        try:
            _write_all(fd, b"".join(chunks))
            os.fsync(fd)
            _fsync_directory(self.path.parent)
        except OSError:
            os.close(fd)
            with contextlib.suppress(OSError):
                self.path.unlink()
            raise
        os.close(self._fd)
        self._fd = fd
        self._removal_said = False
        log.warning("a removed log was written back whole", path=str(self.path), bytes=offset)

    def close(self) -> None:
        """Close the file; the next append opens it again."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def _utc_now() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds")


class Session:
    """One group's session on disk: its plan, its records and its latest state."""

    def __init__(self, directory: Path, plan: dict[str, Any], last_seq: int) -> None:
        """The session in `directory`; use create or open rather than this."""
        self.directory = directory
        self.plan = plan
        self.id: str = plan["session"]
        self.last_seq = last_seq
        self._log = RecordLog(directory / RECORDS_FILE, recreate=self._recreate_directory)

    def _recreate_directory(self) -> None:
        """The session's directory and plan made again (it was removed while in use)."""
        self.directory.mkdir(mode=PRIVATE_DIR, parents=True, exist_ok=True)
        if not (self.directory / PLAN_FILE).exists():
            write_atomic(self.directory / PLAN_FILE, _encoder.encode(self.plan))

    # -- creating and finding -------------------------------------------------

    @classmethod
    def create(
        cls,
        state_dir: Path,
        plan: dict[str, Any],
        now: dt.datetime | None = None,
        robot: str | None = None,
    ) -> Session:
        """A new session directory for `plan` (a dict with at least `group`).

        The directory's name (its start time and group) is readable but not unique
        across robots or state directories; plan.json also holds `uid`, a ULID no
        other session anywhere has, and `robot`, the robot's id (`robot`, else the
        plan's, else kasparctl.config.default_robot_id()).
        """
        sessions = _sessions_dir(state_dir)
        now = now or dt.datetime.now(dt.UTC)
        stamp = now.strftime("%Y%m%dT%H%M%S")
        base = f"{stamp}-{_safe_name(plan['group'])}"
        session_id, suffix = base, 1
        while (sessions / session_id).exists():
            suffix += 1
            session_id = f"{base}-{suffix}"
        directory = sessions / session_id
        try:
            directory.mkdir(mode=PRIVATE_DIR)
        except OSError as error:
            raise _storage_failed(directory, "cannot create the session", error) from error
        try:
            full_plan = {
                "session": session_id,
                "uid": new_ulid(now),
                "robot": robot or plan.get("robot") or default_robot_id(),
                "created": _utc_now(),
                **plan,
            }
            write_atomic(directory / PLAN_FILE, _encoder.encode(full_plan))
        except OSError as error:
            # No half-made session left behind: a directory without its plan is no session.
            shutil.rmtree(directory, ignore_errors=True)
            raise _storage_failed(directory, "cannot create the session", error) from error
        return cls(directory, full_plan, last_seq=0)

    @classmethod
    def open(cls, directory: Path) -> tuple[Session, list[str]]:
        """Reopen a session to carry on; returns it and any repair warnings."""
        try:
            plan = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
        except (OSError, *UNDECODABLE) as error:
            raise SessionError(f"{directory / PLAN_FILE}: cannot read the plan: {error}") from error
        read = read_json_lines(directory / RECORDS_FILE, repair=True)
        for warning in read.warnings:
            log.warning("session records repaired", detail=warning)
        # Every line that is JSON counts, a record or not: its seq is never given again.
        last_seq = max((_seq(record) for record in read.records), default=0)
        return cls(directory, plan, last_seq), read.warnings

    # -- state ----------------------------------------------------------------

    def load_state(self) -> tuple[GameState | None, list[AnyRecord]]:
        """The last snapshot's state, and the records written after it (to replay).

        No snapshot, or one that cannot be read as a snapshot at all, gives None:
        every record is then replayed. A snapshot whose state is damaged is a
        StateError: its records may not be the ones it summarises.
        """
        snapshot = self._read_snapshot()
        included = snapshot.seq if snapshot else 0
        if included > self.last_seq:
            # Emptied or cut: resuming would number new records on after a hole.
            raise RecordsLost(
                f"{self.directory / RECORDS_FILE}: records were lost: the log ends at record "
                f"{self.last_seq}, but the snapshot {STATE_FILE} includes records up to {included}"
            )
        read = read_records(self.directory / RECORDS_FILE)
        for warning in read.warnings:
            log.warning("session record unreadable", detail=warning)
        later = [record for record in read.records if record.seq > included]
        return (_decode_state(snapshot.state) if snapshot else None), later

    def _read_snapshot(self) -> _SnapshotIn | None:
        path = self.directory / STATE_FILE
        try:
            return msgspec.json.decode(path.read_bytes(), type=_SnapshotIn)
        except FileNotFoundError:
            return None
        except (OSError, *UNDECODABLE) as error:
            if isinstance(error, msgspec.ValidationError):
                log.error("session snapshot malformed, replaying all records", path=str(path))
                return None
            # Atomic replacement makes this a disk fault, not a crash; the records
            # still hold everything, so start from them and say so.
            log.error(
                "session snapshot unreadable, replaying all records",
                path=str(path),
                error=str(error),
            )
            return None

    def save_state(self, state: GameState, finished: bool = False) -> None:
        """Replace the snapshot with `state`, as of the last record written."""
        snapshot = _SnapshotOut(self.last_seq, finished, _utc_now(), state_to_plain(state))
        path = self.directory / STATE_FILE
        try:
            self._log.ensure_present()  # a removed session is written back, not half made
            write_atomic(path, _encoder.encode(snapshot))
        except OSError as error:
            raise _storage_failed(path, "cannot write the state snapshot", error) from error

    @property
    def finished(self) -> bool:
        """Whether the last snapshot says the session ended."""
        return is_finished(self.directory)

    # -- records --------------------------------------------------------------

    def record(self, record: RecordT, clock: float) -> RecordT:
        """Append `record`, stamped with its seq, the time and `clock`; return it once on disk.

        StorageFailed when it cannot be written; its seq is then not used.
        """
        stamped = _stamped(record, self.last_seq + 1, clock)
        try:
            self._log.append(_encoder.encode(stamped))
        except OSError as error:
            failed = f"cannot write record {stamped.seq}"
            raise _storage_failed(self._log.path, failed, error) from error
        self.last_seq += 1
        return stamped

    def records(self) -> list[AnyRecord]:
        """Every record on disk, typed (lines that are none are left out, as read_records says)."""
        return read_records(self.directory / RECORDS_FILE).records

    def close(self) -> None:
        """Close the record log."""
        self._log.close()


def _stamped(record: RecordT, seq: int, clock: float) -> RecordT:
    return msgspec.structs.replace(record, seq=seq, time=_utc_now(), clock=clock)


class EventLog:
    """What happens while no session is open: <state_dir>/events.jsonl, the daemon's record.

    A fault before any session (the keyfob not there at boot, a servo that will not
    start, the disk full), a command that did not apply in idle, a line Kaspar could
    not say: the same typed records a session writes, stamped and fsynced the same
    way (each on disk before the robot reacts), numbered on from the last one in the
    file. The file is made at the first record, private like a session's files. It
    is no session: the readers of sessions/ never see it; read_records reads it.
    """

    def __init__(self, state_dir: Path) -> None:
        """The event log of `state_dir`; nothing is opened until the first record."""
        self.path = state_dir / EVENTS_FILE
        self._log: RecordLog | None = None
        self.last_seq = 0

    def record(self, record: RecordT, clock: float) -> RecordT:
        """Append `record` as Session.record does; StorageFailed when it cannot be written."""
        try:
            if self._log is None:
                self.path.parent.mkdir(mode=PRIVATE_DIR, parents=True, exist_ok=True)
                read = read_json_lines(self.path, repair=True)
                for warning in read.warnings:
                    log.warning("event log repaired", detail=warning)
                self.last_seq = max((_seq(plain) for plain in read.records), default=0)
                self._log = RecordLog(self.path)
            stamped = _stamped(record, self.last_seq + 1, clock)
            self._log.append(_encoder.encode(stamped))
        except OSError as error:
            raise _storage_failed(self.path, "cannot write the event log", error) from error
        self.last_seq += 1
        return stamped

    def records(self) -> RecordsRead:
        """Every record of the log, typed, with a warning for each line left out."""
        return read_records(self.path)

    def close(self) -> None:
        """Close the file; the next record opens it again."""
        if self._log is not None:
            self._log.close()
            self._log = None


_CROCKFORD = "0123456789ABCDEFGHJKMNPQRSTVWXYZ"


def new_ulid(now: dt.datetime) -> str:
    """A ULID: 48 bits of milliseconds since 1970, then 80 random bits, in 26 characters.

    Sorts by time like the readable id, and two sessions never share one (even started
    in the same millisecond on two robots: 2^80 random values).
    """
    milliseconds = int(now.timestamp() * 1000) & ((1 << 48) - 1)
    value = (milliseconds << 80) | int.from_bytes(secrets.token_bytes(10), "big")
    return "".join(_CROCKFORD[(value >> shift) & 31] for shift in range(125, -1, -5))


def _seq(plain: dict[str, Any]) -> int:
    seq = plain.get("seq", 0)
    return seq if isinstance(seq, int) and not isinstance(seq, bool) else 0


def _sessions_dir(state_dir: Path) -> Path:
    sessions = state_dir / "sessions"
    try:
        state_dir.mkdir(mode=PRIVATE_DIR, parents=True, exist_ok=True)
        sessions.mkdir(mode=PRIVATE_DIR, exist_ok=True)
    except OSError as error:
        raise _storage_failed(sessions, "cannot create the state directory", error) from error
    return sessions


# A session id is its start time and its group code: well within a file name's 255 bytes.
SAFE_NAME_LIMIT = 64


def _safe_name(text: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("._")[:SAFE_NAME_LIMIT].strip("._")
    return safe or "group"


def session_dirs(state_dir: Path) -> Iterator[Path]:
    """Every session directory, oldest first (ids start with their UTC start time)."""
    sessions = state_dir / "sessions"
    if sessions.is_dir():
        yield from sorted(p for p in sessions.iterdir() if (p / PLAN_FILE).is_file())


def is_finished(directory: Path) -> bool:
    """Whether a session's last snapshot says it ended (finished or stopped)."""
    try:
        snapshot = msgspec.json.decode((directory / STATE_FILE).read_bytes(), type=_SnapshotIn)
    except (OSError, *UNDECODABLE):
        return False
    return snapshot.finished


def find_unfinished(state_dir: Path) -> Path | None:
    """The most recent session that did not finish, if any: it is resumed, not restarted."""
    unfinished = None
    for directory in session_dirs(state_dir):
        if not is_finished(directory):
            unfinished = directory
    return unfinished


# -- resuming, or abandoning -----------------------------------------------------------

# The learner's parameters, kept in plan.json when a session is created: a resume uses
# the very learner the session began with, whatever the configuration says by then.
LEARNER_FIELDS = tuple(f.name for f in dataclasses.fields(LearnerParams))


def frozen_learner(profile: str, params: LearnerParams) -> dict[str, Any]:
    """The plan.json entry "learner": the profile's name and every parameter of its learner."""
    return {"profile": profile, **{name: getattr(params, name) for name in LEARNER_FIELDS}}


@dataclass(frozen=True, slots=True)
class Resumable:
    """An unfinished session read back whole: its files, its plan and the state it reached."""

    session: Session
    plan: SessionPlan
    state: GameState
    # The learner the session began with (frozen in its plan), or its profile's.
    params: LearnerParams

    def config(self, config: Config) -> Config:
        """`config` with the plan's profile being the learner the session began with, so a
        resumed game learns on as it did, whatever the configuration says now."""
        frozen = ProfileSettings(**{name: getattr(self.params, name) for name in LEARNER_FIELDS})
        profiles = {**config.learner.profiles, self.plan.profile: frozen}
        learner = msgspec.structs.replace(config.learner, profiles=profiles)
        return msgspec.structs.replace(config, learner=learner)


@dataclass(frozen=True, slots=True)
class Abandoned:
    """An unfinished session that could not be resumed, closed for good with the reason."""

    session_id: str
    directory: Path
    reason: str


@dataclass(frozen=True, slots=True)
class ResumeOutcome:
    """What the state directory held: the session to resume (if any) and those abandoned."""

    resumable: Resumable | None
    abandoned: list[Abandoned]


class CannotResume(SessionError):
    """A session's files are readable but do not make a session this configuration can
    carry on (damaged, emptied, a learner profile gone...); `reason` says which and why."""

    def __init__(self, directory: Path, reason: str) -> None:
        """`reason` names the file and what is wrong with it."""
        super().__init__(f"{directory}: cannot be resumed: {reason}")
        self.reason = reason


# What plain data of the wrong shape raises while a session is rebuilt from it.
_REPLAY_ERRORS = (StateError, LearnerError, msgspec.MsgspecError, *PLAIN_DATA_ERRORS)


def reopen(
    directory: Path,
    game: GameSettings,
    profile: Callable[[str], LearnerParams],
) -> Resumable:
    """An unfinished session, ready to carry on; CannotResume says why it is not.

    The learner is the one frozen in plan.json; a session created before it was
    kept there takes `profile(name)` of its plan (KeyError when the configuration
    no longer has it: CannotResume). A line in the middle of records.jsonl that is
    no record, a snapshot ahead of the records (the log emptied or cut), records
    that do not replay, or a state that does not fit `game` are all CannotResume.
    StorageFailed when the files cannot be read or repaired at all (a disk fault:
    the data may be whole, and is not judged).
    """
    plan_path = directory / PLAN_FILE
    try:
        raw_plan = plan_path.read_bytes()
    except OSError as error:
        raise _storage_failed(plan_path, "cannot read the plan", error) from error
    try:
        plan_json = msgspec.json.decode(raw_plan)
        if not isinstance(plan_json, dict):
            raise msgspec.ValidationError(f"expected a JSON object, found {raw_plan[:40]!r}")
        session_plan = msgspec.convert(plan_json.get("plan"), type=SessionPlan)
        session_id = plan_json["session"]
        seed = plan_json.get("seed")
        if not isinstance(session_id, str) or not (seed is None or isinstance(seed, int)):
            raise msgspec.ValidationError("expected a session id and an integer seed")
    except (msgspec.MsgspecError, UnicodeDecodeError, KeyError) as error:
        raise CannotResume(directory, f"{plan_path}: not a session plan: {error}") from error
    params = _learner_of(plan_json, session_plan, profile, directory)
    try:
        session, _warnings = Session.open(directory)
    except SessionError as error:
        raise CannotResume(directory, str(error)) from error
    except OSError as error:
        path = directory / RECORDS_FILE
        raise _storage_failed(path, "cannot read or repair the records", error) from error
    try:
        damaged = read_records(directory / RECORDS_FILE).damaged
        if damaged:
            more = f" (and {len(damaged) - 1} more)" if len(damaged) > 1 else ""
            raise CannotResume(directory, damaged[0] + more)
        snapshot, later = session.load_state()
        state = restore(snapshot, later, game, params, seed)
        if changed := _how_it_changed(state, game):
            raise CannotResume(directory, changed)
    except CannotResume:
        session.close()
        raise
    except RecordsLost as error:
        session.close()
        raise CannotResume(directory, str(error)) from error
    except _REPLAY_ERRORS as error:
        session.close()
        raise CannotResume(directory, f"its records do not replay: {error}") from error
    except OSError as error:
        session.close()
        raise _storage_failed(directory / RECORDS_FILE, "cannot read", error) from error
    return Resumable(session, session_plan, state, params)


def _learner_of(
    plan_json: dict[str, Any],
    session_plan: SessionPlan,
    profile: Callable[[str], LearnerParams],
    directory: Path,
) -> LearnerParams:
    frozen = plan_json.get("learner")
    if frozen is not None:
        try:
            values = {name: frozen[name] for name in LEARNER_FIELDS}
            if not all(_is_number(value) for value in values.values()):
                raise TypeError(f"expected numbers, found {values}")
            return LearnerParams(**values)
        except (TypeError, KeyError, LearnerError) as error:
            path = directory / PLAN_FILE
            raise CannotResume(directory, f"{path}: learner: unusable: {error!r}") from error
    try:
        return profile(session_plan.profile)
    except KeyError:
        raise CannotResume(
            directory,
            f"its learner profile {session_plan.profile!r} is no longer in the configuration, "
            f"and {PLAN_FILE} (written before the learner was kept in the plan) has no copy",
        ) from None
    except LearnerError as error:
        raise CannotResume(directory, f"its learner profile: {error}") from error


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _how_it_changed(state: GameState, game: GameSettings) -> str | None:
    """Why the state does not fit the game as configured now, or None when it does."""
    targets, labels = len(game.targets), len(game.toys)
    rows, columns = state.learner.table.shape
    if (rows, columns) != (targets, labels) or len(state.progress) != targets or len(
        state.offered
    ) != labels:
        return (
            f"the game has changed since the session began: it had {rows} targets and "
            f"{columns} toys, the configuration now has {targets} and {labels}"
        )
    if state.step not in STATES:
        return f"its state is at an unknown step {state.step!r}"
    return None


def abandon(directory: Path, reason: str, clock: float = 0.0) -> int:
    """Close an unfinished session for good: a "session" record with event "abandoned" and
    the reason at the end of its records, and a snapshot that says so. Returns its seq.

    The snapshot becomes {"seq", "finished": true, "abandoned": reason, "saved", "state"},
    keeping the state it held where that was JSON (a damaged one is moved aside to
    state.json.damaged first); nothing else is changed or removed. StorageFailed when
    either cannot be written.
    """
    records_path = directory / RECORDS_FILE
    state_path = directory / STATE_FILE
    try:
        lines = read_json_lines(records_path, repair=True)
        seq = max((_seq(plain) for plain in lines.records), default=0) + 1
        step = _last_step(lines.records)
        record = SessionRecord(event=SessionEvent.ABANDONED, reason=reason, state=step)
        records = RecordLog(records_path)
        try:
            records.append(_encoder.encode(_stamped(record, seq, clock)))
        finally:
            records.close()
    except OSError as error:
        raise _storage_failed(records_path, "cannot mark the session abandoned", error) from error
    try:
        kept = _kept_state(state_path)
        snapshot = _AbandonedOut(seq, True, _utc_now(), reason, kept)
        write_atomic(state_path, _encoder.encode(snapshot))
    except OSError as error:
        raise _storage_failed(state_path, "cannot mark the session abandoned", error) from error
    log.error("session abandoned", session=directory.name, reason=reason)
    return seq


def _last_step(records: list[dict[str, Any]]) -> str:
    steps = [plain.get("to") for plain in records if plain.get("kind") == "step"]
    last = steps[-1] if steps else "idle"
    return last if isinstance(last, str) else "unknown"


def _kept_state(path: Path) -> msgspec.Raw:
    """The snapshot's "state" as it was, raw; a snapshot that is not JSON is moved aside."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return msgspec.Raw(b"null")
    try:
        return msgspec.json.decode(data, type=_SnapshotIn).state
    except UNDECODABLE:
        os.replace(path, path.with_name(path.name + DAMAGED_SUFFIX))
        return msgspec.Raw(b"null")


def abandoned_reason(directory: Path) -> str | None:
    """Why a session was abandoned, from its snapshot; None for any other session."""
    try:
        snapshot = msgspec.json.decode((directory / STATE_FILE).read_bytes(), type=_SnapshotIn)
    except (OSError, *UNDECODABLE):
        return None
    return snapshot.abandoned


def resume_or_abandon(
    state_dir: Path,
    game: GameSettings,
    profile: Callable[[str], LearnerParams],
    clock: float = 0.0,
) -> ResumeOutcome:
    """The unfinished session to resume, each that cannot be resumed abandoned on the way.

    StorageFailed when the sessions cannot be read (permissions, a disk error) or an
    abandoned session cannot be marked so: nothing is judged then, and nothing is lost.
    """
    abandoned: list[Abandoned] = []
    tried: set[Path] = set()
    while True:
        try:
            directory = find_unfinished(state_dir)
        except OSError as error:
            raise _storage_failed(state_dir / "sessions", "cannot read", error) from error
        if directory is None or directory in tried:
            return ResumeOutcome(None, abandoned)
        tried.add(directory)
        try:
            return ResumeOutcome(reopen(directory, game, profile), abandoned)
        except CannotResume as cannot:
            abandon(directory, cannot.reason, clock)
            abandoned.append(Abandoned(directory.name, directory, cannot.reason))
