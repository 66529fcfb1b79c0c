"""Sessions found on disk: each one's plan, and what one streaming pass over its records says.

The records are the truth (see kasparctl.game.session): a session's status and
trial count come from them, not from the state snapshot, which a crash can
leave one record behind. Reading is two passes, neither holding the records:
`index_session` streams them once for what every command needs (status,
trials, undone answers, the toys, warnings), and `SessionData.records()`
streams them again for whoever wants each record (export, report).

A session that cannot be read at all (no plan, an empty or malformed plan,
a records file the user may not read) is `Damaged`, with one line saying why;
the commands list it and go on with every other session.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from hal.errors import KasparError
from kasparctl.config import CONDITION_LABELS, SPOKEN_MODES
from kasparctl.game.jsonl import TORN_SUFFIX
from kasparctl.game.records import (
    AnyRecord,
    ClockRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE, never_started
from kasparctl.learning.learner import LearnerError, LearnerParams
from kasparctl.research.reader import Warnings, is_utf8, iter_records

# plan.json is a few hundred bytes; one far larger is not a plan, and is not read whole.
MAX_PLAN_BYTES = 1 << 20
_CROCKFORD = "0123456789ABCDEFGHJKMNPQRSTVWXYZ"
ULID = re.compile(r"[0-9A-HJKMNP-TV-Z]{26}")


class CatalogueError(KasparError):
    """A state directory or a named session that cannot be found or listed, with its path."""


class PlanEntry(msgspec.Struct, kw_only=True, frozen=True):
    """The session's plan as the robot used it (a SessionPlan, read leniently)."""

    group: str = ""
    profile: str = "paper"
    # Sessions recorded before uncertainty modes have only speak_uncertainty.
    uncertainty: str | None = None
    speak_uncertainty: bool | None = None
    children: tuple[str, ...] = ()
    participants: tuple[str, ...] = ()
    group_size: int | None = None
    answer_key: tuple[str, ...] = ()


class RobotEntry(msgspec.Struct, kw_only=True, frozen=True):
    """plan.json's `robot` since robots have names: its stable id and its name."""

    id: str | None = None
    name: str | None = None


class PlanFile(msgspec.Struct, kw_only=True, frozen=True):
    """plan.json: the session's names, when it started, its condition and its plan.

    Keys added over time are read when present and None (missing) otherwise.
    """

    session: str | None = None
    # Written since sessions have ULIDs; older sessions get one derived from plan.json.
    uid: str | None = None
    # The robot's id (a string) before robots had names; {"id", "name"} since.
    robot: str | RobotEntry | None = None
    # The group's session number; the kasparctl that opened it; the learner frozen at the
    # start (profile and parameters); every setting that shaped the session.
    number: int | None = None
    kasparctl_version: str | None = None
    learner: dict[str, Any] | None = None
    settings: dict[str, Any] | None = None
    created: str = ""
    # Its place among its state directory's sessions; 0 before sessions were numbered.
    sequence: int = 0
    group: str | None = None
    condition: str | None = None
    variant: str = ""
    seed: int | None = None
    plan: PlanEntry | None = None
    # The uncertainty script Kaspar spoke; sessions from before scripts spoke "varied".
    script: str = "varied"
    script_version: int = 0
    # The language Kaspar spoke; sessions from before it was recorded spoke English.
    language: str = "en"


@dataclass(frozen=True)
class Damaged:
    """A session directory that cannot be read, and why (one line)."""

    directory: Path
    reason: str


@dataclass
class SessionIndex:
    """What one pass over a session's records found: enough to list, export and report it."""

    records: int = 0
    trial_records: int = 0
    undone: set[int] = field(default_factory=set)
    last_step: str | None = None
    resumed: int = 0
    toys: tuple[str, ...] = ()
    # The most children seen in a turn (child_index + 1), for plans that do not say.
    children_seen: int = 0
    # Trials whose per-toy lists are not as long as the session's toys (damage).
    other_width: int = 0
    # A group marked absent (never opened): True while the mark stands, False once taken
    # back; None for every session that was opened.
    absent: bool | None = None
    warnings: list[str] = field(default_factory=list)
    # Whether the wall clock was synchronised at every clock record (game.wallclock);
    # None for a session without one (older, or the demo's simulated clock).
    clock_synchronised: bool | None = None

    @property
    def trials(self) -> int:
        """The trials that count: an answer taken back with undo is not one."""
        return self.trial_records - len(self.undone)


