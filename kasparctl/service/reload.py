"""`systemctl reload` that fails when the daemon refuses: a request, SIGHUP, an answer.

systemd reports a reload as done once ExecReload= exits, so a bare `kill -HUP`
would say "reloaded" even when the daemon refuses mid-session. ExecReload= runs
`kasparctl reload` instead: it writes a random token to reload.request in the
service's runtime directory ($RUNTIME_DIRECTORY, /run/kaspar), sends SIGHUP to
$MAINPID, and waits (bounded) for reload.reply to carry the same token with the
daemon's answer: exit 0 when it reloaded, 1 when it refused, failed or did not
answer. Both files are replaced atomically, so neither side reads half of one.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import signal
import time
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import msgspec

REQUEST_FILE = "reload.request"
REPLY_FILE = "reload.reply"
POLL_S = 0.02  # how often the requester looks for the answer (a few ms of work each)


class Outcome(StrEnum):
    """What the daemon did with a reload."""

    RELOADED = "reloaded"
    REFUSED = "refused"  # a session is running
    FAILED = "failed"  # the new configuration could not be used; the old one is kept
    NO_ANSWER = "no answer"  # nothing came back in time (the requester's own verdict)


class Answer(msgspec.Struct, frozen=True):
    """The daemon's answer to the request carrying `token` (None: a bare SIGHUP)."""

    token: str | None
    outcome: Outcome
    detail: str = ""


def runtime_directory(environ: dict[str, str] | None = None) -> Path | None:
    """The service's runtime directory: the first of $RUNTIME_DIRECTORY, if systemd set one."""
    value = (environ if environ is not None else os.environ).get("RUNTIME_DIRECTORY", "")
    first = value.split(":")[0]
    return Path(first) if first else None


def _replace(path: Path, data: bytes) -> None:
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_bytes(data)
    os.replace(temporary, path)


class ReloadDesk:
    """The daemon's side: which request a SIGHUP answers, and the answer written back."""

    def __init__(self, directory: Path | None) -> None:
        """Answer in `directory` (None: outside systemd, nobody waits for an answer)."""
        self.directory = directory

    def token(self) -> str | None:
        """The token of the request waiting, if any (None for a SIGHUP sent by hand)."""
        if self.directory is None:
            return None
        try:
            return (self.directory / REQUEST_FILE).read_text().strip() or None
        except OSError:
            return None

    def answer(self, token: str | None, outcome: Outcome, detail: str = "") -> None:
        """Write the answer for `token`; an unwritable runtime directory only loses it."""
        if self.directory is None:
            return
        # Unwritable: the requester times out and says so; the reload itself is unaffected.
        with contextlib.suppress(OSError):
            data = msgspec.json.encode(Answer(token, outcome, detail))
            _replace(self.directory / REPLY_FILE, data)


@dataclass(frozen=True)
class Verdict:
    """What `request_reload` found: the daemon's outcome and its words."""

    outcome: Outcome
    detail: str

    @property
    def ok(self) -> bool:
        """True only when the daemon reloaded."""
        return self.outcome is Outcome.RELOADED


def request_reload(pid: int, directory: Path, timeout: float = 10.0) -> Verdict:
    """Ask the daemon `pid` to reload and wait up to `timeout` s for its answer in `directory`.

    OSError when the request cannot be written or the signal sent (no such process).
    """
    token = secrets.token_hex(8)
    _replace(directory / REQUEST_FILE, token.encode())
    os.kill(pid, signal.SIGHUP)
    deadline = time.monotonic() + timeout
    reply = directory / REPLY_FILE
    while time.monotonic() < deadline:
        try:
            answer = msgspec.json.decode(reply.read_bytes(), type=Answer)
        except (OSError, msgspec.DecodeError):
            answer = None
        if answer is not None and answer.token == token:
            return Verdict(answer.outcome, answer.detail)
        time.sleep(POLL_S)
    return Verdict(Outcome.NO_ANSWER, f"process {pid} did not answer within {timeout:g} s")
