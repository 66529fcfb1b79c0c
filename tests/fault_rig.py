"""The daemon on simulated hardware in simulated time, for the tests of faults in every stage.

The Daemon itself (its session loop, its event log, its STATUS=, its lock) plays
on a rig of simulated servos, keyfob and voice, with honest simulated children
who answer Kaspar's questions and show it where the bags are; the test is the
researcher (their own device's next, pause and stop, named by the keyfob gestures
that once gave them: long green, long red, both) and the one who breaks things. Faults are
injected where the robot has them: in the servos (SimServos.inject_fault), the
keyfob (lost and back), the voice (SimVoice.inject_fault: a player that fails),
the phrase code (a line that raises: a bug), and the disk (every write refused
with ENOSPC or EROFS at the one place session files are written).

Every wait is for something the daemon does (a game event, a STATUS=, a spoken
line) with a deadline in simulated time that only bounds a failure.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import io
import json
import os
import re
import tomllib
from collections.abc import Awaitable, Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from hal import Hardware
from hal.clock import LoopClock
from hal.keyfob.seats import Seats
from hal.keyfob.sim import COMMAND_GESTURES, SimKeyfob
from hal.servos.sim import SimServos
from hal.voice.sim import SimVoice
from kasparctl.config import load_config
from kasparctl.game import storage as storage_module
from kasparctl.game.events import GameEvent
from kasparctl.game.phrases import PhrasePicker
from kasparctl.game.session import EVENTS_FILE, RECORDS_FILE
from kasparctl.log import configure_logging
from kasparctl.service.daemon import Daemon, DaemonOptions
from kasparctl.service.sdnotify import Notifier
from kasparctl.sim import simtime

REPO = Path(__file__).resolve().parents[1]
DEMO_TOML = (REPO / "kasparctl" / "sim" / "demo.toml").read_text(encoding="utf-8")
PHRASES = tomllib.loads((REPO / "phrases" / "en.toml").read_text(encoding="utf-8"))
TOYS = ["lion", "elephant", "giraffe", "monkey", "zebra", "crocodile"]
PILOT = """
variant = "pilot"
locations = ["box", "shelf", "basket"]
poses = { box = { right_shoulder_pitch = -40.0, right_shoulder_roll = 10.0 }, shelf = { right_shoulder_pitch = -70.0, right_shoulder_roll = 40.0 }, basket = { right_shoulder_pitch = -30.0, right_shoulder_roll = 70.0 } }
"""
# What aplay says without a sound card: the cause first, then its consequences.
ALSA_NO_CARD = """\
ALSA lib confmisc.c:855:(parse_card) cannot find card '0'
ALSA lib conf.c:5178:(_snd_config_evaluate) function snd_func_card_inum returned error: No such file or directory
ALSA lib confmisc.c:422:(snd_func_concat) error evaluating strings
ALSA lib conf.c:5178:(_snd_config_evaluate) function snd_func_concat returned error: No such file or directory
ALSA lib confmisc.c:1334:(snd_func_refer) error evaluating name
ALSA lib conf.c:5178:(_snd_config_evaluate) function snd_func_refer returned error: No such file or directory
ALSA lib conf.c:5701:(snd_config_expand) Evaluate error: No such file or directory
ALSA lib pcm.c:2664:(snd_pcm_open_noupdate) Unknown PCM default
aplay: main:831: audio open error: No such file or directory
"""
# ...as the voice reports it (hal.voice.processes.telling_lines).
NO_CARD = (
    "player exited with 1: ALSA lib confmisc.c:855:(parse_card) cannot find card '0' | "
    "ALSA lib conf.c:5178:(_snd_config_evaluate) function snd_func_card_inum returned error: "
    "No such file or directory | ... 5 more lines ... | "
    "aplay: main:831: audio open error: No such file or directory"
)
DEADLINE_S = 600.0  # simulated seconds: bounds a failure only
RECHECK_S = 0.5  # simulated seconds between looks at what no event announces


def write_config(
    directory: Path, variant: str = "names", edit: Callable[[str], str] | None = None
) -> Path:
    """The demo robot with one child per group (six bags to teach), names or pilot;
    `edit` changes its text (a profile removed between two runs)."""
    text = DEMO_TOML.replace("children_per_group = 3", "children_per_group = 1")
    answers = TOYS if variant == "names" else TOYS[:3]
    key = "answer_key = [" + ", ".join(f'"{toy}"' for toy in answers) + "]"
    text = text.replace('group = "demo"', f'group = "demo"\n{key}')
    if variant == "pilot":
        text = text.replace('variant = "names"\n', PILOT.lstrip("\n"))
    if edit is not None:
        text = edit(text)
    path = directory / f"kaspar-{variant}.toml"
    path.write_text(text, encoding="utf-8")
    load_config(str(path))  # a broken test config fails here, by name
    return path


SEATS = """
[[keyfob.children]]
child = 1
device = "/dev/input/kaspar-seat1"