@dataclass(frozen=True)
class SessionData:
    """One readable session: its directory, plan and index; its records streamed on demand."""

    directory: Path
    meta: PlanFile
    index: SessionIndex
    # Unique across robots and state directories: plan.json's uid, or one derived from it.
    uid: str

    @property
    def name(self) -> str:
        """The readable id: its start time (UTC) and group code, its directory's name."""
        return self.meta.session or self.directory.name

    @property
    def id(self) -> str:
        """The session's id in every table: its uid."""
        return self.uid

    @property
    def robot(self) -> str:
        """The robot that recorded it (its stable id); empty for sessions older than ids."""
        robot = self.meta.robot
        if isinstance(robot, RobotEntry):
            return robot.id or ""
        return robot or ""

    @property
    def robot_name(self) -> str | None:
        """The robot's name ([robot] name); None for sessions older than robot names."""
        robot = self.meta.robot
        return robot.name if isinstance(robot, RobotEntry) else None

    @property
    def number(self) -> int | None:
        """The group's session number (1 for its first); None before sessions had one."""
        return self.meta.number

    @property
    def kasparctl_version(self) -> str | None:
        """The kasparctl that opened the session; None before it was recorded."""
        return self.meta.kasparctl_version

    @property
    def settings(self) -> dict[str, Any] | None:
        """Every setting that shaped the session (plan.json's `settings`), if recorded."""
        return self.meta.settings

    @property
    def learner(self) -> dict[str, Any] | None:
        """The learner frozen in plan.json at the start: `learner`, else `settings.learner`."""
        if self.meta.learner is not None:
            return self.meta.learner
        settings = self.meta.settings or {}
        learner = settings.get("learner")
        return learner if isinstance(learner, dict) else None

    def learner_params(self) -> LearnerParams | None:
        """The parameters the session's learner really had, from plan.json; None when the
        session recorded none (or ones the learner refuses: damage), so the caller falls
        back to the profile of the configuration."""
        frozen = self.learner
        if frozen is None:
            return None
        names = {f.name for f in dataclasses.fields(LearnerParams)}
        values = {k: v for k, v in frozen.items() if k in names}
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in values.values()):
            return None
        try:
            return LearnerParams(**{k: float(v) for k, v in values.items()})
        except (LearnerError, TypeError):
            return None

    @property
    def plan(self) -> PlanEntry:
        """The session's plan entry as the robot used it."""
        return self.meta.plan or PlanEntry()

    @property
    def group(self) -> str:
        """The group's code."""
        return self.meta.group if self.meta.group is not None else self.plan.group

    @property
    def profile(self) -> str:
        """The learner profile's name."""
        return self.plan.profile

    @property
    def uncertainty(self) -> str:
        """How Kaspar showed how sure it was: spoken, body, both or none (sessions from
        before the modes: speak_uncertainty true is spoken, false none)."""
        plan = self.plan
        if plan.uncertainty is not None:
            return plan.uncertainty
        return "none" if plan.speak_uncertainty is False else "spoken"

    @property
    def speak_uncertainty(self) -> bool:
        """Whether Kaspar said how sure it was."""
        return self.uncertainty in SPOKEN_MODES

    @property
    def condition(self) -> str:
        """profile/spoken, profile/body, profile/both or profile/silent."""
        word = CONDITION_LABELS.get(self.uncertainty, self.uncertainty)
        return self.meta.condition or f"{self.profile}/{word}"

    @property
    def variant(self) -> str:
        """The game variant: "names" or "pilot"."""
        return self.meta.variant

    @property
    def script(self) -> tuple[str, int]:
        """The uncertainty script and its version; ("varied", 0) for a session planned
        before scripts existed (the five bands, with the words of then)."""
        return self.meta.script, self.meta.script_version

    @property
    def language(self) -> str:
        """The language Kaspar spoke; "en" for a session planned before it was recorded."""
        return self.meta.language

    @property
    def identity(self) -> dict[str, object]:
        """The columns that name a session and its condition, first in every table of it."""
        return {
            "session": self.uid,
            "session_name": self.name,
            "robot": self.robot,
            "robot_name": self.robot_name,
            "group": self.group,
            "session_number": self.number,
            "condition": self.condition,
            "profile": self.profile,
            "speak_uncertainty": self.speak_uncertainty,
            "uncertainty": self.uncertainty,
            "variant": self.variant,
            "language": self.language,
        }

    @property
    def created(self) -> str:
        """When the session was opened, UTC ISO 8601."""
        return self.meta.created

    @property
    def date(self) -> str:
        """The day the session was opened, YYYY-MM-DD."""
        return self.created[:10]

    @property
    def children(self) -> tuple[str, ...]:
        """The first names in the plan, if any."""
        return self.plan.children

    @property
    def participants(self) -> tuple[str, ...]:
        """The children's pseudonymous codes in turn order, if the plan has them."""
        return self.plan.participants

    @property
    def group_size(self) -> int:
        """How many children took turns: the plan's names or codes or size, else as seen."""
        plan = self.plan
        return (
            len(plan.children)
            or len(plan.participants)
            or plan.group_size
            or self.index.children_seen
            or 1
        )

    def participant(self, child_index: int) -> str | None:
        """The code of the child at this place in the turn order, if the plan has codes."""
        codes = self.participants
        return codes[child_index] if 0 <= child_index < len(codes) else None

    def child_label(self, child_index: int) -> str:
        """The child's first name from the plan, else "child 1", "child 2"... (the words
        Kaspar says for a child without a name are in the trial records)."""
        if 0 <= child_index < len(self.children):
            return self.children[child_index]
        return f"child {child_index + 1}"

    @property
    def answer_key(self) -> tuple[str, ...]:
        """The right toy of each target, if the plan has a usable key (toys it offered)."""
        key = self.plan.answer_key
        return key if set(key) <= set(self.toys) else ()

    @property
    def toys(self) -> tuple[str, ...]:
        """The game's toys in the order of the per-toy lists (probabilities, Q rows)."""
        return self.index.toys

    @property
    def undone(self) -> frozenset[int]:
        """The numbers of the trials whose answers the researcher took back."""
        return frozenset(self.index.undone)

    @property
    def warnings(self) -> list[str]:
        """Lines of records.jsonl that were not whole records, one message each."""
        return self.index.warnings

    @property
    def status(self) -> str:
        """ "finished", "stopped" (the researcher's stop) or "interrupted" (never ended); a
        group marked absent in idle (never opened) "absent", or "absent, taken back"."""
        if self.index.absent is not None:
            return "absent" if self.index.absent else "absent, taken back"
        step = self.index.last_step
        return step if step in ("finished", "stopped") else "interrupted"

    @property
    def resumed(self) -> int:
        """How many times the robot carried this session on after a crash or restart."""
        return self.index.resumed

    @property
    def recovered(self) -> str | None:
        """What a crash cost the session, found when it was resumed or read: a torn last
        record (never fsynced, so never reacted to), kept aside; None when nothing."""
        torn = self.directory / f"{RECORDS_FILE}{TORN_SUFFIX}"
        try:
            size = torn.stat().st_size
        except OSError:
            size = 0
        pending = [w for w in self.index.warnings if "the last line was torn" in w]
        if size:
            return (
                f"a crash tore its last record ({size} bytes, never fsynced: "
                f"kept in {torn.name}); nothing saved was lost"
            )
        if pending:
            return "a crash tore its last record (never fsynced); repaired when it resumes"
        return None

    def first_names(self) -> dict[str, str]:
        """Each first name in the plan and the pseudonym that replaces it ("child 2")."""
        return {name: f"child {index + 1}" for index, name in enumerate(self.children) if name}

    def records(self) -> Iterator[AnyRecord]:
        """Every record, streamed from disk (lines that are none were reported by the index)."""
        return iter_records(self.directory / RECORDS_FILE, lambda _warning: None)

    def all_trials(self) -> Iterator[TrialRecord]:
        """Every trial record, undone ones included, in the order they were recorded."""
        return (r for r in self.records() if isinstance(r, TrialRecord))

    def trials(self) -> Iterator[TrialRecord]:
        """The trials that count: an answer taken back with undo is not one."""
        undone = self.index.undone
        return (t for t in self.all_trials() if t.trial not in undone)


