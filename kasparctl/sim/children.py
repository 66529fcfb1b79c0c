"""A simulated group of children and their researcher, pressing the simulated keyfob.

They follow what the game announces (a question, a request to show a bag, a
step waiting for the researcher) and answer like the simulator's teachers
(kasparctl.sim.teacher): they know the right toys, and may press the wrong button
or not answer at all; a child who did not answer answers after a prompt. They
may press messily (Messiness: holds, double taps, both buttons, early presses),
and every press they make is kept (`presses`) so a run can check that each
answer was taken and that no press of theirs became a researcher's command. A
press Kaspar did not take (a hold as long as a researcher's command, on one
keyfob) is pressed again, quickly, when Kaspar asks again.
The researcher gives commands through `command` (their own device, or holds on
the children's keyfob), and may interrupt at any moment, open questions included
(Interruptions: a pause and later the resume, an undo, a stop); a hold on one
keyfob that Kaspar did not take (begun during a question) is given again a
moment later. They act only through the simulated hardware, as real children
would, so the game under test is the game on the robot.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from hal.keyfob.sim import CHORD_LAG, PRESS_GAP, PRESS_HOLD, SimKeyfob
from hal.servos.settings import ServoSettings
from kasparctl.game.events import GameEvent
from kasparctl.game.records import FaultSource
from kasparctl.game.recovery import to_reopen
from kasparctl.game.stages import ENDS, PAUSABLE
from kasparctl.sim.teacher import Messiness, Teacher, TeacherError

Say = Callable[[str], None]
# The researcher's command ("next", "pause", "undo", "stop", "reopen"), however they give them.
Command = Callable[[str], Awaitable[None]]
MAX_RESUMES = 3
# How long a child takes to press the button Kaspar asks for when it checks them (s).
CHECK_THINK_S = 1.0
# An interruption comes this long after Kaspar starts asking (or after an answer, for an
# undo): across the question, the listening and the feedback (s).
INTERRUPT_WITHIN_S = (0.0, 12.0)
# A paused game is resumed after this long (s).
PAUSED_FOR_S = (2.0, 8.0)
# A researcher's hold Kaspar did not take is given again, this often, this long after
# the children's next answer (past the game's 1 s for extras), or after WINDOW_WAIT_S.
RETRY_AFTER_S = 1.2
RETRIES = 8
WINDOW_WAIT_S = 60.0
# Where a child shows a bag is where the bag is, give or take this much (degrees).
SHOW_NOISE_DEG = 3.0


class Hands(Protocol):
    """Servos a child can move by hand while they are limp (simulated or emulated)."""

    @property
    def settings(self) -> ServoSettings:
        """The servos' settings: each joint's safe range."""
        ...

    @property
    def groups(self) -> Mapping[str, tuple[str, ...]]:
        """Joint groups by name (the pointing arm is one)."""
        ...

    def push(self, joint: str, degrees: float) -> None:
        """Move a limp joint by hand to `degrees`."""
        ...


@dataclass(frozen=True, slots=True)
class ChildPress:
    """One press a child made: for which question (trial) or bag, what they meant, when.

    `downs` are the times its keys went down (a double and a squeeze have two) and
    `up` when the last one came up; `early` when made while Kaspar was still asking;
    `check` when it answered Kaspar's check of the buttons at the session's start;
    `withdrawn` when it went down after Kaspar had paused or stopped.
    """

    trial: int | None
    bag: int | None
    button: str
    action: str
    downs: tuple[float, ...]
    up: float
    early: bool
    check: bool = False
    # Its key went down after Kaspar had paused or stopped (it waited for the keyfob):
    # no question was open for it.
    withdrawn: bool = False
    # Step 2: pressed before anyone moved the arm (demo --p-unmoved-arm).
    unmoved: bool = False


@dataclass(frozen=True, slots=True)
class ResearcherAction:
    """One command the researcher gave: `downs` when its keys went down, `up` when it was
    done; `on_keyfob` when given on the children's keyfob (or keypad)."""

    command: str
    downs: tuple[float, ...]
    up: float
    on_keyfob: bool


