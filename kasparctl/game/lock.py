"""One writer per state directory: an exclusive flock held for the writer's life.

`kasparctl run` and `kasparctl demo` write sessions; two of them on one state
directory would interleave their records (the same trial numbers twice in one
records.jsonl). The lock is taken on the directory itself, not on a file in it,
so it needs no write permission, leaves nothing behind, and is released by the
kernel when the process dies, SIGKILL included. Readers (sessions, export,
report, watch) take no lock: records are appended whole and fsynced, and
snapshots are replaced atomically, so a reader never sees a torn record.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from hal.errors import KasparError

PROC_LOCKS = Path("/proc/locks")


class StateDirBusy(KasparError):
    """Another process already writes to this state directory."""

    def __init__(self, directory: Path, holder: int | None) -> None:
        """Name the directory and, where the kernel tells, the PID that holds it."""
        who = f"process {holder}" if holder is not None else "another process"
        super().__init__(
            f"{directory}: the state directory is in use by {who} "
            "(a running kasparctl service or demo); stop it first, or use another --state-dir"
        )
        self.directory = directory
        self.holder = holder


class StateDirLock:
    """The exclusive writer's lock on a state directory, created if missing."""

    def __init__(self, directory: Path) -> None:
        """Prepare the lock; nothing is taken until `acquire`."""
        self.directory = directory
        self._fd = -1

    def acquire(self) -> None:
        """Take the lock at once or raise StateDirBusy naming the holder.

        Creates the directory (0700) if it does not exist; an OSError from that
        (permission, read-only file system) is raised as it is, for the caller
        to report.
        """
        self.directory.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd = os.open(self.directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = lock_holder(fd)
            os.close(fd)
            raise StateDirBusy(self.directory, holder) from None
        except BaseException:
            os.close(fd)
            raise
        self._fd = fd

    def release(self) -> None:
        """Let the next writer in (closing the descriptor drops the flock)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    @property
    def held(self) -> bool:
        """Whether this process holds the lock."""
        return self._fd >= 0

    def __enter__(self) -> StateDirLock:
        """Acquire for a with-block."""
        self.acquire()
        return self

    def __exit__(self, *_: object) -> None:
        """Release at the end of the with-block."""
        self.release()


def lock_holder(fd: int, locks: Path = PROC_LOCKS) -> int | None:
    """The PID holding a flock on the file behind `fd`, from /proc/locks, if listed.

    A line reads `1: FLOCK  ADVISORY  WRITE 4242 fd:01:1234 0 EOF`; the device
    is in hex major:minor and the inode in decimal.
    """
    status = os.fstat(fd)
    wanted = (os.major(status.st_dev), os.minor(status.st_dev), status.st_ino)
    try:
        text = locks.read_text()
    except OSError:
        return None
    for line in text.splitlines():
        fields = line.split()
        # A blocked waiter's line starts with "->" and has one more field.
        if fields and fields[0] == "->":
            continue
        if len(fields) < 6 or fields[1] != "FLOCK":
            continue
        try:
            major, minor, inode = fields[5].split(":")
            if (int(major, 16), int(minor, 16), int(inode)) == wanted:
                return int(fields[4])
        except ValueError:
            continue
    return None
