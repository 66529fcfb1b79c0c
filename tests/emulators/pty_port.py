"""A pseudo-terminal that stands in for a USB serial adapter, and can be unplugged."""

from __future__ import annotations

import contextlib
import os
import select
import tty
from pathlib import Path


class PtyPort:
    """The master side of a pty; `path` (a symlink) is what the driver opens.

    unplug() closes the master, so the driver's next read or write fails the
    way a pulled USB adapter does (EIO); plug() makes a fresh pty and points
    the symlink at it, as udev does when the adapter comes back.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.master: int | None = None
        self._slave: int | None = None
        self.plug()

    def plug(self) -> None:
        master, slave = os.openpty()
        # Raw mode on the shared termios: no echo, no line editing, no CR/LF mangling.
        tty.setraw(slave)
        tty.setraw(master)
        tmp = self.path.with_name(self.path.name + ".new")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(os.ttyname(slave))
        tmp.replace(self.path)
        self.master, self._slave = master, slave

    def unplug(self) -> None:
        for fd in (self.master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master = self._slave = None

    @property
    def plugged(self) -> bool:
        return self.master is not None

    def read_available(self, timeout: float) -> bytes:
        """Whatever the driver has written within `timeout` seconds (b"" if nothing)."""
        if self.master is None:
            return b""
        ready, _, _ = select.select([self.master], [], [], timeout)
        if not ready:
            return b""
        try:
            return os.read(self.master, 4096)
        except OSError:
            return b""

    def write(self, data: bytes) -> None:
        if self.master is not None:
            with contextlib.suppress(OSError):
                os.write(self.master, data)

    def close(self) -> None:
        self.unplug()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