def read_plan(directory: Path) -> PlanFile:
    """plan.json of a session directory; CatalogueError (one line, the file and why) if unusable."""
    path = directory / PLAN_FILE
    try:
        with path.open("rb") as stream:
            data = stream.read(MAX_PLAN_BYTES + 1)
    except FileNotFoundError:
        raise CatalogueError(f"{path}: no plan (not a session, or one never started)") from None
    except PermissionError:
        raise CatalogueError(f"{path}: permission denied") from None
    except OSError as error:
        raise CatalogueError(f"{path}: cannot read it: {error.strerror or error}") from None
    if len(data) > MAX_PLAN_BYTES:
        raise CatalogueError(f"{path}: larger than {MAX_PLAN_BYTES} bytes, not a plan")
    if not data.strip():
        raise CatalogueError(f"{path}: empty (expected the session's plan as a JSON object)")
    try:
        return msgspec.json.decode(data, type=PlanFile)
    except msgspec.ValidationError as error:
        raise CatalogueError(f"{path}: {_validation_message(str(error))}") from None
    except msgspec.DecodeError as error:
        if not is_utf8(data):
            raise CatalogueError(f"{path}: not UTF-8 text") from None
        raise CatalogueError(f"{path}: not JSON ({error})") from None
    except UnicodeDecodeError:
        raise CatalogueError(f"{path}: not UTF-8 text") from None
    except RecursionError:
        raise CatalogueError(f"{path}: nested too deeply to be a plan") from None