[[keyfob.children]]
child = 2
device = "/dev/input/kaspar-seat2"
"""


def seated(tmp_path: Path, rule: str = "ignore") -> Path:
    """The rig's pilot robot with a group of two, each child at a seat of their own
    ([[keyfob.children]]), a press out of turn handled by `rule`."""

    def edit(text: str) -> str:
        text = text.replace("children_per_group = 1", "children_per_group = 2")
        text = text.replace("[game]\n", f'[game]\nanswer_out_of_turn = "{rule}"\n', 1)
        return text.replace("\n[servos]", SEATS + "\n[servos]", 1)

    return write_config(tmp_path, "pilot", edit)


class RecordedNotifier(Notifier):
    """What would go to systemd, kept: every STATUS= in order, READY, STOPPING."""

    def __init__(self, changed: Callable[[], None]) -> None:
        super().__init__("")
        self.sent: list[tuple[str, ...]] = []
        self._changed = changed

    def notify(self, *fields: str) -> bool:
        self.sent.append(fields)
        self._changed()
        return True

    @property
    def statuses(self) -> list[str]:
        return [f.removeprefix("STATUS=") for fs in self.sent for f in fs if f.startswith("STATUS=")]


class Children:
    """Honest children: they answer each question with the answer key, teach each bag, and
    press the button Kaspar asks for when it checks them.

    With one keyfob per child (`seats`), the child asked answers on their own seat's."""

    def __init__(
        self, keyfob: SimKeyfob, answers: list[int], seats: Sequence[SimKeyfob] = ()
    ) -> None:
        self.keyfob = keyfob
        self.answers = answers
        self.seats = list(seats)
        self.tasks: set[asyncio.Task[None]] = set()

    def __call__(self, event: GameEvent, info: dict[str, Any]) -> None:
        if event is GameEvent.QUESTION:
            right = info["choice"] == self.answers[info["target"]]
            keyfob = self.seats[info["child_index"]] if self.seats else self.keyfob
            self._spawn("green" if right else "red", keyfob)
        elif event is GameEvent.TEACH:
            self._spawn("green")
        elif event is GameEvent.BUTTON_CHECK:
            # Kaspar checks the buttons: the one asked for (with seats, on the first seat's).
            self._spawn(str(info["button"]), self.seats[0] if self.seats else None)

    def _spawn(self, action: str, keyfob: SimKeyfob | None = None) -> None:
        async def press() -> None:
            await asyncio.sleep(1.0)  # a child thinks (simulated time)
            await (keyfob or self.keyfob).perform(action)

        task = asyncio.get_running_loop().create_task(press())
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)


