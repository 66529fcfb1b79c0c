"""Simulated keyfobs: a scripted one for tests and the demo, and one driven from the terminal.

Both press simulated keys into the real GestureRecognizer on the injected
clock, so the game sees the same gestures, in the same order and with the
same latencies (a red press waits out its double-press window) as from the
real keyfob. With a virtual clock a whole script runs in no real time.

Actions: "green", "red", "long green", "long red", "double green",
"double red", "both", "command NAME", "lost", "back", and the ones messy
children make: "hold BUTTON SECONDS" (one press held that long) and
"chord FIRST SECONDS" (both buttons, FIRST a moment before the other, held
that long). A long press and "both" are held just past the hold the game asks
for (its GestureNeeds.long_press), or the keyfob's long press.

The terminal and fifo keyfobs are the children's keyfob and, when there is
one, the researcher's device: g and r are the children's green and red, D a
double green; G, R, d and b are the researcher's next, pause, undo and stop,
given on the researcher's device, or as the keyfob gesture that means them
when the researcher uses the children's keyfob; o, c, a and w (reopen, choose,
absent, away) only on their device.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import stat
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TextIO, TypedDict, Unpack

import structlog

from hal.clock import Clock
from hal.errors import InvalidArgument
from hal.keyfob.api import InputEvent, KeyfobBack, KeyfobLost
from hal.keyfob.gestures import GREEN, RED, Gesture, GestureNeeds, GestureRecognizer, GestureTimings

log = structlog.get_logger("hal.keyfob.sim")

PRESS_HOLD = 0.1  # a child's short press
PRESS_GAP = 0.1  # between the two presses of a double
CHORD_LAG = 0.05  # the second button of "both", a little after the first

ACTIONS = (
    "green",
    "red",
    "long green",
    "long red",
    "double green",
    "double red",
    "both",
    "lost",
    "back",
)
_ACTION_LIST = ", ".join(
    [*ACTIONS, "command NAME", "hold BUTTON SECONDS", "chord FIRST SECONDS"]
)


class SimKeyfobOptions(TypedDict, total=False):
    """SimKeyfob's options, passed on by the keyfobs built on it."""

    timings: GestureTimings | None
    needs: GestureNeeds | None
    commands: Iterable[str]