def _validation_message(text: str) -> str:
    """msgspec's "Expected `int`, got `str` - at `$.seed`" as "$.seed: expected int, found str"."""
    message, _, where = text.rpartition(" - at ")
    if not message:
        message, where = text, ""
    got = re.fullmatch(r"Expected `(.+)`, got `(.+)`", message)
    if got:
        message = f"expected {got.group(1)}, found {got.group(2)}"
    where = where.strip("`")
    return f"{where}: {message}" if where else message


def derived_uid(plan_bytes: bytes, created: str) -> str:
    """A stable ULID-shaped id for a session older than uids: its time, then a hash of its plan.

    plan.json is written once, so the same session gets the same id on every
    computer and every run.
    """
    import datetime as dt

    try:
        when = dt.datetime.fromisoformat(created)
        milliseconds = int(when.timestamp() * 1000) & ((1 << 48) - 1)
    except (ValueError, OverflowError, OSError):
        milliseconds = 0
    digest = int.from_bytes(hashlib.sha256(b"kaspar session\0" + plan_bytes).digest()[:10], "big")
    value = (milliseconds << 80) | digest
    return "".join(_CROCKFORD[(value >> shift) & 31] for shift in range(125, -1, -5))


def session_uid(directory: Path, meta: PlanFile) -> str:
    """The session's uid: plan.json's, or one derived from plan.json's bytes."""
    if meta.uid is not None and ULID.fullmatch(meta.uid):
        return meta.uid
    try:
        plan_bytes = (directory / PLAN_FILE).read_bytes()[:MAX_PLAN_BYTES]
    except OSError:
        plan_bytes = str(directory).encode()
    return derived_uid(plan_bytes, meta.created)


def index_session(directory: Path) -> SessionIndex:
    """One streaming pass over a session's records: status, trials, undos, toys, warnings.

    OSError (permission, a disk error) propagates for the caller to name.
    """
    path = directory / RECORDS_FILE
    warnings = Warnings(path)
    index = SessionIndex()
    width = 0
    toys: tuple[str, ...] = ()
    chosen: dict[int, str] = {}
    widths: dict[int, int] = {}  # per-toy list length -> trials
    for record in iter_records(path, warnings.add):
        index.records += 1
        if isinstance(record, TrialRecord):
            width_here = len(record.probabilities)
            widths[width_here] = widths.get(width_here, 0) + 1
            index.trial_records += 1
            index.children_seen = max(index.children_seen, record.child_index + 1)
            width = max(width, len(record.probabilities))
            # A guess over every toy lists them all, in the per-toy lists' order; the
            # first guess of a problem is such a guess in both variants.
            if (
                not toys
                and record.candidates
                and len(record.candidates) == len(record.probabilities)
            ):
                toys = tuple(record.candidates)
            if not toys and 0 <= record.choice_index < 64:
                chosen.setdefault(record.choice_index, record.choice)
        elif isinstance(record, UndoRecord):
            index.undone.add(record.trial)
        elif isinstance(record, StepRecord):
            index.last_step = record.to
        elif isinstance(record, SessionRecord) and record.event is SessionEvent.RESUMED:
            index.resumed += 1
        elif isinstance(record, SessionRecord) and record.event in (
            SessionEvent.ABSENT,
            SessionEvent.PRESENT,
        ):
            index.absent = record.event is SessionEvent.ABSENT
        elif isinstance(record, ClockRecord):
            index.clock_synchronised = record.synchronised and index.clock_synchronised is not False
    if not toys:
        # Failing a full guess, positions are named from the choices.
        toys = tuple(chosen.get(i, f"toy {i + 1}") for i in range(width))
    index.toys = toys
    index.other_width = sum(n for w, n in widths.items() if w != len(toys))
    if index.other_width:
        warnings.add(
            f"{path}: {index.other_width} trials have per-toy lists of another length than "
            f"the session's {len(toys)} toys; the report leaves them out"
        )
    index.warnings = warnings.lines()
    return index


