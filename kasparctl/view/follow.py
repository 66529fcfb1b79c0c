"""Following a state directory: which session is live, and its files read when they change.

inotify watches the state directory (the daemon's events.jsonl, the sessions
folder), the sessions folder (a session starting) and each session's folder
(its records.jsonl growing, or cut back to its last whole line when a resumed
daemon repairs a torn one). A directory that does not exist yet is waited for
by watching the nearest one that does. The session followed is the one being
written: the last begun at the start (by the state directory's sequence number,
game.session.session_order, never by a file's time: the robot's wall clock may
be hours or years off), then whichever one a write lands in, so a new session
and a resumed older one are both followed without a rule of ours to guess which
the daemon picks. A session still being made (under its hidden building name)
is not one yet.

Read-only: files are read with the game's own readers (torn and damaged lines
are left out with a warning, never repaired from here), and a file is read
again only after an event says it changed.
"""

from __future__ import annotations

import errno
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.game.jsonl import read_json_lines, read_records
from kasparctl.game.lock import lock_holder
from kasparctl.game.opening import is_absence
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE, session_order
from kasparctl.view.fold import SessionFold, daemon_events
from kasparctl.view.inotify import (
    IN_CREATE,
    IN_DELETE,
    IN_DELETE_SELF,
    IN_IGNORED,
    IN_MODIFY,
    IN_MOVE_SELF,
    IN_MOVED_FROM,
    IN_MOVED_TO,
    IN_ONLYDIR,
    Event,
    Inotify,
)
from kasparctl.view.model import DaemonEvent, SessionView, WatchView

# The daemon's own log of events outside a session (faults at start-up among them).
EVENTS_FILE = "events.jsonl"
SESSIONS = "sessions"

# Entries coming, going or being written; a directory's own removal or move.
_DIR_MASK = (
    IN_CREATE
    | IN_MOVED_TO
    | IN_MODIFY
    | IN_DELETE
    | IN_MOVED_FROM
    | IN_DELETE_SELF
    | IN_MOVE_SELF
    | IN_ONLYDIR
)
# Waiting for the state directory: only entries appearing matter.
_WAIT_MASK = IN_CREATE | IN_MOVED_TO | IN_DELETE_SELF | IN_MOVE_SELF | IN_ONLYDIR
_SESSION_FILES = (RECORDS_FILE, PLAN_FILE)


def read_plan(directory: Path) -> dict[str, Any] | None:
    """A session's plan.json as plain data; None when it cannot be read (yet)."""
    try:
        plan = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
    except (OSError, msgspec.DecodeError):
        return None
    return plan if isinstance(plan, dict) else None


def read_session(directory: Path) -> SessionView:
    """The view of one session directory as it is on disk now."""
    return SessionReader(directory).read()


class SessionReader:
    """One session's view, read again after each change and folded on from where it was.

    The records are read whole each time (by the game's reader), but folded only from
    the first new one while the ones folded before are still there, as they are in an
    append-only log; anything else (a different plan, a shorter log) folds them again.
    """

    def __init__(self, directory: Path) -> None:
        """Read the session in `directory`."""
        self.directory = directory
        self._plan: dict[str, Any] | None = None
        self._fold = SessionFold(None)
        self._folded: list[tuple[int, str]] = []  # (seq, time) of each record folded

    def read(self) -> SessionView:
        """The view as of the files now."""
        plan = read_plan(self.directory)
        read = read_records(self.directory / RECORDS_FILE)
        done = len(self._folded)
        keys = [(record.seq, record.time) for record in read.records[:done]]
        if plan != self._plan or keys != self._folded[: len(keys)] or len(keys) < done:
            self._plan, self._fold, self._folded, done = plan, SessionFold(plan), [], 0
        for record in read.records[done:]:
            self._fold.apply(record)
            self._folded.append((record.seq, record.time))
        view = replace(self._fold.view, warnings=tuple(read.warnings))
        # A plan not yet readable still has its directory's name.
        return view if view.session else replace(view, session=self.directory.name)