class SimKeyfob:
    """A keyfob whose keys are pressed by `perform`; satisfies hal.keyfob.api.KeyfobInput."""

    def __init__(
        self,
        clock: Clock,
        *,
        timings: GestureTimings | None = None,
        needs: GestureNeeds | None = None,
        commands: Iterable[str] = (),
    ) -> None:
        """A keyfob on `clock` with the recogniser's `timings`, `needs` and command keys."""
        self._clock = clock
        self._timings = timings or GestureTimings()
        self._recogniser = GestureRecognizer(
            self._timings, needs or GestureNeeds(), commands=commands
        )
        self._events: asyncio.Queue[InputEvent] = asyncio.Queue()
        self._lock = asyncio.Lock()
        self._connected = True
        self._closed = False

    async def start(self) -> None:
        """Nothing to open: the keys are pressed by perform()."""
        pass

    async def next_event(self) -> InputEvent:
        """The next gesture or lost/back event, in order; waits as long as it takes."""
        return await self._events.get()

    def set_needs(self, needs: GestureNeeds) -> None:
        """Which gestures the game listens for from each button's next key-down."""
        self._recogniser.set_needs(needs)

    @property
    def connected(self) -> bool:
        """False between the actions "lost" and "back"."""
        return self._connected

    async def close(self) -> None:
        """Mark the keyfob closed; nothing else to release."""
        self._closed = True

    async def perform(self, action: str) -> float:
        """Press the keys of one action, then wait until its gestures are certain.

        Key times are planned on the clock, so a stalled process cannot turn a
        press into a long press. Returns when its first key went down (one action at a
        time: a keyfob has one pair of buttons). Raises InvalidArgument for an unknown
        action.
        """
        async with self._lock:
            # Key times are the planned ones, as a real keyfob's carry the kernel's
            # timestamps: a process stalled mid-press (a busy machine, a fast
            # simulated clock) must not turn a child's press into a long press.
            planned = started = self._clock.now()
            for step in self._steps(action):
                if isinstance(step, float):
                    planned += step
                    await self._wait_until(planned)
                else:
                    button, down = step
                    self._publish(self._recogniser.key(button, down, planned))
            await self._settle()
        return started

    def _steps(self, action: str) -> list[float | tuple[str, bool]]:
        words = action.split()
        asked = self._recogniser.needs.long_press
        hold_long = (asked if asked is not None else self._timings.long_press) + 0.2
        if words[:1] == ["command"] and len(words) == 2:
            return [(words[1], True), PRESS_HOLD, (words[1], False)]
        held = _held(words)
        if held is not None:
            kind, button, seconds = held
            if kind == "hold":
                return [(button, True), seconds, (button, False)]
            other = RED if button == GREEN else GREEN
            return [(button, True), CHORD_LAG, (other, True), seconds, (button, False),
                    (other, False)]  # fmt: skip
        if action in (GREEN, RED):
            return [(action, True), PRESS_HOLD, (action, False)]
        if len(words) == 2 and words[1] in (GREEN, RED) and words[0] in ("long", "double"):
            button = words[1]
            if words[0] == "long":
                return [(button, True), hold_long, (button, False)]
            press: list[float | tuple[str, bool]] = [(button, True), PRESS_HOLD, (button, False)]
            return [*press, PRESS_GAP, *press]
        if action == "both":
            return [(GREEN, True), CHORD_LAG, (RED, True), hold_long, (GREEN, False), (RED, False)]
        if action == "lost":
            self._connected = False
            self._publish(self._recogniser.reset())
            self._events.put_nowait(KeyfobLost(at=self._clock.now(), reason="simulated"))
            return []
        if action == "back":
            self._connected = True
            self._events.put_nowait(KeyfobBack(at=self._clock.now(), device="simulated"))
            return []
        raise InvalidArgument(f"unknown keyfob action {action!r}; expected one of {_ACTION_LIST}")

    async def _wait_until(self, until: float) -> None:
        """Sleep on the clock, delivering any gesture whose time comes meanwhile."""
        while (deadline := self._recogniser.next_deadline()) is not None and deadline <= until:
            await self._clock.sleep(max(0.0, deadline - self._clock.now()))
            self._publish(self._recogniser.advance(deadline))
        await self._clock.sleep(max(0.0, until - self._clock.now()))

    async def _settle(self) -> None:
        while (deadline := self._recogniser.next_deadline()) is not None:
            await self._clock.sleep(max(0.0, deadline - self._clock.now()))
            self._publish(self._recogniser.advance(deadline))

    def _publish(self, gestures: list[Gesture]) -> None:
        if not self._connected:
            return
        for gesture in gestures:
            self._events.put_nowait(gesture)


class ScriptedKeyfob(SimKeyfob):
    """Plays a script of (seconds to wait, action) from start(); for tests and the demo."""

    def __init__(
        self,
        script: Iterable[tuple[float, str]] | str,
        clock: Clock,
        **options: Unpack[SimKeyfobOptions],
    ) -> None:
        """Play `script` ("1.5 green; 0.5 long red", or (delay, action) pairs) from start().

        Every action is checked here: InvalidArgument names the first unknown one.
        """
        super().__init__(clock, **options)
        self._script = parse_script(script) if isinstance(script, str) else list(script)
        for _, action in self._script:
            self._steps_check(action)
        self._task: asyncio.Task[None] | None = None
        self.done = asyncio.Event()

    def _steps_check(self, action: str) -> None:
        words = action.split()
        known = action in ACTIONS or _held(words) is not None
        if not known and not (words[:1] == ["command"] and len(words) == 2):
            raise InvalidArgument(
                f"unknown keyfob action {action!r}; expected one of {_ACTION_LIST}"
            )

    async def start(self) -> None:
        """Start playing the script on the running loop; `done` is set after its last action."""
        self._task = asyncio.get_running_loop().create_task(self._play())

    async def _play(self) -> None:
        for delay, action in self._script:
            await self._clock.sleep(delay)
            await self.perform(action)
        self.done.set()

    async def close(self) -> None:
        """Stop the script where it is."""
        await super().close()
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task


def _held(words: list[str]) -> tuple[str, str, float] | None:
    """("hold" or "chord", button, seconds) of "hold green 1.5" or "chord red 0.4"."""
    if len(words) != 3 or words[0] not in ("hold", "chord") or words[1] not in (GREEN, RED):
        return None
    try:
        seconds = float(words[2])
    except ValueError:
        return None
    return (words[0], words[1], seconds) if 0.0 < seconds < 60.0 else None


