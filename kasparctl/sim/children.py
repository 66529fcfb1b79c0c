"""A simulated group of children and their researcher, pressing the simulated keyfob.

They follow what the game announces (a question, a request to move the arm,
a step waiting for the researcher) and answer like the simulator's teachers
(kasparctl.sim.teacher): they know the right toys, and may press the wrong button
or not answer at all; a child who did not answer answers after a prompt. They
act only through the simulated hardware, as real children would, so the game
under test is the game on the robot.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from hal.keyfob.sim import SimKeyfob
from hal.servos.settings import ServoSettings
from kasparctl.game.events import GameEvent
from kasparctl.game.records import FaultSource
from kasparctl.sim.teacher import Teacher

Say = Callable[[str], None]
MAX_RESUMES = 3


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
        think_s: tuple[float, float] = (0.8, 2.5),
        researcher_s: float = 1.5,
        narrate: Say | None = None,
        patience: int = MAX_RESUMES,
    ) -> None:
        """Children who press `keyfob` and move `servos`, believing `answers` (a toy per target)."""
        self.keyfob = keyfob
        self.servos = servos
        self.teacher = teacher
        self.answers = list(answers)
        self.rng = rng
        self.pointing_group = pointing_group
        self.think_s = think_s
        self.researcher_s = researcher_s
        self.narrate = narrate or (lambda text: None)
        self._tasks: set[asyncio.Task[None]] = set()
        self._silent_question: tuple[int, int] | None = None
        self.patience = patience
        self._faults = 0
        self._state = "idle"
        self._resuming = False

    def __call__(self, event: GameEvent, info: dict[str, Any]) -> None:
        """Hear a game event and act on it, as the children or the researcher would."""
        if event is GameEvent.STATE:
            self._state = str(info["state"])
        if event is GameEvent.WAITING_FOR_RESEARCHER:
            self._spawn(self._researcher_next())
        elif event is GameEvent.QUESTION:
            self._spawn(self._answer(int(info["target"]), int(info["choice"])))
        elif event is GameEvent.PROMPT and self._silent_question is not None:
            target, choice = self._silent_question
            self._silent_question = None
            self._spawn(self._answer(target, choice, honest_now=True))
        elif event is GameEvent.TEACH:
            self._spawn(self._teach(int(info["bag"])))
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

    async def _press(self, action: str, who: str) -> None:
        self.narrate(f"{who} presses {action.upper()}")
        await self.keyfob.perform(action)

    async def _researcher_next(self) -> None:
        await asyncio.sleep(self.researcher_s)
        await self._press("long green", "the researcher")

    async def _researcher_resumes(self) -> None:
        # The researcher checks the robot, then resumes with the usual gesture (again,
        # if the robot refused); after `patience` tries they end the session safely.
        try:
            await asyncio.sleep(self.researcher_s * 2)
            if self._state != "fault":
                return  # resumed already, or over
            self._faults += 1
            if self._faults > self.patience:
                await self._press("both", "the researcher")
            else:
                await self._press("long red", "the researcher")
        finally:
            self._resuming = False

    async def _answer(self, target: int, choice: int, honest_now: bool = False) -> None:
        correct = choice == self.answers[target]
        reply = correct if honest_now else self.teacher.answer(correct, self.rng)
        if reply is None:
            self.narrate("the children say nothing")
            self._silent_question = (target, choice)
            return
        await self._think()
        await self._press("green" if reply else "red", "a child")

    async def _teach(self, bag: int) -> None:
        await self._think()
        # Each bag somewhere else in the room, within what the arm can safely reach.
        ranges = {j.name: j.range_deg for j in self.servos.settings.joints}
        pose = {}
        for joint in self.servos.groups[self.pointing_group]:
            low, high = ranges[joint]
            margin = (high - low) * 0.1
            pose[joint] = float(self.rng.uniform(low + margin, high - margin))
        for joint, degrees in pose.items():
            self.servos.push(joint, degrees)
        self.narrate(f"a child moves Kaspar's arm towards bag {bag + 1}")
        await asyncio.sleep(0.5)
        await self._press("green", "another child")


def _calls_researcher(event: GameEvent, info: dict[str, Any]) -> bool:
    """A fault the researcher resumes from (a lost keyfob only once it is back)."""
    fault = event is GameEvent.FAULT
    lost_keyfob = fault and info.get("kind") is FaultSource.KEYFOB
    return (fault and not lost_keyfob) or event in (
        GameEvent.KEYFOB_BACK,
        GameEvent.RESUME_REFUSED,
    )