def open_session(directory: Path) -> SessionData | Damaged:
    """A session directory read (plan, then one pass over its records), or why it cannot be."""
    try:
        meta = read_plan(directory)
    except CatalogueError as error:
        return Damaged(directory, str(error))
    try:
        index = index_session(directory)
    except PermissionError:
        return Damaged(directory, f"{directory / RECORDS_FILE}: permission denied")
    except OSError as error:
        return Damaged(
            directory, f"{directory / RECORDS_FILE}: cannot read it: {error.strerror or error}"
        )
    return SessionData(directory, meta, index, session_uid(directory, meta))


def load_session(directory: Path) -> SessionData:
    """A session directory read back; CatalogueError if it is damaged beyond reading."""
    opened = open_session(directory)
    if isinstance(opened, Damaged):
        raise CatalogueError(opened.reason)
    return opened


def session_dirs(state_dir: Path) -> list[Path]:
    """Every session directory of a state directory, by name (their start time).

    A directory without a plan.json is listed too (it is a damaged session, and
    says why), but not what a crash left of a session being made (never started:
    game.session.never_started); CatalogueError when the state directory cannot be listed.
    """
    sessions = state_dir / "sessions"
    try:
        if not sessions.is_dir():
            return []
        return sorted(
            p
            for p in sessions.iterdir()
            if p.is_dir() and not p.name.startswith(".") and not never_started(p)
        )
    except PermissionError:
        raise CatalogueError(
            f"{sessions}: permission denied (the state directory is private to the robot's "
            "service user: run as that user, or with sudo)"
        ) from None
    except OSError as error:
        raise CatalogueError(f"{sessions}: cannot list it: {error.strerror or error}") from None


def find_sessions(state_dirs: Sequence[Path], names: Sequence[str]) -> list[Path]:
    """Session directories: every one in the state directories, or the named ones.

    A name is a session directory's path, its readable id (a directory name under
    <state_dir>/sessions) or its uid; a readable id found in several state
    directories is ambiguous, and the error says to give the uid or the path.
    """
    if not names:
        if not state_dirs:
            raise CatalogueError("no state directory to list sessions from")
        return [directory for state_dir in state_dirs for directory in session_dirs(state_dir)]
    found: list[Path] = []
    uids: dict[str, list[Path]] | None = None
    for name in names:
        path = Path(name)
        if (path / PLAN_FILE).is_file():
            found.append(path)
            continue
        matches = [
            state_dir / "sessions" / name
            for state_dir in state_dirs
            if "/" not in name and (state_dir / "sessions" / name / PLAN_FILE).is_file()
        ]
        if not matches and ULID.fullmatch(name):
            if uids is None:
                uids = _uids(state_dirs)
            matches = uids.get(name, [])
        if len(matches) > 1:
            raise CatalogueError(
                f"session {name!r} is in {len(matches)} state directories "
                f"({', '.join(str(m) for m in matches)}): give its uid or its directory"
            )
        if not matches:
            where = ", ".join(str(d / "sessions") for d in state_dirs)
            raise CatalogueError(
                f"no session {name!r}{f' in {where}' if where else ''} (`kasparctl sessions` "
                "lists them; a session directory's path works too)"
            )
        found.extend(matches)
    return found


def _uids(state_dirs: Sequence[Path]) -> dict[str, list[Path]]:
    """Every readable session's uid, and where it is."""
    by_uid: dict[str, list[Path]] = {}
    for state_dir in state_dirs:
        for directory in session_dirs(state_dir):
            try:
                meta = read_plan(directory)
            except CatalogueError:
                continue
            by_uid.setdefault(session_uid(directory, meta), []).append(directory)
    return by_uid


@dataclass
class Catalogue:
    """The sessions a command works on, oldest first, and those it could not read."""

    sessions: list[SessionData] = field(default_factory=list)
    damaged: list[Damaged] = field(default_factory=list)
    # The same session found twice (copied into two state directories): counted once.
    duplicates: list[str] = field(default_factory=list)


def open_sessions(directories: Iterable[Path]) -> Catalogue:
    """Each directory opened; duplicates (one uid twice) kept once, sessions oldest first."""
    catalogue = Catalogue()
    seen: dict[str, Path] = {}
    for directory in directories:
        opened = open_session(directory)
        if isinstance(opened, Damaged):
            catalogue.damaged.append(opened)
            continue
        if opened.uid in seen:
            catalogue.duplicates.append(
                f"{directory}: the same session as {seen[opened.uid]} (uid {opened.uid}); "
                "counted once"
            )
            continue
        seen[opened.uid] = directory
        catalogue.sessions.append(opened)
    # Each state directory's in the order they began: its sequence number (the wall clock
    # may have been wrong), then the readable id (its UTC start time), then the uid.
    catalogue.sessions.sort(
        key=lambda s: (str(s.directory.parent), s.meta.sequence, s.name, s.created, s.uid)
    )
    return catalogue
