"""A real terminal for the tests: a program run in a tmux pane, its screen read back as text.

Each Tmux has its own server (its own socket), so tests never touch a person's tmux
and a failed test leaves nothing running.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import time
import uuid
from collections.abc import Callable, Sequence

POLL_S = 0.05  # the poll interval of a wait for the screen, not an ordering


class Tmux:
    """One tmux server with one pane of a given size."""

    def __init__(self, width: int = 80, height: int = 24) -> None:
        self.socket = f"kaspar-test-{uuid.uuid4().hex[:10]}"
        self.width, self.height = width, height

    def _tmux(self, *arguments: str, check: bool = True) -> str:
        result = subprocess.run(
            ["tmux", "-u", "-L", self.socket, *arguments],
            capture_output=True,
            text=True,
            check=check,
            env={**os.environ, "LANG": "C.UTF-8"},
        )
        return result.stdout

    def start(self, command: Sequence[str], env: dict[str, str] | None = None) -> None:
        """Run `command` in a new pane; the pane stays after it exits, to read its last words."""
        exports = " ".join(f"{k}={shlex.quote(v)}" for k, v in (env or {}).items())
        line = f"env {exports} {shlex.join(command)}" if exports else shlex.join(command)
        self._tmux(
            "new-session", "-d", "-s", "test", "-x", str(self.width), "-y", str(self.height), line
        )
        self._tmux("set-option", "-t", "test", "remain-on-exit", "on")

    def screen(self) -> str:
        """What the pane shows now, as plain text."""
        return self._tmux("capture-pane", "-p", "-t", "test")

    def keys(self, *keys: str) -> None:
        """Type keys (tmux's names: Space, Right, Left, q...)."""
        self._tmux("send-keys", "-t", "test", *keys)

    def dead(self) -> bool:
        """Whether the program in the pane has exited."""
        return self._tmux("display-message", "-p", "-t", "test", "#{pane_dead}").strip() == "1"

    def wait_for(self, wanted: Callable[[str], bool], seconds: float = 20.0, what: str = "") -> str:
        """The screen once `wanted(screen)` holds."""
        end = time.monotonic() + seconds
        while True:
            screen = self.screen()
            if wanted(screen):
                return screen
            if time.monotonic() > end:
                raise AssertionError(f"not on screen within {seconds} s: {what}\n{screen}")
            time.sleep(POLL_S)

    def close(self) -> None:
        """End the server and everything in it."""
        self._tmux("kill-server", check=False)
