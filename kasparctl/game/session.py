"""Crash-safe session files: a plan, a state snapshot, and append-only records.

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
Files are private to the service's user.

The lines of records.jsonl are kasparctl.game.jsonl's (a record to its line and
back, the torn tail); every byte reaches the disk through kasparctl.game.storage;
whether an unfinished session is resumed or abandoned is kasparctl.game.resume's.
This module is where the snapshot (kasparctl.game.state.GameState) becomes bytes
and back, with msgspec.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import re
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TypeVar

import msgspec
import structlog

from kasparctl.config import DEFAULT_ROBOT_NAME, default_robot_id
from kasparctl.game.jsonl import (
    UNDECODABLE,
    RecordsRead,
    encode_record,
    line_seq,
    read_json_lines,
    read_records,
)
from kasparctl.game.records import AnyRecord, Record
from kasparctl.game.state import GameState, StateError
from kasparctl.game.storage import (
    RecordLog,
    SessionError,
    create_empty,
    make_directory,
    remove_tree,
    rename,
    rename_new,
    storage_failed,
    write_atomic,
)
from kasparctl.learning.learner import PLAIN_DATA_ERRORS, LearnerParams, LearnerState

log = structlog.get_logger(__name__)

PLAN_FILE = "plan.json"
STATE_FILE = "state.json"
RECORDS_FILE = "records.jsonl"
EVENTS_FILE = "events.jsonl"
DAMAGED_SUFFIX = ".damaged"
# A session is built under this name (".<id>.new") and renamed into place once whole.
BUILDING_SUFFIX = ".new"

_encoder = msgspec.json.Encoder()
RecordT = TypeVar("RecordT", bound=Record)


class RecordsLost(StateError):
    """A session's records end before its snapshot does: records.jsonl emptied or cut."""


# -- the snapshot ------------------------------------------------------------------


class _SnapshotOut(msgspec.Struct):
    seq: int
    finished: bool
    saved: str
    state: dict[str, Any]


class Snapshot(msgspec.Struct):
    """state.json read back: the last record it includes, and the state, still raw."""

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


def read_snapshot(directory: Path) -> Snapshot | None:
    """A session's snapshot; None where there is none, or none that can be read."""
    try:
        return msgspec.json.decode((directory / STATE_FILE).read_bytes(), type=Snapshot)
    except (OSError, *UNDECODABLE):
        return None


def write_abandoned_snapshot(directory: Path, seq: int, reason: str) -> None:
    """Replace the snapshot with {"seq", "finished": true, "abandoned": reason, "saved",
    "state"}, keeping the state it held where that was JSON (a damaged one is moved
    aside to state.json.damaged first). OSError when it cannot be written."""
    path = directory / STATE_FILE
    kept = _kept_state(path)
    snapshot = _AbandonedOut(seq, True, utc_now(), reason, kept)
    write_atomic(path, _encoder.encode(snapshot))