class Breakage:
    """The faults that are not hardware: a phrase that raises once (a bug), a disk that
    refuses every write (the one place session files are written: storage._write_all)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.bug_armed = False
        self.bugs = 0
        self.disk_errno: int | None = None
        original_line = PhrasePicker.line
        original_write = storage_module._write_all
        breakage = self

        def line(picker: PhrasePicker, key: str, **values: str) -> str:
            if breakage.bug_armed:
                breakage.bug_armed = False
                breakage.bugs += 1
                raise KeyError(f"bug: no value for a placeholder of {key}")
            return original_line(picker, key, **values)

        def write_all(fd: int, data: bytes) -> None:
            if breakage.disk_errno is not None:
                raise OSError(breakage.disk_errno, os.strerror(breakage.disk_errno))
            original_write(fd, data)

        monkeypatch.setattr(PhrasePicker, "line", line)
        monkeypatch.setattr(storage_module, "_write_all", write_all)

    def disk(self, error: int | None = errno.ENOSPC) -> None:
        self.disk_errno = error


@dataclass
class FaultRig:
    """The daemon, its hardware, what it said, logged and showed, and the breakage."""

    daemon: Daemon
    servos: SimServos
    keyfob: SimKeyfob
    researcher: SimKeyfob
    voice: SimVoice
    notifier: RecordedNotifier
    lines: io.StringIO
    log: io.StringIO
    breakage: Breakage
    state_dir: Path
    children: Children
    events: list[tuple[GameEvent, dict[str, Any]]] = field(default_factory=list)
    # One keyfob per child ([[keyfob.children]]): each seat's, in order.
    seats: list[SimKeyfob] = field(default_factory=list)
    # stage -> what to do the moment the game enters it (once)
    at_state: dict[str, Callable[[], None]] = field(default_factory=dict)
    changed: asyncio.Condition = field(default_factory=asyncio.Condition)

    # -- what the daemon did ------------------------------------------------------------

    @property
    def stage(self) -> str:
        """The stage the game last said it entered (a new game is "idle" until it begins)."""
        states = [info["state"] for event, info in self.events if event is GameEvent.STATE]
        return states[-1] if states else "starting"

    def status(self) -> str:
        return self.notifier.statuses[-1] if self.notifier.statuses else ""

    def said(self) -> list[str]:
        """Every line Kaspar said (began to say), in order."""
        return [line.split(": ", 1)[1] for line in self.lines.getvalue().splitlines() if ": " in line]

    def log_lines(self) -> list[dict[str, Any]]:
        return [json.loads(line) for line in self.log.getvalue().splitlines() if line.strip()]

    def records(self) -> list[dict[str, Any]]:
        """Every record on disk: each session's, oldest first, then the event log's."""
        found: list[dict[str, Any]] = []
        sessions = self.state_dir / "sessions"
        paths = sorted(sessions.glob(f"*/{RECORDS_FILE}")) if sessions.is_dir() else []
        for path in [*paths, self.state_dir / EVENTS_FILE]:
            if path.exists():
                found += [json.loads(line) for line in path.read_text().splitlines()]
        return found

    def session_records(self) -> Iterator[list[dict[str, Any]]]:
        for path in sorted((self.state_dir / "sessions").glob(f"*/{RECORDS_FILE}")):
            yield [json.loads(line) for line in path.read_text().splitlines()]

    # -- waiting ---------------------------------------------------------------------

    def _listener(self, event: GameEvent, info: dict[str, Any]) -> None:
        self.events.append((event, info))
        if event is GameEvent.STATE and info["state"] in self.at_state:
            # Called as the game enters the stage, before it does anything there.
            self.at_state.pop(info["state"])()
        self._wake()

    def _wake(self) -> None:
        async def notify() -> None:
            async with self.changed:
                self.changed.notify_all()

        asyncio.get_running_loop().create_task(notify())

    async def until(self, what: str, condition: Callable[[], Any], seconds: float = DEADLINE_S) -> Any:
        """Wait for `condition()` to be truthy (checked at every game event and STATUS=)."""
        try:
            async with asyncio.timeout(seconds):
                async with self.changed:
                    while not (found := condition()):
                        # Woken by every game event and STATUS=, and at least every half
                        # simulated second (a line said changes no event).
                        with contextlib.suppress(TimeoutError):
                            async with asyncio.timeout(RECHECK_S):
                                await self.changed.wait()
                    return found
        except TimeoutError:
            recent = [f"{line['level']}: {line['event']}" for line in self.log_lines()[-15:]]
            raise AssertionError(
                f"{what}: not within {seconds} simulated s; stage {self.stage}, "
                f"status {self.status()!r}; said {self.said()[-4:]}; logged {recent}"
            ) from None

    async def stage_is(self, *stages: str) -> str:
        return await self.until(f"stage {stages}", lambda: self.stage if self.stage in stages else None)

    async def event(self, wanted: GameEvent, when: Callable[[dict[str, Any]], bool] = lambda _: True, since: int | None = None) -> dict[str, Any]:
        start = len(self.events) if since is None else since

        def seen() -> dict[str, Any] | None:
            return next((i for e, i in self.events[start:] if e is wanted and when(i)), None)

        return await self.until(f"event {wanted.value}", seen)

    async def next_line(self) -> str:
        """The next line Kaspar begins to say."""
        future: asyncio.Future[str] = asyncio.get_running_loop().create_future()

        def started(text: str) -> None:
            if not future.done():
                future.set_result(text)

        self.voice.on_line = started
        try:
            async with asyncio.timeout(DEADLINE_S):
                return await future
        finally:
            self.voice.on_line = None

    async def command(self, name: str) -> None:
        """The researcher's command `name` on their own device ("choose", "away"...)."""
        await self.researcher.perform(f"command {name}")

    async def press(self, action: str) -> None:
        """A child's key ("green", "red"), the keyfob lost or back, or the researcher's
        command by its old gesture's name ("long green" is next, on their own device)."""
        command = RESEARCHER_GESTURES.get(action)
        if command is not None:
            await self.researcher.perform(f"command {command}")
        else:
            await self.keyfob.perform(action)


