"""The service as systemd runs it, for the tests: its command line, the notify socket, its output.

Every wait here is for an event the service makes (a datagram, a line, a record on
disk) with a deadline that only bounds a failure; nothing waits a fixed time.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from kasparctl.game.session import RECORDS_FILE
from kasparctl.service.status import CLOCK_WORDS

REPO = Path(__file__).resolve().parents[1]
DEMO_CONFIG = REPO / "kasparctl" / "sim" / "demo.toml"
PHRASES = tomllib.loads((REPO / "phrases" / "en.toml").read_text(encoding="utf-8"))
DEADLINE_S = 30.0  # bounds a failure only: a healthy service is far quicker
POLL_S = 0.005  # how often a file on disk is looked at while waiting for a record


def run_command(
    state_dir: Path, config: Path = DEMO_CONFIG, sim: bool = True, extra: tuple[str, ...] = ()
) -> list[str]:
    """The service on the demo robot's simulated hardware (or as `config` says, without
    `sim`), keeping its sessions in state_dir."""
    return [
        sys.executable,
        "-m",
        "kasparctl",
        "run",
        *(["--sim"] if sim else []),
        "--config",
        str(config),
        "--state-dir",
        str(state_dir),
        *extra,
    ]


def _fields(message: str) -> list[str]:
    """A datagram's fields, STATUS= without its battery part (" | battery 13.2 V", last):
    the simulated battery falls with time, so an exact STATUS= is compared without it."""
    return [without_battery(field) if field.startswith("STATUS=") else field
            for field in message.split("\n")]


class NotifyListener:
    """The systemd end of NOTIFY_SOCKET: keeps every datagram, waits for a field."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.socket.bind(str(path))
        self.messages: list[tuple[float, str]] = []  # (monotonic time of receipt, datagram)

    def _receive(self, timeout: float) -> str | None:
        """One datagram, or None if none came within timeout (0: only one already queued)."""
        self.socket.settimeout(max(timeout, 0.0))  # 0: non-blocking
        try:
            data = self.socket.recv(4096)
        except (TimeoutError, BlockingIOError):
            return None
        message = data.decode()
        self.messages.append((time.monotonic(), message))
        return message

    def drain(self) -> list[str]:
        """The datagrams already queued, without waiting for more."""
        drained = []
        while (message := self._receive(0)) is not None:
            drained.append(message)
        return drained

    def collect(self, seconds: float) -> list[str]:
        """Every datagram arriving within `seconds`: for checking that something does NOT come."""
        end = time.monotonic() + seconds
        got = []
        while (left := end - time.monotonic()) > 0:
            if (message := self._receive(left)) is not None:
                got.append(message)
        return got

    def mark(self) -> int:
        """A place in the datagrams received so far, for `wait_for(..., since=)`."""
        return len(self.messages)

    def wait_for(self, field: str, seconds: float = DEADLINE_S, since: int | None = None) -> str:
        """The first datagram holding `field` (e.g. "READY=1"): among those received
        from mark `since` on, or if not given among those still to come."""
        for _, seen in self.messages[since if since is not None else len(self.messages) :]:
            if field in _fields(seen):
                return seen
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            message = self._receive(left)
            if message is not None and field in _fields(message):
                return message
        recent = [m for _, m in self.messages][-10:]
        raise AssertionError(f"{field} never arrived within {seconds} s; last: {recent}")

    def wait_for_status(
        self, wanted: Callable[[str], bool], seconds: float = DEADLINE_S, since: int = 0
    ) -> str:
        """The first STATUS= text (from mark `since` on) for which wanted(text) is true."""
        checked = since
        end = time.monotonic() + seconds
        while True:
            for _, seen in self.messages[checked:]:
                for field in seen.split("\n"):
                    if field.startswith("STATUS=") and wanted(field.removeprefix("STATUS=")):
                        return field.removeprefix("STATUS=")
            checked = len(self.messages)
            left = end - time.monotonic()
            if left <= 0:
                statuses = [m for _, m in self.messages if "STATUS=" in m][-5:]
                raise AssertionError(f"no such STATUS= within {seconds} s; last: {statuses}")
            self._receive(left)

    def close(self) -> None:
        """Closes the socket and removes its path, so the next run can bind it again."""
        self.socket.close()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()