def _kept_state(path: Path) -> msgspec.Raw:
    """The snapshot's "state" as it was, raw; a snapshot that is not JSON is moved aside."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return msgspec.Raw(b"null")
    try:
        return msgspec.json.decode(data, type=Snapshot).state
    except UNDECODABLE:
        rename(path, path.with_name(path.name + DAMAGED_SUFFIX))
        return msgspec.Raw(b"null")


def utc_now() -> str:
    """Now, UTC, as the records and snapshots write it (ISO 8601, milliseconds)."""
    return dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds")


class Session:
    """One group's session on disk: its plan, its records and its latest state."""

    def __init__(self, directory: Path, plan: dict[str, Any], last_seq: int) -> None:
        """The session in `directory`; use create or open rather than this."""
        self.directory = directory
        self.plan = plan
        self.id: str = plan["session"]
        self.last_seq = last_seq
        # What opening it found and repaired (Session.open), one line each: said, not silent.
        self.repairs: list[str] = []
        self._log = RecordLog(directory / RECORDS_FILE, recreate=self._recreate_directory)

    def _recreate_directory(self) -> None:
        """The session's directory and plan made again (it was removed while in use)."""
        make_directory(self.directory, parents=True, exist_ok=True)
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
        other session anywhere has, `robot`, the robot's id and name (the plan's
        `robot` object, else {"id": `robot` or kasparctl.config.default_robot_id(),
        "name": "Kaspar"}), and `sequence`, its place
        among the state directory's sessions (the wall clock may be wrong: see
        session_order).

        The session is built under a hidden name (plan.json and an empty records.jsonl,
        both durable) and renamed into sessions/ in one step, so no reader ever sees it
        half made; what a crash left of an earlier one is removed here first.
        """
        sessions = _sessions_dir(state_dir)
        remove_never_started(sessions)
        now = now or dt.datetime.now(dt.UTC)
        sequence, last_uid = last_session(sessions)
        stamp = now.strftime("%Y%m%dT%H%M%S")
        base = f"{stamp}-{_safe_name(plan['group'])}"
        session_id, suffix = base, 1
        while (sessions / session_id).exists():
            suffix += 1
            session_id = f"{base}-{suffix}"
        directory = sessions / session_id
        building = sessions / f".{session_id}{BUILDING_SUFFIX}"
        full_plan = {
            "session": session_id,
            "uid": new_ulid(now, after=last_uid),
            # The robot's id and name (the plan's own, from kasparctl.game.opening).
            "robot": _robot(plan, robot),
            "created": utc_now(),
            "sequence": sequence + 1,
            **plan,
        }
        try:
            make_directory(building)
        except OSError as error:
            raise storage_failed(directory, "cannot create the session", error) from error
        try:
            write_atomic(building / PLAN_FILE, _encoder.encode(full_plan))
            create_empty(building / RECORDS_FILE)
            rename_new(building, directory)
        except OSError as error:
            # No half-made session left behind: it was never in sessions/ by its name.
            remove_tree(building)
            raise storage_failed(directory, "cannot create the session", error) from error
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
        last_seq = max((line_seq(record) for record in read.records), default=0)
        session = cls(directory, plan, last_seq)
        session.repairs = [
            warning.removeprefix(f"{directory}/") for warning in read.warnings
        ]
        return session, read.warnings

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

    def _read_snapshot(self) -> Snapshot | None:
        path = self.directory / STATE_FILE
        try:
            return msgspec.json.decode(path.read_bytes(), type=Snapshot)
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
        snapshot = _SnapshotOut(self.last_seq, finished, utc_now(), state_to_plain(state))
        path = self.directory / STATE_FILE
        try:
            self._log.ensure_present()  # a removed session is written back, not half made
            write_atomic(path, _encoder.encode(snapshot))
        except OSError as error:
            raise storage_failed(path, "cannot write the state snapshot", error) from error

    @property
    def finished(self) -> bool:
        """Whether the last snapshot says the session ended."""
        return is_finished(self.directory)

    # -- records --------------------------------------------------------------

    def record(self, record: RecordT, clock: float) -> RecordT:
        """Append `record`, stamped with its seq, the time and `clock`; return it once on disk.

        StorageFailed when it cannot be written; its seq is then not used.
        """
        stamped = stamp(record, self.last_seq + 1, clock)
        try:
            self._log.append(encode_record(stamped))
        except OSError as error:
            failed = f"cannot write record {stamped.seq}"
            raise storage_failed(self._log.path, failed, error) from error
        self.last_seq += 1
        return stamped

    def records(self) -> list[AnyRecord]:
        """Every record on disk, typed (lines that are none are left out, as read_records says)."""
        return read_records(self.directory / RECORDS_FILE).records

    def close(self) -> None:
        """Close the record log."""
        self._log.close()


def stamp(record: RecordT, seq: int, clock: float) -> RecordT:
    """`record` as it is written: its seq, the time now and `clock`."""
    return msgspec.structs.replace(record, seq=seq, time=utc_now(), clock=clock)


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
                make_directory(self.path.parent, parents=True, exist_ok=True)
                read = read_json_lines(self.path, repair=True)
                for warning in read.warnings:
                    log.warning("event log repaired", detail=warning)
                self.last_seq = max((line_seq(plain) for plain in read.records), default=0)
                self._log = RecordLog(self.path)
            stamped = stamp(record, self.last_seq + 1, clock)
            self._log.append(encode_record(stamped))
        except OSError as error:
            failed = "cannot write the event log"
            raise storage_failed(self.path, failed, error, in_event_log=True) from error
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


def new_ulid(now: dt.datetime, after: str | None = None) -> str:
    """A ULID: 48 bits of milliseconds since 1970, then 80 random bits, in 26 characters.

    Two sessions never share one (even started in the same millisecond on two robots:
    2^80 random values). Its milliseconds are past those of `after` (the state
    directory's last session's ULID), so a state directory's ULIDs sort in the order
    its sessions began even when the wall clock stepped back between them.
    """
    milliseconds = int(now.timestamp() * 1000) & ((1 << 48) - 1)
    if after is not None and (previous := ulid_milliseconds(after)) is not None:
        milliseconds = max(milliseconds, previous + 1) & ((1 << 48) - 1)
    value = (milliseconds << 80) | int.from_bytes(secrets.token_bytes(10), "big")
    return "".join(_CROCKFORD[(value >> shift) & 31] for shift in range(125, -1, -5))


def ulid_milliseconds(ulid: str) -> int | None:
    """The milliseconds a ULID begins with; None when it is not one."""
    if len(ulid) != 26 or any(c not in _CROCKFORD for c in ulid.upper()):
        return None
    value = 0
    for character in ulid.upper():
        value = value * 32 + _CROCKFORD.index(character)
    return value >> 80


def _sessions_dir(state_dir: Path) -> Path:
    sessions = state_dir / "sessions"
    try:
        make_directory(state_dir, parents=True, exist_ok=True)
        make_directory(sessions, exist_ok=True)
    except OSError as error:
        raise storage_failed(sessions, "cannot create the state directory", error) from error
    return sessions


# A session id is its start time and its group code: well within a file name's 255 bytes.
SAFE_NAME_LIMIT = 64


def _safe_name(text: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("._")[:SAFE_NAME_LIMIT].strip("._")
    return safe or "group"


def _robot(plan: dict[str, Any], robot: str | None) -> dict[str, Any]:
    given = plan.get("robot")
    if isinstance(given, dict):
        return given
    return {"id": robot or given or default_robot_id(), "name": DEFAULT_ROBOT_NAME}


def robot_id(plan: dict[str, Any]) -> str | None:
    """The id of the robot that recorded a session: plan.json's `robot`, an object since
    robots have names, a string before; None for sessions older than robot ids."""
    robot = plan.get("robot")
    if isinstance(robot, dict):
        robot = robot.get("id")
    return robot if isinstance(robot, str) else None


def session_dirs(state_dir: Path) -> Iterator[Path]:
    """Every session directory, oldest first: in the order they began (session_order)."""
    sessions = state_dir / "sessions"
    if sessions.is_dir():
        found = [
            p
            for p in sessions.iterdir()
            if not p.name.startswith(".") and (p / PLAN_FILE).is_file()
        ]
        yield from sorted(found, key=session_order)


def plan_sequence(plan: Any) -> int:
    """A plan's `sequence`; 0 for a session from before sessions were numbered."""
    sequence = plan.get("sequence", 0) if isinstance(plan, dict) else 0
    return sequence if isinstance(sequence, int) and not isinstance(sequence, bool) else 0