RESEARCHER_GESTURES = {gesture: command for command, gesture in COMMAND_GESTURES.items()}
# The commands of the researcher's simulated device.
RIG_COMMANDS = ("next", "pause", "undo", "stop", "away", "choose", "absent")


async def _started(rig: FaultRig) -> None:
    await rig.until("READY=1", lambda: any("READY=1" in fs for fs in rig.notifier.sent))
    await rig.stage_is("idle", "fault")


def run_daemon(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    scenario: Callable[[FaultRig], Awaitable[None]],
    variant: str = "names",
    edit: Callable[[str], str] | None = None,
    *,
    config: Path | None = None,
) -> FaultRig:
    """The daemon on the rig in simulated time, `scenario` beside it; stopped after it.

    `config` replaces the rig's own configuration (write_config's, edited by `edit`);
    with [[keyfob.children]] in it, each seat has a simulated keyfob of its own.
    """
    config_path = config if config is not None else write_config(tmp_path, variant, edit)
    state_dir = tmp_path / "state"
    log = io.StringIO()
    configure_logging("debug", "json", stream=log)
    breakage = Breakage(monkeypatch)
    result: list[FaultRig] = []

    async def main() -> int:
        clock = LoopClock()
        config = load_config(str(config_path))
        lines = io.StringIO()
        servos = SimServos(config.servos, clock)
        keyfob = SimKeyfob(clock)
        researcher = SimKeyfob(clock, commands=RIG_COMMANDS)
        voice = SimVoice(lines, clock, timeout=config.voice.timeout)
        answers = [TOYS.index(toy) for toy in config.sessions[0].answer_key]
        seated = config.keyfob.children
        seats = [SimKeyfob(clock) for _ in seated]
        children = Children(keyfob, answers, seats)
        keyfobs = Seats(seats, [seat.where for seat in seated]) if seats else keyfob
        changed = asyncio.Condition()
        notifier = RecordedNotifier(lambda: rig._wake())
        daemon = Daemon(
            DaemonOptions(str(config_path), sim=True, state_dir=str(state_dir)),
            notifier,
            hardware=Hardware(servos, keyfobs, voice, researcher),
        )
        rig = FaultRig(daemon, servos, keyfob, researcher, voice, notifier, lines, log, breakage,
                       state_dir, children, changed=changed, seats=seats)  # fmt: skip
        daemon.listeners += [rig._listener, children]
        result.append(rig)
        running = asyncio.create_task(daemon.run())
        try:
            await _started(rig)
            await scenario(rig)
        finally:
            daemon.request_stop("the test is over")
            code = await asyncio.wait_for(running, timeout=DEADLINE_S)
            for task in children.tasks:
                task.cancel()
        return code

    code = simtime.run(main(), virtual=True)
    assert code == 0
    return result[0]


def phrase_said(rig: FaultRig, section: str, key: str, since: int = 0) -> bool:
    """Whether Kaspar said one of the variants of phrase section.key (placeholders as any words)."""
    patterns = [
        re.compile(re.sub(r"\\\{\w+\\\}", ".+", re.escape(text)) + r"$")
        for text in PHRASES[section][key]
    ]
    return any(p.match(line) for line in rig.said()[since:] for p in patterns)