@dataclass(frozen=True, slots=True)
class Interruptions:
    """How often the researcher interrupts: per question or request, a pause (resumed
    PAUSED_FOR_S later) or a stop; per answer, an undo. Each comes INTERRUPT_WITHIN_S
    after it began: during the question, the listening or the feedback."""

    p_pause: float = 0.0
    p_undo: float = 0.0
    p_stop: float = 0.0

    def __post_init__(self) -> None:
        """Refuse a probability outside [0, 1], naming it."""
        for name in ("p_pause", "p_undo", "p_stop"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise TeacherError(f"expected a probability in [0, 1], found {value!r}", name)

    @property
    def none(self) -> bool:
        """The researcher never interrupts (nothing is drawn)."""
        return not (self.p_pause or self.p_undo or self.p_stop)


class SimulatedGroup:
    """A listener for Game.listeners that plays the children and the researcher."""

    def __init__(
        self,
        keyfob: SimKeyfob,
        servos: Hands,
        teacher: Teacher,
        answers: Sequence[int],
        rng: np.random.Generator,
        *,
        pointing_group: str,
        command: Command,
        messiness: Messiness | None = None,
        room: np.random.Generator | None = None,
        think_s: tuple[float, float] = (0.8, 2.5),
        researcher_s: float = 1.5,
        narrate: Say | None = None,
        patience: int = MAX_RESUMES,
        interruptions: Interruptions | None = None,
        researcher_rng: np.random.Generator | None = None,
        shares_keyfob: Callable[[], bool] = lambda: False,
        p_unmoved_arm: float = 0.0,
        unmoved_rng: np.random.Generator | None = None,
    ) -> None:
        """Children who press `keyfob` and move `servos`, believing `answers` (a toy per
        target); their researcher gives commands with `command`. Where the bags are is
        drawn from `room` (the same after a resume, when the children's `rng` is new)."""
        self.keyfob = keyfob
        self.servos = servos
        self.teacher = teacher
        self.answers = list(answers)
        self.rng = rng
        self.pointing_group = pointing_group
        self.command = command
        self.messiness = messiness or Messiness()
        self.think_s = think_s
        self.researcher_s = researcher_s
        self.narrate = narrate or (lambda text: None)
        self.patience = patience
        self.presses: list[ChildPress] = []
        # One keyfob for the group: a child waits for it, and then sees whether the
        # question was answered meanwhile (by the child who had it).
        self._keyfob_free = asyncio.Lock()
        self._tasks: set[asyncio.Task[None]] = set()
        self._silent_question: tuple[int, int, int] | None = None
        self._answered: set[int] = set()
        # The question being asked (trial, target, choice): one abandoned (a re-open or an
        # undo asks anew, under the same number) is answered no more.
        self._asking: tuple[int, int, int] | None = None
        self._room = room if room is not None else rng
        self._bag_poses: dict[int, dict[str, float]] = {}
        self._faults = 0
        self._state = "idle"
        self._resuming = False
        self.interruptions = interruptions or Interruptions()
        # The researcher's commands are on the children's keyfob (or keypad) now: they
        # take it in hand, and no child presses it while they hold it.
        self.shares_keyfob = shares_keyfob
        self._researcher_rng = researcher_rng or np.random.default_rng(0)
        # How many times Kaspar has started asking, and the last answer pressed since
        # (the count then, the press's question or bag, the button): not yet taken.
        self._asked = 0
        self._unheard: tuple[int, int | None, int | None, str] | None = None
        self._interrupting = False
        # Set when a hold on one keyfob could be a command again: an answer was taken (the
        # children are asked nothing for a moment), Kaspar asked for a grown-up, a step.
        self._window = asyncio.Event()
        self._state_since = -math.inf
        # Step 2: how often the presser presses before anyone has moved the arm; drawn
        # from its own stream, so the children's answers are the same whatever it is.
        if not (math.isfinite(p_unmoved_arm) and 0.0 <= p_unmoved_arm <= 1.0):
            raise TeacherError(
                f"expected a probability in [0, 1], found {p_unmoved_arm!r}", "p_unmoved_arm"
            )
        self.p_unmoved_arm = p_unmoved_arm
        self._unmoved_rng = unmoved_rng or np.random.default_rng(0)

    def __call__(self, event: GameEvent, info: dict[str, Any]) -> None:
        """Hear a game event and act on it, as the children or the researcher would."""
        if event is GameEvent.STATE:
            self._state = str(info["state"])
            self._state_since = asyncio.get_running_loop().time()
            self._unheard = None
            self._window.set()
        elif event is GameEvent.ANSWERED:
            self._unheard = None
            self._window.set()
            self._maybe_interrupt("undo", self.interruptions.p_undo)
        elif event is GameEvent.ASKING:
            self._asked += 1
            self._maybe_interrupt("pause", self.interruptions.p_pause)
            self._maybe_interrupt("stop", self.interruptions.p_stop)
        elif event is GameEvent.PROMPT:
            if info.get("line") == "prompt.ask_researcher":
                self._window.set()
            self._press_again()
        if event is GameEvent.WAITING_FOR_RESEARCHER:
            self._spawn(self._researcher_next())
        elif event is GameEvent.ASKING:
            if "trial" in info:
                self._asking = (int(info["trial"]), int(info["target"]), int(info["choice"]))
                # Asked again (after an undo or a re-open): it is open again.
                self._answered.discard(int(info["trial"]))
                if self._silent_question != self._asking:
                    self._silent_question = None
            self._spawn(self._eager(info))
        elif event is GameEvent.QUESTION:
            self._spawn(self._answer(int(info["trial"]), int(info["target"]), int(info["choice"])))
        elif event is GameEvent.ANSWERED:
            self._answered.add(int(info["trial"]))
        elif event is GameEvent.PROMPT and self._silent_question is not None:
            trial, target, choice = self._silent_question
            self._silent_question = None
            self._spawn(self._answer(trial, target, choice, honest_now=True))
        elif event is GameEvent.TEACH:
            self._spawn(self._teach(int(info["bag"])))
        elif event is GameEvent.BUTTON_CHECK:
            self._spawn(self._try_button(str(info["button"])))
        elif event is GameEvent.CONFUSED:
            self._spawn(self._researcher_reopens(info["learned"]))
        elif _calls_researcher(event, info) and not self._resuming:
            # One researcher at a time: a fault can be announced twice.
            self._resuming = True
            self._spawn(self._researcher_resumes())

    async def close(self) -> None:
        """Stop every press still to come."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    def _spawn(self, work: Any) -> None:
        task = asyncio.get_running_loop().create_task(work)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _think(self) -> None:
        low, high = self.think_s
        await asyncio.sleep(float(self.rng.uniform(low, high)))

    async def _press(
        self, action: str, who: str, *, trial: int | None = None, bag: int | None = None,
        button: str = "", early: bool = False, check: bool = False, unmoved: bool = False,
    ) -> None:  # fmt: skip
        self.narrate(f"{who} presses {action.upper()}")
        start = await self.keyfob.perform(action)
        if who == "the researcher":
            return
        if trial is not None or bag is not None:
            self._unheard = (self._asked, trial, bag, button)
        self.presses.append(
            ChildPress(
                trial, bag, button, action, gesture_downs(action, start),
                asyncio.get_running_loop().time(), early, check,
                withdrawn=self._waiting() and self._state_since <= start,
                unmoved=unmoved,
            )
        )

    def _press_again(self) -> None:
        """Kaspar asks again after an answer was pressed for this question: it was not
        taken (held too long on one keyfob); the child presses again, quickly."""
        unheard = self._unheard
        if unheard is None or unheard[0] != self._asked or self._silent_question is not None:
            return
        _, trial, bag, button = unheard
        self._unheard = None
        self._spawn(self._again(trial, bag, button))

    async def _again(self, trial: int | None, bag: int | None, button: str) -> None:
        await asyncio.sleep(0.5)
        async with self._keyfob_free:
            if (trial is not None and trial in self._answered) or self._waiting():
                return
            await self._press(button, "a child, again", trial=trial, bag=bag, button=button)

    def _maybe_interrupt(self, command: str, chance: float) -> None:
        """Draw whether the researcher gives `command` soon (nothing drawn at chance 0)."""
        if chance == 0.0 or self._interrupting:
            return
        when, draw = (float(value) for value in self._researcher_rng.random(2))
        if draw >= chance:
            return
        low, high = INTERRUPT_WITHIN_S
        self._interrupting = True
        self._spawn(self._interrupt(command, low + when * (high - low)))

    async def _interrupt(self, command: str, after: float) -> None:
        try:
            await asyncio.sleep(after)
            if self._state not in PAUSABLE:
                return
            if await self._until_taken(command) and command == "pause":
                low, high = PAUSED_FOR_S
                await asyncio.sleep(float(self._researcher_rng.uniform(low, high)))
                if self._state == "paused":
                    await self._until_taken("pause", resume=True)
        finally:
            self._interrupting = False

    async def _until_taken(self, command: str, resume: bool = False) -> bool:
        """Give `command` until the game shows it was taken (a hold on one keyfob begun
        during a question is not); False if it is not taken after RETRIES tries."""
        for attempt in range(RETRIES):
            if attempt:
                # Not taken: a hold begun during a question. Again once Kaspar has its
                # answer (and the moment for extras is over), or asks for a grown-up.
                self._window.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(WINDOW_WAIT_S):
                        await self._window.wait()
                await asyncio.sleep(RETRY_AFTER_S)
            self.narrate(f"the researcher gives {command.upper()}")
            await self._give(command)
            await asyncio.sleep(RETRY_AFTER_S)
            if command == "undo":
                return True  # an undo shows in the records only: given once
            paused = self._state == "paused"
            if self._state in ENDS or (paused != resume):
                return True
            if self._state not in PAUSABLE:
                return False  # the step it was meant for is over
        return False

    async def _give(self, command: str) -> None:
        """The researcher gives `command`, taking the children's keyfob if it carries it."""
        if not self.shares_keyfob():
            await self.command(command)
            return
        async with self._keyfob_free:
            await self.command(command)

    async def _researcher_next(self) -> None:
        await asyncio.sleep(self.researcher_s)
        self.narrate("the researcher gives NEXT")
        await self._give("next")

    async def _researcher_resumes(self) -> None:
        # The researcher checks the robot, then resumes (again, if the robot refused);
        # after `patience` tries they end the session safely.
        try:
            await asyncio.sleep(self.researcher_s * 2)
            if self._state != "fault":
                return  # resumed already, or over
            self._faults += 1
            command = "stop" if self._faults > self.patience else "pause"
            self.narrate(f"the researcher gives {command.upper()}")
            await self._give(command)
        finally:
            self._resuming = False

    async def _researcher_reopens(self, learned: list[tuple[int, int]]) -> None:
        """Kaspar is confused and asks: the researcher, who knows what is in each bag,
        re-opens the names learned last down to the one learned wrong (none if all are
        right), one command at a time."""
        for _ in range(to_reopen(learned, self.answers)):
            await asyncio.sleep(self.researcher_s)
            self.narrate("the researcher gives REOPEN")
            await self._give("reopen")

    def _reply(self, target: int, choice: int, honest_now: bool) -> bool | None:
        correct = choice == self.answers[target]
        return correct if honest_now else self.teacher.answer(correct, self.rng)

    async def _eager(self, info: dict[str, Any]) -> None:
        """A child who presses while Kaspar is still asking (Messiness.p_early)."""
        if "trial" not in info:
            return  # in step 2 the presser waits for the arm
        delay = self.messiness.early(self.rng)
        if delay is None:
            return
        trial, target, choice = int(info["trial"]), int(info["target"]), int(info["choice"])
        await asyncio.sleep(delay)
        meant = "green" if choice == self.answers[target] else "red"
        action = self.messiness.action(meant, self.rng)
        async with self._keyfob_free:
            if self._open(trial, target, choice):
                await self._press(action, "an eager child", trial=trial, button=meant, early=True)

    async def _answer(self, trial: int, target: int, choice: int, honest_now: bool = False) -> None:
        reply = self._reply(target, choice, honest_now)
        if reply is None:
            self.narrate("the children say nothing")
            self._silent_question = (trial, target, choice)
            return
        await self._think()
        button = "green" if reply else "red"
        action = self.messiness.action(button, self.rng)
        async with self._keyfob_free:
            # An eager press may have answered it, or it was abandoned and asked anew.
            if self._open(trial, target, choice):
                await self._press(action, "a child", trial=trial, button=button)

    async def _try_button(self, button: str) -> None:
        """Kaspar checks the buttons: a child presses the one asked for, cleanly (no draw
        from the children's stream: the game after it is the game it was before)."""
        await asyncio.sleep(CHECK_THINK_S)
        async with self._keyfob_free:
            if not self._waiting():
                await self._press(button, "a child", button=button, check=True)

    def _open(self, trial: int, target: int, choice: int) -> bool:
        """The question is still asked: not answered, not abandoned, and Kaspar not paused
        or stopped (it said it would wait, or goodbye: the children stop too)."""
        current = self._asking == (trial, target, choice)
        return current and trial not in self._answered and not self._waiting()

    def _waiting(self) -> bool:
        """Kaspar said it would wait (paused) or said goodbye (stopped): nobody presses."""
        return self._state == "paused" or self._state in ENDS

    async def _teach(self, bag: int) -> None:
        asked = self._asked
        await self._think()
        # Each bag in its own place in the room, within what the arm can safely reach;
        # each child shows it a little differently.
        ranges = {j.name: j.range_deg for j in self.servos.settings.joints}
        joints = self.servos.groups[self.pointing_group]
        while len(self._bag_poses) <= bag:  # in bag order: the same room after a resume
            pose = {}
            for joint in joints:
                low, high = ranges[joint]
                margin = (high - low) * 0.1
                pose[joint] = float(self._room.uniform(low + margin, high - margin))
            self._bag_poses[len(self._bag_poses)] = pose
        unmoved = bool(self.p_unmoved_arm) and self._unmoved_rng.random() < self.p_unmoved_arm
        if unmoved:
            self.narrate("nobody moves Kaspar's arm yet")
        else:
            for joint, degrees in self._bag_poses[bag].items():
                low, high = ranges[joint]
                noise = float(self.rng.uniform(-SHOW_NOISE_DEG, SHOW_NOISE_DEG))
                self.servos.push(joint, min(high, max(low, degrees + noise)))
            self.narrate(f"a child moves Kaspar's arm towards bag {bag + 1}")
        await asyncio.sleep(0.5)
        action = self.messiness.action("green", self.rng)
        if self._waiting() or self._asked != asked:
            return  # Kaspar waits (the request is asked again once resumed), or it is over
        await self._press(action, "another child", bag=bag, button="green", unmoved=unmoved)


def gesture_downs(action: str, start: float) -> tuple[float, ...]:
    """When the keys of a keyfob action went down, performed from `start`."""
    words = action.split()
    if words[0] == "double":
        return (start, start + PRESS_HOLD + PRESS_GAP)
    if words[0] == "chord":
        return (start, start + CHORD_LAG)
    return (start,)


def _calls_researcher(event: GameEvent, info: dict[str, Any]) -> bool:
    """A fault the researcher resumes from (a lost keyfob only once it is back)."""
    fault = event is GameEvent.FAULT
    lost_keyfob = fault and info.get("kind") is FaultSource.KEYFOB
    return (fault and not lost_keyfob) or event in (
        GameEvent.KEYFOB_BACK,
        GameEvent.RESUME_REFUSED,
    )