def session_order(directory: Path) -> tuple[int, str]:
    """Where a session stands among its state directory's: its plan's sequence number, then
    its name (a start time, which orders only the sessions from before the numbers).

    Never the wall clock alone: a robot without a real-time clock may start a session
    hours or years behind the one before it.
    """
    try:
        plan = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
    except (OSError, *UNDECODABLE):
        plan = None
    return plan_sequence(plan), directory.name


def last_session(sessions: Path) -> tuple[int, str | None]:
    """The highest sequence number among the sessions in `sessions`, and the latest uid."""
    sequence, uids = 0, []
    for directory in sessions.iterdir():
        if directory.name.startswith("."):
            continue
        try:
            plan = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
        except (OSError, *UNDECODABLE):
            continue
        sequence = max(sequence, plan_sequence(plan))
        uid = plan.get("uid") if isinstance(plan, dict) else None
        if isinstance(uid, str) and ulid_milliseconds(uid) is not None:
            uids.append(uid.upper())
    return sequence, max(uids, default=None)


def never_started(directory: Path) -> bool:
    """Whether a folder of sessions/ is what a crash left of a session being made: one
    still under its building name, or (made before sessions were built aside) a folder
    holding no plan.json and nothing but the plan's temporary file."""
    if directory.name.startswith(".") and directory.name.endswith(BUILDING_SUFFIX):
        return True
    try:
        names = {entry.name for entry in directory.iterdir()}
    except OSError:
        return False
    return names <= {f".{PLAN_FILE}.tmp"}


def remove_never_started(sessions: Path) -> None:
    """Remove what crashes left of sessions being made (never_started): the writer's job."""
    for directory in sessions.iterdir():
        if directory.is_dir() and never_started(directory):
            log.warning("removed a session a crash left half made", directory=str(directory))
            remove_tree(directory)


def is_finished(directory: Path) -> bool:
    """Whether a session's last snapshot says it ended (finished or stopped)."""
    snapshot = read_snapshot(directory)
    return snapshot is not None and snapshot.finished


# The learner's parameters, kept in plan.json when a session is created: a resume uses
# the very learner the session began with, whatever the configuration says by then.
LEARNER_FIELDS = tuple(f.name for f in dataclasses.fields(LearnerParams))


def frozen_learner(profile: str, params: LearnerParams) -> dict[str, Any]:
    """The plan.json entry "learner": the profile's name and every parameter of its learner."""
    return {"profile": profile, **{name: getattr(params, name) for name in LEARNER_FIELDS}}