def parse_script(text: str) -> list[tuple[float, str]]:
    """Parse "1.5 green; 0.5 long red" into [(1.5, "green"), (0.5, "long red")].

    Parts are separated by ";" or new lines; InvalidArgument for a part that is
    not SECONDS ACTION (the action itself is checked by ScriptedKeyfob).
    """
    script = []
    for part in text.replace("\n", ";").split(";"):
        part = part.strip()
        if not part:
            continue
        delay, _, action = part.partition(" ")
        try:
            script.append((float(delay), action.strip()))
        except ValueError as error:
            raise InvalidArgument(f"expected 'SECONDS ACTION', found {part!r}") from error
    return script


# Keys of the terminal keyfob: the children's, and the researcher's commands.
TERMINAL_KEYS = {
    "g": "green",
    "r": "red",
    "D": "double green",
    "l": "lost",
    "k": "back",
}
RESEARCHER_KEYS = {
    "G": "next",
    "R": "pause",
    "d": "undo",
    "b": "stop",
    "o": "reopen",
    # In idle: choose the group, mark it absent; in step 4: the child asked away (or back).
    "c": "choose",
    "a": "absent",
    "w": "away",
}
# A command given on the children's keyfob when the researcher has no device of their own.
COMMAND_GESTURES = {"next": "long green", "pause": "long red", "undo": "double red", "stop": "both"}
TERMINAL_HELP = (
    "children: g green, r red, D double green; researcher: G next, R pause, d undo, "
    "b stop, o reopen, c choose, a absent, w away (their device); keyfob: l lost, k back"
)


class ResearcherKeys:
    """Where the researcher's terminal keys go: their own device, else the children's keyfob."""

    def __init__(self, keyfob: SimKeyfob, device: SimKeyfob | None) -> None:
        """Commands on `device` (a simulated keypad of command keys), or gestures on `keyfob`."""
        self.keyfob = keyfob
        self.device = device

    async def command(self, name: str) -> None:
        """Give the researcher's command `name` ("next", "pause", "undo", "stop")."""
        if self.device is not None:
            await self.device.perform(f"command {name}")
        elif name in COMMAND_GESTURES:
            await self.keyfob.perform(COMMAND_GESTURES[name])
        # else: a command with no gesture on the children's keyfob (reopen): nothing


class TerminalKeyfob(SimKeyfob):
    """Keys typed in the terminal become keyfob actions (one character each)."""

    def __init__(
        self,
        clock: Clock,
        stream: TextIO | None = None,
        *,
        researcher: SimKeyfob | None = None,
        **options: Unpack[SimKeyfobOptions],
    ) -> None:
        """Read keys from `stream` (standard input by default) once started; the
        researcher's keys go to `researcher` (their simulated device), if given."""
        super().__init__(clock, **options)
        self.researcher = ResearcherKeys(self, researcher)
        self._stream = stream or sys.stdin
        # What termios.tcgetattr returns (typeshed: list[Any]), handed back unchanged.
        self._saved_mode: list[Any] | None = None
        self._pending: asyncio.Queue[str] = asyncio.Queue()
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> None:
        """Put a terminal in cbreak mode and read keys on the running loop.

        A stream that cannot be watched (a regular file, /dev/null under a service)
        is only logged: there is nobody to press keys.
        """
        fd = self._stream.fileno()
        if os.isatty(fd):
            import termios
            import tty

            self._saved_mode = termios.tcgetattr(fd)
            tty.setcbreak(fd)  # one key at a time, no Enter; Ctrl-C still works
        try:
            asyncio.get_running_loop().add_reader(fd, self._on_key)
        except PermissionError:
            # A regular file or /dev/null (a service's stdin) cannot be watched:
            # nobody is there to press keys, which is not a fault.
            log.warning("no terminal keyfob: standard input cannot be read for keys")
            return
        print(TERMINAL_HELP, file=sys.stderr)
        self._task = asyncio.get_running_loop().create_task(self._perform_keys())

    def _on_key(self) -> None:
        data = os.read(self._stream.fileno(), 64).decode(errors="ignore")
        if not data:
            asyncio.get_running_loop().remove_reader(self._stream.fileno())
            return
        for char in data:
            if char in TERMINAL_KEYS or char in RESEARCHER_KEYS:
                self._pending.put_nowait(char)

    async def _perform_keys(self) -> None:
        while True:
            await _perform_key(self, self.researcher, await self._pending.get())

    async def close(self) -> None:
        """Stop reading keys and give the terminal its mode back."""
        await super().close()
        fd = self._stream.fileno()
        asyncio.get_running_loop().remove_reader(fd)
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        if self._saved_mode is not None:
            import termios

            termios.tcsetattr(fd, termios.TCSADRAIN, self._saved_mode)
            self._saved_mode = None