def writer_pid(state_dir: Path) -> int | None:
    """The process holding the state directory's writer lock, if the kernel lists one.

    Opens the directory read-only to name it to /proc/locks; takes no lock.
    """
    try:
        fd = os.open(state_dir, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        return lock_holder(fd)
    finally:
        os.close(fd)


@dataclass
class _Watches:
    """Watch descriptors both ways: the kernel names a watch, we name a path."""

    paths: dict[int, Path] = field(default_factory=dict)
    wds: dict[Path, int] = field(default_factory=dict)

    def add(self, wd: int, path: Path) -> None:
        old = self.wds.get(path)
        if old is not None and old != wd:
            self.paths.pop(old, None)
        self.paths[wd] = path
        self.wds[path] = wd

    def forget(self, wd: int) -> None:
        path = self.paths.pop(wd, None)
        if path is not None and self.wds.get(path) == wd:
            del self.wds[path]


class Follower:
    """A state directory followed through inotify; `observe` gives what to show."""

    def __init__(self, state_dir: Path, inotify: Inotify) -> None:
        """Follow `state_dir` (which may not exist yet) with the given inotify instance."""
        self.state_dir = state_dir
        self.sessions_dir = state_dir / SESSIONS
        self._inotify = inotify
        self._watches = _Watches()
        self.current: Path | None = None
        self._known: set[Path] = set()
        # Why a directory that is there could not be watched, e.g. permission denied.
        self.problems: list[str] = []
        self._unreadable = {"session": "", "daemon": ""}
        self._session_reader: SessionReader | None = None
        self._session: SessionView | None = None
        self._session_stale = True
        self._daemon: tuple[DaemonEvent, ...] = ()
        self._daemon_stale = True
        self.rescan()

    # -- watches ----------------------------------------------------------------

    def rescan(self) -> None:
        """Watch what exists from the state directory down; choose the session to follow.

        Each directory is watched before it is listed, so an entry made in between
        is reported rather than missed.
        """
        wanted: dict[Path, int] = {}
        self.problems = []
        if self._watch(self.state_dir, _DIR_MASK):
            wanted[self.state_dir] = _DIR_MASK
            if self._watch(self.sessions_dir, _DIR_MASK):
                wanted[self.sessions_dir] = _DIR_MASK
                # Every folder, plan.json or not: a session's plan is written after its folder.
                for directory in self._folders(self.sessions_dir):
                    if self._watch(directory, _DIR_MASK):
                        wanted[directory] = _DIR_MASK
        else:
            waiting = self._nearest_existing(self.state_dir)
            if waiting is not None and self._watch(waiting, _WAIT_MASK):
                wanted[waiting] = _WAIT_MASK
        for path, wd in list(self._watches.wds.items()):
            if path not in wanted:
                self._inotify.remove_watch(wd)
                self._watches.forget(wd)
        sessions = [path for path in wanted if path.parent == self.sessions_dir]
        new = [path for path in sessions if path not in self._known]
        self._known = set(sessions)
        if self.current not in self._known or (new and self.current is not None):
            # A group marked absent is no session to follow (kasparctl.game.opening).
            opened = [path for path in new or sessions if not is_absence(path)]
            if opened or self.current not in self._known:
                self.current = self._newest(opened or [p for p in sessions if not is_absence(p)])
        self._session_stale = self._daemon_stale = True

    def _watch(self, path: Path, mask: int) -> bool:
        try:
            wd = self._inotify.add_watch(path, mask)
        except OSError as error:
            # Not there (yet) is waited for; anything else (not ours to read, not a
            # directory, too many watches) is said on screen.
            if error.errno != errno.ENOENT:
                self.problems.append(str(error))
            return False
        self._watches.add(wd, path)
        return True

    @staticmethod
    def _folders(directory: Path) -> list[Path]:
        try:
            return sorted(
                path
                for path in directory.iterdir()
                if path.is_dir() and not path.name.startswith(".")
            )
        except OSError:
            return []

    @staticmethod
    def _nearest_existing(path: Path) -> Path | None:
        for parent in path.parents:
            if parent.is_dir():
                return parent
        return None

    @staticmethod
    def _newest(directories: list[Path]) -> Path | None:
        """The session begun last: the highest sequence number (then the latest name)."""
        return max(directories, key=session_order, default=None)

    # -- events -----------------------------------------------------------------

    def handle(self, events: list[Event]) -> bool:
        """Take what inotify reported; True when what the view shows may have changed."""
        changed = rescan = False
        for event in events:
            if event.overflow:
                rescan = True
                continue
            if event.mask & IN_IGNORED:
                # The kernel dropped the watch: its directory was deleted or moved.
                self._watches.forget(event.wd)
                rescan = True
                continue
            path = self._watches.paths.get(event.wd)
            if path is None:
                continue
            if event.mask & (IN_DELETE_SELF | IN_MOVE_SELF):
                rescan = True
            elif path == self.state_dir:
                if event.name == EVENTS_FILE:
                    self._daemon_stale = changed = True
                elif event.name == SESSIONS:
                    rescan = True
            elif path == self.sessions_dir:
                rescan = True
            elif path.parent == self.sessions_dir:
                if event.name in _SESSION_FILES:
                    # Follow the writer: the session written to is the live one.
                    if path != self.current:
                        self.current = path
                    self._session_stale = changed = True
            elif self._leads_to_state_dir(path, event.name):
                rescan = True
        if rescan:
            self.rescan()
            changed = True
        return changed

    def _leads_to_state_dir(self, path: Path, name: str) -> bool:
        """Whether `name` in the watched ancestor `path` is the next step to the state dir."""
        try:
            relative = self.state_dir.relative_to(path)
        except ValueError:
            return False
        return bool(relative.parts) and relative.parts[0] == name

    # -- what to show -----------------------------------------------------------

    def _reader(self, directory: Path) -> SessionReader:
        """The reader of the current session, kept while it stays current."""
        if self._session_reader is None or self._session_reader.directory != directory:
            self._session_reader = SessionReader(directory)
        return self._session_reader

    def observe(self, footer: str = "") -> WatchView:
        """The picture now, reading again only the files an event said changed."""
        exists = self.state_dir in self._watches.wds
        if self._session_stale:
            self._session, self._unreadable["session"] = None, ""
            try:
                current = self.current
                self._session = self._reader(current).read() if current is not None else None
            except OSError as error:
                self._unreadable["session"] = f"{error.filename}: cannot read: {error.strerror}"
            self._session_stale = False
        if self._daemon_stale:
            self._daemon, self._unreadable["daemon"] = (), ""
            try:
                if exists:
                    read = read_json_lines(self.state_dir / EVENTS_FILE)
                    self._daemon = daemon_events(read.records)
            except OSError as error:
                self._unreadable["daemon"] = f"{error.filename}: cannot read: {error.strerror}"
            self._daemon_stale = False
        unreadable = [problem for problem in self._unreadable.values() if problem]
        return WatchView(
            state_dir=str(self.state_dir),
            exists=exists,
            problem="; ".join([*self.problems, *unreadable]),
            session=self._session,
            sessions=len(self._known),
            daemon=self._daemon,
            writer=writer_pid(self.state_dir) if exists else None,
            footer=footer,
        )
