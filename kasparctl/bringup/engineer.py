"""What bring-up shares (calibrate, poses, behaviours): the servos, the engineer, the end.

The servos are the configured backend's (the real buses or the simulated
servos). Only the chosen joints go limp; every other joint holds where it is
(turned on the safe way: goal := present position). The engineer is told what
to do on the terminal and, with a real voice, aloud; a green keyfob press or
Enter ends the demonstration, a red press cancels it, and `--seconds` ends it
after a fixed time for scripts and tests.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import os
import sys
import tempfile
import threading
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Any, TextIO

import msgspec
import structlog

from hal.clock import Clock
from hal.errors import KasparError, UnsafeCommand
from hal.keyfob.api import KeyfobInput
from hal.keyfob.gestures import ANSWERS_ONLY, GREEN, RED
from hal.servos.joints import Joints
from hal.servos.sim import SimServos
from hal.voice.api import VoiceOutput
from hal.voice.settings import voice_for_language
from kasparctl.config import Config

log = structlog.get_logger("kasparctl.bringup")

class BringUpError(KasparError):
    """A bring-up command that cannot go on; the message says why and what to do."""


class Ending(enum.Enum):
    """How a demonstration ended."""

    DONE = "done"  # a green press, Enter, or the --seconds elapsed
    CANCELLED = "cancelled"  # a red press


def open_servos(config: Config, clock: Clock) -> Joints:
    """The configured servos, not yet started: the real buses, or the simulated twins."""
    if config.servos.backend == "real":
        return Joints.from_settings(config.servos, clock)
    return SimServos(config.servos, clock)


def select_joints(
    servos: Joints, joints: Sequence[str] | None, group: str | None
) -> list[str]:
    """The joints a command works on: named ones, a group's, or every joint.

    BringUpError names an unknown joint or group.
    """
    if joints:
        unknown = [name for name in joints if name not in servos.joints]
        if unknown:
            known = ", ".join(servos.joints)
            raise BringUpError(f"unknown joint {', '.join(map(repr, unknown))} (joints: {known})")
        return list(dict.fromkeys(joints))
    if group is not None:
        if group not in servos.groups:
            known = ", ".join(servos.groups)
            raise BringUpError(f"unknown group {group!r} (groups: {known})")
        return list(servos.groups[group])
    return list(servos.joints)


async def hold_others(servos: Joints, limp: Sequence[str]) -> list[str]:
    """Turn on, holding where they are, every joint not in `limp`; return those left limp.

    A joint found outside its safe range cannot be turned on without a jump: it
    stays limp and is named (the engineer is told).
    """
    left = []
    for name in servos.joints:
        if name in limp:
            continue
        try:
            await servos.set_compliant(name, False)
        except UnsafeCommand as error:
            log.warning("joint left limp", joint=name, reason=str(error))
            left.append(name)
    return left


class Engineer:
    """The person at the robot: prompts printed (and spoken with a real voice), presses read.

    With `seconds`, the demonstration ends after that long and neither the keyfob
    nor the terminal is read (scripts, tests). `out` takes the printed prompts.
    """

    def __init__(
        self, config: Config, clock: Clock, *, seconds: float | None, quiet: bool, out: TextIO
    ) -> None:
        """Prepare the voice and keyfob the configuration names; nothing opens until start()."""
        self.config = config
        self.clock = clock
        self.seconds = seconds
        self.quiet = quiet
        self.out = out
        self.voice: VoiceOutput | None = None
        self.keyfob: KeyfobInput | None = None
        self._speaking: set[asyncio.Task[Any]] = set()

    async def start(self) -> None:
        """Open the real voice and keyfob where configured (the keyfob only when interactive)."""
        if self.config.voice.backend == "real" and not self.quiet:
            from hal.voice.speaker import Voice

            # The engineer's prompts are English: said with the English voice whatever
            # language the children hear (a German voice would mangle them).
            settings = self.config.voice
            if self.config.language != "en":
                settings = msgspec.structs.replace(settings, voice=voice_for_language("en"))
            self.voice = Voice(settings, self.clock)
        if self.config.keyfob.backend == "real" and self.seconds is None:
            from hal.keyfob.reader import Keyfob

            self.keyfob = Keyfob(self.config.keyfob, self.clock, needs=ANSWERS_ONLY)
            await self.keyfob.start()

    async def close(self) -> None:
        """Let the last prompt finish, then release the voice and keyfob."""
        if self._speaking:
            await asyncio.gather(*self._speaking, return_exceptions=True)
        if self.voice is not None:
            await self.voice.close()
        if self.keyfob is not None:
            await self.keyfob.close()

    def say(self, text: str) -> None:
        """Print `text` now, and speak it with a real voice without waiting for it."""
        print(text, file=self.out, flush=True)
        if self.voice is not None:
            task = asyncio.ensure_future(self.voice.say(text))
            self._speaking.add(task)
            task.add_done_callback(self._speaking.discard)

    async def demonstrate(self, tick: Callable[[], Awaitable[None]], every: float) -> Ending:
        """Call `tick` every `every` seconds until the engineer ends (or the time is up).

        BringUpError when the demonstration could never end (no keyfob, and the
        terminal's input is closed).
        """
        ended: asyncio.Future[Ending] = asyncio.get_running_loop().create_future()
        watchers: list[asyncio.Task[None]] = []
        if self.seconds is None:
            self._read_enter(ended)
            if self.keyfob is not None:
                watchers.append(asyncio.create_task(self._read_keyfob(ended)))
        deadline = None if self.seconds is None else self.clock.now() + self.seconds
        try:
            while True:
                await tick()
                if ended.done():
                    return ended.result()
                if deadline is not None and self.clock.now() >= deadline:
                    return Ending.DONE
                await self.clock.sleep(every)
        finally:
            for watcher in watchers:
                watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.gather(*watchers, return_exceptions=True)

    def _read_enter(self, ended: asyncio.Future[Ending]) -> None:
        loop = asyncio.get_running_loop()
        has_keyfob = self.keyfob is not None

        def settle(line: str) -> None:
            if ended.done():
                return
            if line:
                ended.set_result(Ending.DONE)
            elif not has_keyfob:
                ended.set_exception(BringUpError(
                    "standard input is closed and no keyfob is configured: "
                    "give --seconds N to end after N seconds"
                ))

        def wait_for_line() -> None:
            # A daemon thread: a line never typed must not keep the command from exiting.
            line = sys.stdin.readline()
            with contextlib.suppress(RuntimeError):  # the loop has closed: nobody is waiting
                loop.call_soon_threadsafe(settle, line)

        threading.Thread(target=wait_for_line, name="enter", daemon=True).start()

    async def _read_keyfob(self, ended: asyncio.Future[Ending]) -> None:
        assert self.keyfob is not None
        while not ended.done():
            event = await self.keyfob.next_event()
            button = getattr(event, "button", None)
            if button == GREEN and not ended.done():
                ended.set_result(Ending.DONE)
            elif button == RED and not ended.done():
                ended.set_result(Ending.CANCELLED)


async def start_servos(servos: Joints) -> None:
    """Start the servos with their health poll; a fault at start stops the command.

    BringUpError lists the latched faults (a silent servo, an impossible reading).
    """
    await servos.start()
    if servos.faults:
        faults = "; ".join(str(fault) for fault in servos.faults)
        raise BringUpError(f"the servos are not ready: {faults}")


def write_atomically(path: Path, text: str) -> None:
    """Replace the file in one rename, with its permissions kept: never half a configuration."""
    mode = path.stat().st_mode
    handle, temporary = tempfile.mkstemp(prefix=path.name + ".", dir=path.parent)
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as file:
            file.write(text)
            file.flush()
            os.fsync(file.fileno())
        os.chmod(temporary, mode & 0o7777)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
