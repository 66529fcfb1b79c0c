"""Linux inotify through ctypes on libc: the kernel says when a watched directory changes.

Why not a library: the three calls and one struct are all the view needs, and
libc is on every robot; a dependency would be one more package to install on
it for about sixty lines (inotify_simple, the smallest, is itself these ctypes
calls). The descriptor is non-blocking, to be waited on with a selector next
to the keyboard: the view sleeps in the kernel until a record is written.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import struct
from dataclasses import dataclass
from pathlib import Path

from hal.errors import KasparError

# <sys/inotify.h>
IN_MODIFY = 0x00000002
IN_ATTRIB = 0x00000004
IN_CLOSE_WRITE = 0x00000008
IN_MOVED_FROM = 0x00000040
IN_MOVED_TO = 0x00000080
IN_CREATE = 0x00000100
IN_DELETE = 0x00000200
IN_DELETE_SELF = 0x00000400
IN_MOVE_SELF = 0x00000800
IN_UNMOUNT = 0x00002000
IN_Q_OVERFLOW = 0x00004000
IN_IGNORED = 0x00008000
IN_ONLYDIR = 0x01000000
IN_ISDIR = 0x40000000
IN_NONBLOCK = os.O_NONBLOCK
IN_CLOEXEC = os.O_CLOEXEC

_EVENT = struct.Struct("iIII")  # wd, mask, cookie, len; then len bytes of name
_READ_SIZE = 64 * 1024


class InotifyError(KasparError, OSError):
    """inotify is not available, or a watch could not be added; names the path."""


def _error(code: int, message: str) -> InotifyError:
    """An InotifyError whose text is `message` alone, with its errno kept for callers."""
    error = InotifyError(message)
    error.errno = code
    return error


@dataclass(frozen=True, slots=True)
class Event:
    """One inotify event: the watch it came from, what happened, and the entry's name."""

    wd: int
    mask: int
    name: str

    @property
    def overflow(self) -> bool:
        """The kernel's queue overflowed: events were lost, so everything must be read again."""
        return bool(self.mask & IN_Q_OVERFLOW)


def _libc() -> ctypes.CDLL:
    name = ctypes.util.find_library("c") or "libc.so.6"
    libc = ctypes.CDLL(name, use_errno=True)
    libc.inotify_init1.argtypes = [ctypes.c_int]
    libc.inotify_init1.restype = ctypes.c_int
    libc.inotify_add_watch.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_uint32]
    libc.inotify_add_watch.restype = ctypes.c_int
    libc.inotify_rm_watch.argtypes = [ctypes.c_int, ctypes.c_int]
    libc.inotify_rm_watch.restype = ctypes.c_int
    return libc


def parse_events(data: bytes) -> list[Event]:
    """The events packed in one read of an inotify descriptor."""
    events = []
    offset = 0
    while offset + _EVENT.size <= len(data):
        wd, mask, _cookie, length = _EVENT.unpack_from(data, offset)
        offset += _EVENT.size
        raw = data[offset : offset + length]
        offset += length
        events.append(Event(wd, mask, os.fsdecode(raw.rstrip(b"\0"))))
    return events


class Inotify:
    """One inotify instance: add watches, read what happened. Close it when done."""

    def __init__(self) -> None:
        """Open a non-blocking, close-on-exec inotify descriptor."""
        try:
            self._libc = _libc()
        except OSError as error:
            raise InotifyError(f"inotify: libc cannot be loaded: {error}") from error
        fd = int(self._libc.inotify_init1(IN_NONBLOCK | IN_CLOEXEC))
        if fd < 0:
            code = ctypes.get_errno()
            raise _error(code, f"inotify_init1: {os.strerror(code)}")
        self._fd = fd

    def fileno(self) -> int:
        """The descriptor, readable when events are waiting."""
        return self._fd

    def add_watch(self, path: Path, mask: int) -> int:
        """Watch `path` for `mask`; the watch descriptor (the same one if already watched).

        InotifyError names the path when it fails (gone, not permitted, too many watches).
        """
        wd = int(self._libc.inotify_add_watch(self._fd, os.fsencode(path), mask))
        if wd < 0:
            code = ctypes.get_errno()
            raise _error(code, f"{path}: cannot watch: {os.strerror(code)}")
        return wd

    def remove_watch(self, wd: int) -> None:
        """Stop watching; a watch the kernel already dropped (its path deleted) is no error."""
        if self._libc.inotify_rm_watch(self._fd, wd) < 0:
            code = ctypes.get_errno()
            if code != errno.EINVAL:
                raise _error(code, f"inotify_rm_watch: {os.strerror(code)}")

    def read(self) -> list[Event]:
        """Every event waiting now; an empty list when there is none."""
        events: list[Event] = []
        while True:
            try:
                data = os.read(self._fd, _READ_SIZE)
            except BlockingIOError:
                return events
            if not data:
                return events
            events.extend(parse_events(data))

    def close(self) -> None:
        """Close the descriptor (dropping every watch)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def __enter__(self) -> Inotify:
        """Use in a with-block."""
        return self

    def __exit__(self, *_: object) -> None:
        """Close at the end of the with-block."""
        self.close()
