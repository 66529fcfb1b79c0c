"""Durable files of the state directory: the one place they are written, synced and renamed.

Every write of a session's files and of the daemon's event log goes through
this module: a file replaced atomically (write_atomic), bytes appended and
fsynced (append_durably, RecordLog), a file cut back (truncate), a private
directory made (make_directory), a file renamed (rename), a directory's entries
made durable (fsync_directory), a half-made session removed (remove_tree).

Under POSIX a new name (a directory made, a file created, a rename) survives a
power cut only once its directory is fsynced, and a file's bytes only once the
file is: so every function here returns with both durable, the entry of each
directory it makes or fills included. Every change goes through this module's
`os`, so a test can record the operations and explore the states a crash may
leave (tests/crash_states.py).
What goes into the files is kasparctl.game.jsonl's and kasparctl.game.session's;
an OSError here becomes StorageFailed there, naming the file and the reason.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Callable
from pathlib import Path

import structlog

from hal.errors import KasparError

log = structlog.get_logger(__name__)

PRIVATE_FILE = 0o600
PRIVATE_DIR = 0o700


class SessionError(KasparError):
    """A session directory that cannot be written or read back, with the path."""


class StorageFailed(SessionError):
    """A record, snapshot or session directory could not be written (the disk full, the
    state directory unwritable); the message names the file and the system's reason."""

    def __init__(self, message: str, path: Path, *, in_event_log: bool = False) -> None:
        """`message` says what failed and why; `path` is what could not be written;
        `in_event_log` whether it was the daemon's event log (not a session's files)."""
        super().__init__(message)
        self.path = path
        self.in_event_log = in_event_log


def storage_failed(
    path: Path, failed: str, error: OSError, *, in_event_log: bool = False
) -> StorageFailed:
    """StorageFailed saying `PATH: FAILED: REASON`, the reason being the system's."""
    reason = error.strerror or str(error)
    return StorageFailed(f"{path}: {failed}: {reason}", path, in_event_log=in_event_log)


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
    fsync_directory(path.parent)


def append_durably(path: Path, data: bytes) -> None:
    """Append `data` to `path` (made private if new) and fsync it before returning;
    a file made here has its directory entry made durable too."""
    fd, created = _open_appending(path, os.O_WRONLY)
    try:
        _write_all(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)
    if created:
        fsync_directory(path.parent)


def create_empty(path: Path) -> None:
    """Make the empty private file `path` (kept if there), its entry durable."""
    fd, _created = _open_appending(path, os.O_WRONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    fsync_directory(path.parent)


def _open_appending(path: Path, access: int) -> tuple[int, bool]:
    """`path` opened for appending, made private if new; and whether it was made now."""
    try:
        return os.open(path, access | os.O_CREAT | os.O_EXCL | os.O_APPEND, PRIVATE_FILE), True
    except FileExistsError:
        return os.open(path, access | os.O_APPEND), False


def truncate(path: Path, size: int) -> None:
    """Cut the file at `path` back to its first `size` bytes, durably."""
    fd = os.open(path, os.O_WRONLY)
    try:
        os.ftruncate(fd, size)
        os.fsync(fd)
    finally:
        os.close(fd)


def rename(source: Path, target: Path) -> None:
    """Move `source` to `target`, replacing what was there; durable on return."""
    os.replace(source, target)
    fsync_directory(target.parent)
    if source.parent != target.parent:
        fsync_directory(source.parent)


def rename_new(source: Path, target: Path) -> None:
    """Move the directory `source` to `target`, which must not exist (FileExistsError, or
    OSError ENOTEMPTY); one rename, so a reader sees it whole or not at all."""
    if os.path.lexists(target):
        raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(target))
    os.rename(source, target)
    fsync_directory(target.parent)


def make_directory(path: Path, *, parents: bool = False, exist_ok: bool = False) -> None:
    """Make the private directory `path` (Path.mkdir's `parents` and `exist_ok`), its entry
    and those of any parent made durable: a directory found there is made durable too,
    since a crash may have come between its mkdir and its parent's fsync."""
    missing: list[Path] = []
    here = path
    while parents and not os.path.isdir(here.parent) and here.parent != here:
        here = here.parent
        missing.append(here)
    for directory in reversed(missing):
        _mkdir(directory, exist_ok=True)
    _mkdir(path, exist_ok=exist_ok)


def _mkdir(path: Path, *, exist_ok: bool) -> None:
    try:
        os.mkdir(path, PRIVATE_DIR)
    except FileExistsError:
        if not exist_ok or not os.path.isdir(path):
            raise
    fsync_directory(path.parent)


def remove_tree(directory: Path) -> None:
    """Remove `directory` and all it holds, as far as it can be; its removal made durable."""
    for root, folders, files in os.walk(directory, topdown=False):
        for name in files:
            with contextlib.suppress(OSError):
                os.unlink(os.path.join(root, name))
        for name in folders:
            with contextlib.suppress(OSError):
                os.rmdir(os.path.join(root, name))
    with contextlib.suppress(OSError):
        os.rmdir(directory)
    with contextlib.suppress(OSError):
        fsync_directory(directory.parent)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        written = os.write(fd, view)
        view = view[written:]


def fsync_directory(directory: Path) -> None:
    """Make the entries of `directory` durable."""
    # A rename or a new file is durable only once its directory entry is.
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


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
        self._fd, created = _open_appending(self.path, os.O_RDWR)
        if created:
            # The log's first record is durable only once the log's name is.
            fsync_directory(self.path.parent)

    def _make_directory(self) -> None:
        make_directory(self.path.parent, parents=True, exist_ok=True)

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
            fsync_directory(self.path.parent)
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

