"""systemd's notify protocol: a few datagrams to $NOTIFY_SOCKET, no dependency.

Outside systemd (no NOTIFY_SOCKET) every call does nothing, so the daemon runs
the same from a terminal. Abstract socket names ("@...") are supported.
"""

from __future__ import annotations

import os
import socket


class Notifier:
    """Tells systemd how the service is (READY, STATUS, WATCHDOG, STOPPING); silent outside it."""
    def __init__(self, address: str | None = None) -> None:
        """Talk to `address`, or to $NOTIFY_SOCKET when None."""
        address = os.environ.get("NOTIFY_SOCKET") if address is None else address
        self._address: str | None = None
        self._socket: socket.socket | None = None
        if address:
            # A leading "@" names a Linux abstract socket: a NUL byte on the wire.
            self._address = "\0" + address[1:] if address.startswith("@") else address
            self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            # Never wait on the event loop: a full queue (systemd busy) loses one status,
            # where a blocking send would hold every gesture and the stop itself.
            self._socket.setblocking(False)

    @property
    def enabled(self) -> bool:
        """Whether there is a systemd to tell."""
        return self._socket is not None

    def notify(self, *fields: str) -> bool:
        """Send "KEY=value" fields in one datagram; False if systemd could not be told."""
        if self._socket is None or self._address is None:
            return False
        try:
            self._socket.sendto("\n".join(fields).encode(), self._address)
        except OSError:
            return False
        return True

    def ready(self, status: str) -> bool:
        """The service is up: READY=1 with the status in words."""
        return self.notify("READY=1", f"STATUS={status}")

    def status(self, status: str) -> bool:
        """The status in words, as `systemctl status` shows it."""
        return self.notify(f"STATUS={status}")

    def watchdog(self) -> bool:
        """A watchdog ping: the service is alive."""
        return self.notify("WATCHDOG=1")

    def stopping(self, status: str) -> bool:
        """The service is stopping, with why."""
        return self.notify("STOPPING=1", f"STATUS={status}")

    def close(self) -> None:
        """Close the socket; later calls do nothing."""
        if self._socket is not None:
            self._socket.close()
            self._socket = None


def watchdog_interval() -> float | None:
    """Half of systemd's WatchdogSec for this process, or None when there is no watchdog."""
    usec = os.environ.get("WATCHDOG_USEC")
    pid = os.environ.get("WATCHDOG_PID")
    if not usec or (pid and pid != str(os.getpid())):
        return None
    try:
        return int(usec) / 2_000_000
    except ValueError:
        return None