class FifoKeyfob(SimKeyfob):
    """The terminal keyfob's keys read from a fifo that may come late, go, and come back.

    For the service on simulated hardware (`kasparctl run --sim --keys PATH`), where
    a keyfob that pairs or is plugged in after the start is to be shown honestly:
    the fifo missing at start is KeyfobLost("not available at start: ..."), its
    directory is watched with inotify (as the real reader watches /dev/input), and
    KeyfobBack comes when it appears; removing it is an unplug. It is opened
    read-write, so a writer coming and going is never an end of file.
    """

    def __init__(
        self,
        path: str,
        clock: Clock,
        *,
        retry_every: float = 5.0,
        researcher: SimKeyfob | None = None,
        **options: Unpack[SimKeyfobOptions],
    ) -> None:
        """Keys from the fifo at `path` once started; looked for again every `retry_every` s.

        The researcher's keys go to `researcher` (their simulated device), if given.
        """
        super().__init__(clock, **options)
        self.researcher = ResearcherKeys(self, researcher)
        self._path = path
        self._retry_every = retry_every
        self._connected = False
        self._fd = -1
        self._pending: asyncio.Queue[str] = asyncio.Queue()
        self._tasks: list[asyncio.Task[None]] = []

    async def start(self) -> None:
        """Open the fifo if it is there, else report it lost; watch it either way."""
        loop = asyncio.get_running_loop()
        self._tasks = [loop.create_task(self._watch()), loop.create_task(self._perform_keys())]

    async def close(self) -> None:
        """Stop watching and reading; close the fifo."""
        await super().close()
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._drop()

    async def _watch(self) -> None:
        from hal.keyfob.reader import DirectoryWatch  # inotify, shared with the real reader

        first = True
        with DirectoryWatch([str(Path(self._path).parent)]) as watch:
            while not self._closed:
                if self._fd < 0:
                    try:
                        self._open()
                    except OSError as error:
                        if first:
                            reason = f"not available at start: {error.strerror or error}"
                            log.warning("keyfob not connected; watching for it", reason=reason)
                            self._lost(reason)
                    else:
                        log.info("keyfob open", device=self._path)
                        if not first:
                            self._events.put_nowait(KeyfobBack(self._clock.now(), self._path))
                elif not os.path.exists(self._path):
                    log.warning("keyfob lost", reason="removed")
                    self._drop()
                    self._lost("removed")
                first = False
                await watch.changed(self._retry_every)

    def _open(self) -> None:
        fd = os.open(self._path, os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC)
        try:
            if not stat.S_ISFIFO(os.fstat(fd).st_mode):
                raise OSError(f"{self._path} is not a fifo")
            asyncio.get_running_loop().add_reader(fd, self._on_keys)
        except BaseException:
            os.close(fd)
            raise
        self._fd = fd
        self._connected = True

    def _drop(self) -> None:
        if self._fd >= 0:
            with contextlib.suppress(RuntimeError):  # the loop may already be closed
                asyncio.get_running_loop().remove_reader(self._fd)
            os.close(self._fd)
            self._fd = -1

    def _lost(self, reason: str) -> None:
        self._connected = False
        self._publish(self._recogniser.reset())
        self._events.put_nowait(KeyfobLost(at=self._clock.now(), reason=reason))

    def _on_keys(self) -> None:
        try:
            data = os.read(self._fd, 64).decode(errors="ignore")
        except BlockingIOError:
            return
        for char in data:
            if TERMINAL_KEYS.get(char) not in (None, "lost", "back") or char in RESEARCHER_KEYS:
                self._pending.put_nowait(char)

    async def _perform_keys(self) -> None:
        while True:
            await _perform_key(self, self.researcher, await self._pending.get())


async def _perform_key(keyfob: SimKeyfob, researcher: ResearcherKeys, char: str) -> None:
    """One terminal key: a child's action on the keyfob, or the researcher's command."""
    command = RESEARCHER_KEYS.get(char)
    if command is not None:
        await researcher.command(command)
    else:
        await keyfob.perform(TERMINAL_KEYS[char])