class OutputLines:
    """A process's stream read line by line on a thread, as it comes: waits for a line."""

    def __init__(self, stream: IO[str]) -> None:
        self.lines: list[str] = []
        self._ended = False
        self._changed = threading.Condition()
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream: IO[str]) -> None:
        for line in stream:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._ended = True
            self._changed.notify_all()

    def wait_for(self, wanted: Callable[[str], bool], seconds: float = DEADLINE_S) -> str:
        """The first line (read so far or still to come) for which wanted(line) is true."""
        checked = 0
        end = time.monotonic() + seconds
        with self._changed:
            while True:
                for line in self.lines[checked:]:
                    if wanted(line):
                        return line
                checked = len(self.lines)
                left = end - time.monotonic()
                if self._ended or left <= 0:
                    ended = "the stream ended" if self._ended else f"not within {seconds} s"
                    raise AssertionError(f"no such line ({ended}); last: {self.lines[-10:]}")
                self._changed.wait(left)

    def text(self, seconds: float = DEADLINE_S) -> str:
        """Everything the stream gave, once it has ended (the process has exited)."""
        self._thread.join(seconds)
        assert not self._thread.is_alive(), "the stream did not end"
        return "\n".join(self.lines)


def status_is(wanted: str) -> Callable[[str], bool]:
    """A STATUS= text that says `wanted`, with the clock's warning after it or not (whether
    the machine running the tests has a synchronised clock is not the test's)."""
    return lambda text: without_battery(text).removesuffix(f" | {CLOCK_WORDS}") == wanted


def without_battery(status: str) -> str:
    """STATUS= without its battery part (" | battery 13.2 V", last): it falls with time."""
    return re.sub(r" \| battery [^|]*$", "", status)


def spoken(line: str, phrases: list[str]) -> bool:
    """Whether a line of the simulated voice's output is Kaspar saying one of `phrases`."""
    # The greeting says the robot's name ([robot] name): the demo robot's is Kaspar.
    return any(
        line.endswith(f"Kaspar: {phrase.replace('{robot}', 'Kaspar')}") for phrase in phrases
    )


def log_event(line: str, event: str) -> dict[str, Any] | None:
    """The JSON log line of `event`, or None if this line is another one."""
    try:
        entry = json.loads(line)
    except ValueError:
        return None
    return entry if isinstance(entry, dict) and entry.get("event") == event else None


def read_session_records(state_dir: Path) -> list[dict[str, Any]]:
    """Every complete record of every session in state_dir, oldest session first."""
    sessions = state_dir / "sessions"
    records: list[dict[str, Any]] = []
    for directory in sorted(sessions.iterdir()) if sessions.is_dir() else []:
        path = directory / RECORDS_FILE
        if path.exists():
            for line in path.read_text(encoding="utf-8").splitlines(keepends=True):
                if line.endswith("\n"):  # a line still being written is not a record yet
                    records.append(json.loads(line))
    return records


def wait_for_record(
    state_dir: Path, wanted: Callable[[dict[str, Any]], bool], seconds: float = DEADLINE_S
) -> dict[str, Any]:
    """The first record on disk for which wanted(record) is true, as soon as it is written."""
    end = time.monotonic() + seconds
    while True:
        for record in read_session_records(state_dir):
            if wanted(record):
                return record
        if time.monotonic() > end:
            raise AssertionError(f"no such record within {seconds} s in {state_dir}")
        time.sleep(POLL_S)  # the poll interval of the wait for the file, not an ordering


@dataclass
class RunningService:
    """One run of the service: the process, its notify socket and its two output streams."""

    process: subprocess.Popen[str]
    notify: NotifyListener
    stdout: OutputLines  # the JSON log
    stderr: OutputLines  # the simulated voice and the terminal keyfob's help
    state_dir: Path

    def press(self, keys: str) -> None:
        """Keys on the terminal keyfob (G: long green, R: long red, ...)."""
        assert self.process.stdin is not None
        self.process.stdin.write(keys)
        self.process.stdin.flush()

    def stop(self, signum: signal.Signals = signal.SIGTERM) -> int:
        """Sends `signum` and returns the exit code once the process has ended."""
        self.process.send_signal(signum)
        return self.process.wait(timeout=DEADLINE_S)


@contextlib.contextmanager
def running_service(
    directory: Path,
    environment: dict[str, str] | None = None,
    state_dir: Path | None = None,
    command: Callable[[Path], list[str]] = run_command,
) -> Iterator[RunningService]:
    """The service started as systemd would (NOTIFY_SOCKET; sessions in state_dir, by
    default directory/state; `command` of the state dir, run_command's by default);
    killed at the end if it is still running."""
    notify_path = directory / "notify.sock"
    listener = NotifyListener(notify_path)
    env = os.environ | {"NOTIFY_SOCKET": str(notify_path)}
    for name in ("WATCHDOG_USEC", "WATCHDOG_PID", "LISTEN_FDS", "LISTEN_PID"):
        env.pop(name, None)
    env |= environment or {}
    state_dir = state_dir or directory / "state"
    process = subprocess.Popen(
        command(state_dir),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert process.stdout is not None and process.stderr is not None
    service = RunningService(
        process, listener, OutputLines(process.stdout), OutputLines(process.stderr), state_dir
    )
    try:
        yield service
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=DEADLINE_S)
        if process.stdin is not None:
            process.stdin.close()
        service.stdout.text()
        service.stderr.text()
        listener.close()
