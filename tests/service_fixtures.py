"""The service as systemd runs it, for the tests: its command line and the notify socket."""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEMO_CONFIG = REPO / "kasparctl" / "sim" / "demo.toml"


def run_command(state_dir: Path) -> list[str]:
    """The service on the demo robot's simulated hardware, keeping its sessions in state_dir."""
    return [
        sys.executable,
        "-m",
        "kasparctl",
        "run",
        "--sim",
        "--config",
        str(DEMO_CONFIG),
        "--state-dir",
        str(state_dir),
    ]


class NotifyListener:
    """The systemd end of NOTIFY_SOCKET: collects datagrams, waits for a field."""

    def __init__(self, path: Path) -> None:
        self.socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.socket.bind(str(path))
        self.messages: list[tuple[float, str]] = []

    def collect(self, seconds: float) -> list[tuple[float, str]]:
        end = time.monotonic() + seconds
        got = []
        while (left := end - time.monotonic()) > 0:
            self.socket.settimeout(left)
            try:
                data = self.socket.recv(4096)
            except TimeoutError:
                break
            got.append((time.monotonic(), data.decode()))
        self.messages += got
        return got

    def wait_for(self, field: str, seconds: float = 30.0) -> float:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for at, message in self.collect(min(0.5, end - time.monotonic())):
                if field in message.split("\n"):
                    return at
        raise AssertionError(f"{field} never arrived; got {[m for _, m in self.messages][-10:]}")


@contextlib.contextmanager
def running_service(
    directory: Path, environment: dict[str, str] | None = None
) -> Iterator[tuple[subprocess.Popen[str], NotifyListener]]:
    """The service started as systemd would (NOTIFY_SOCKET, sessions in directory/state);
    killed at the end if it is still running, its notify socket closed."""
    listener = NotifyListener(directory / "notify.sock")
    env = os.environ | {"NOTIFY_SOCKET": str(directory / "notify.sock")}
    for name in ("WATCHDOG_USEC", "WATCHDOG_PID", "LISTEN_FDS", "LISTEN_PID"):
        env.pop(name, None)
    env |= environment or {}
    process = subprocess.Popen(
        run_command(directory / "state"),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        yield process, listener
    finally:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=30)
        listener.socket.close()
