"""Whether an unfinished session is resumed or abandoned, and how it is reopened.

At start the daemon takes the most recent session that did not finish and
carries it on with the learner it began with (frozen in its plan.json) from
its snapshot and the records after it. A session whose files are readable but
make no session this configuration can carry on (damaged in the middle,
emptied, a learner profile gone, a game since changed) is abandoned: closed
for good with a "session" record and a snapshot that say why, so the next
session starts anew and nothing is removed. A disk that cannot be read is
StorageFailed instead: nothing is judged then, and nothing is lost.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import structlog

from kasparctl.config import (
    Config,
    ConfigError,
    GameSettings,
    ProfileSettings,
    SessionPlan,
    SessionSettings,
    recorded_game,
    recorded_session,
)
from kasparctl.game.jsonl import encode_record, line_seq, read_json_lines, read_records
from kasparctl.game.records import SessionEvent, SessionRecord
from kasparctl.game.session import (
    LEARNER_FIELDS,
    PLAN_FILE,
    RECORDS_FILE,
    STATE_FILE,
    RecordsLost,
    Session,
    is_finished,
    read_snapshot,
    session_dirs,
    stamp,
    write_abandoned_snapshot,
)
from kasparctl.game.stages import STATES
from kasparctl.game.state import GameState, StateError, restore
from kasparctl.game.storage import RecordLog, SessionError, storage_failed
from kasparctl.learning.learner import PLAIN_DATA_ERRORS, LearnerError, LearnerParams

log = structlog.get_logger(__name__)


def find_unfinished(state_dir: Path) -> Path | None:
    """The most recent session that did not finish, if any: it is resumed, not restarted."""
    unfinished = None
    for directory in session_dirs(state_dir):
        if not is_finished(directory):
            unfinished = directory
    return unfinished


@dataclass(frozen=True, slots=True)
class Resumable:
    """An unfinished session read back whole: its files, its plan and the state it reached."""

    session: Session
    plan: SessionPlan
    state: GameState
    # The learner the session began with (frozen in its plan), or its profile's.
    params: LearnerParams

    def settings(self, config: Config) -> SessionSettings:
        """What the session plays with: its plan.json's `settings` (a session recorded
        before them: `config`'s robot-wide values, as it had then)."""
        source = str(self.session.directory / PLAN_FILE)
        return recorded_session(self.session.plan, config, self.plan, self.params, source)

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
        raise storage_failed(plan_path, "cannot read the plan", error) from error
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
        # The game it was recorded with, whatever [game] says now.
        game = recorded_game(plan_json, game, str(plan_path))
    except ConfigError as error:
        raise CannotResume(directory, str(error)) from error
    try:
        session, _warnings = Session.open(directory)
    except SessionError as error:
        raise CannotResume(directory, str(error)) from error
    except OSError as error:
        path = directory / RECORDS_FILE
        raise storage_failed(path, "cannot read or repair the records", error) from error
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
        raise storage_failed(directory / RECORDS_FILE, "cannot read", error) from error
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
        seq = max((line_seq(plain) for plain in lines.records), default=0) + 1
        step = _last_step(lines.records)
        record = SessionRecord(event=SessionEvent.ABANDONED, reason=reason, state=step)
        records = RecordLog(records_path)
        try:
            records.append(encode_record(stamp(record, seq, clock)))
        finally:
            records.close()
    except OSError as error:
        raise storage_failed(records_path, "cannot mark the session abandoned", error) from error
    try:
        write_abandoned_snapshot(directory, seq, reason)
    except OSError as error:
        raise storage_failed(state_path, "cannot mark the session abandoned", error) from error
    log.error("session abandoned", session=directory.name, reason=reason)
    return seq


def _last_step(records: list[dict[str, Any]]) -> str:
    steps = [plain.get("to") for plain in records if plain.get("kind") == "step"]
    last = steps[-1] if steps else "idle"
    return last if isinstance(last, str) else "unknown"


def abandoned_reason(directory: Path) -> str | None:
    """Why a session was abandoned, from its snapshot; None for any other session."""
    snapshot = read_snapshot(directory)
    return snapshot.abandoned if snapshot is not None else None


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
            raise storage_failed(state_dir / "sessions", "cannot read", error) from error
        if directory is None or directory in tried:
            return ResumeOutcome(None, abandoned)
        tried.add(directory)
        try:
            return ResumeOutcome(reopen(directory, game, profile), abandoned)
        except CannotResume as cannot:
            abandon(directory, cannot.reason, clock)
            abandoned.append(Abandoned(directory.name, directory, cannot.reason))
