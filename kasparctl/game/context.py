"""What a step may use: the open session, Kaspar's voice, body and servos, the children's
presses, the records, the game's listeners; and the acts steps share (waiting for an
answer with prompts, pointing at a target, naming a child).

A step has no hold on the machine: it cannot fire a trigger, open or close a
session, or stop for a fault. It speaks, moves, waits and records; it ends by
returning (the run loop then moves on) or by raising (the run loop makes it a
fault), and it is cancelled when its stage is left.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from hal.servos.api import ServoApi
from kasparctl.body.api import GazeKind
from kasparctl.config import GameSettings, SessionPlan
from kasparctl.game.battery import BatteryWatch
from kasparctl.game.bodywork import PLAIN_POINT, BodyWork, PointStyle, point
from kasparctl.game.buttons import ButtonCheck
from kasparctl.game.events import GameEvent
from kasparctl.game.opening import OpenedSession
from kasparctl.game.presses import ChildPresses, Press
from kasparctl.game.recorder import Recorder, loop_time
from kasparctl.game.records import PromptRecord, Record
from kasparctl.game.rotation import Turn
from kasparctl.game.scripts import Script
from kasparctl.game.session import Session
from kasparctl.game.speech import Speech
from kasparctl.game.state import GameState
from kasparctl.learning.learner import LearnerParams

RecordT = TypeVar("RecordT", bound=Record)


class Emit(Protocol):
    """Tell the game's listeners of `event`."""

    def __call__(self, event: GameEvent, **info: Any) -> None:
        """Tell every listener; one that fails is logged and left out."""


@dataclass(frozen=True, slots=True)
class StepContext:
    """One open session's step, and what it may use."""

    settings: GameSettings
    opened: OpenedSession
    # The uncertainty script the session was planned with, the learner it began with,
    # and how many children it has.
    script: Script
    params: LearnerParams
    group_size: int
    # Each joint's safe range: a taught pose outside it is asked for again.
    joint_ranges: Mapping[str, tuple[float, float]]
    # The voice has a clip for the listening sound ([voice.clips]).
    listening_sound: bool
    speech: Speech
    body: BodyWork
    servos: ServoApi
    presses: ChildPresses
    recorder: Recorder
    emit: Emit
    # Behaviours the step does not wait for (a smile after an answer), kept until done.
    showing: set[asyncio.Future[None]]
    # Whether the battery is already known to be low (outlives the game: Lasting).
    battery: BatteryWatch
    # The session's check of the buttons (kasparctl.game.buttons), for the game's life.
    buttons: ButtonCheck
    # A whole prompt cycle passed with no answer to what was asked from this time: the
    # game checks whether the keyfob was silent all along (a flat battery?).
    unanswered: Callable[[float], None]
    # Whose turn the open question is, and which seat answered (kasparctl.game.rotation).
    turn: Turn = field(default_factory=Turn)
    # Each joint's rest position: a pose shown at rest is an arm nobody moved.
    rest_pose: Mapping[str, float] = field(default_factory=dict)

    @property
    def session(self) -> Session:
        """The open session."""
        return self.opened.session

    @property
    def plan(self) -> SessionPlan:
        """The plan the session plays."""
        return self.opened.plan

    @property
    def reactions(self) -> str:
        """Kaspar's face after an answer ([game] reactions): the one place it is read."""
        return self.settings.reactions

    @property
    def state(self) -> GameState:
        """What the session has reached (changed only by `change`)."""
        return self.opened.state

    def now(self) -> float:
        """The loop's clock, as the records are stamped."""
        return loop_time()

    def record(self, record: RecordT) -> RecordT | None:
        """Record history: never raises (a refused record is kept and stops the game)."""
        return self.recorder.record(record)

    def change(self, record: RecordT) -> RecordT:
        """Record, apply, snapshot; StorageFailed when the disk refuses."""
        return self.recorder.change(record, self.state, self.settings)

    def child_name(self, index: int) -> str:
        """The name of the child at `index` (their plan's, or "child 2")."""
        children = self.plan.children
        if children:
            return children[index]
        return self.speech.book.fill("names.child", number=str(index + 1))

    async def wait_with_prompts(
        self,
        answer: asyncio.Future[Press],
        prompts: Sequence[tuple[str, Mapping[str, str]]],
    ) -> Press:
        """The first green or red that answers; prompts while nobody does, the last one
        asking for a grown-up (who may then use the keyfob's holds, if they have no
        device of their own)."""
        delays = self.settings.prompt_after_s
        for index, (key, values) in enumerate(prompts):
            delay = delays[min(index, len(delays) - 1)]
            with contextlib.suppress(TimeoutError):
                # Not wait_for: on Python 3.11 it can drop a pause that lands as the answer does.
                async with asyncio.timeout(delay):
                    return await asyncio.shield(answer)
            if index == len(prompts) - 1:
                self.presses.hand_to_researcher(self.now())
                self.unanswered(self.presses.question_start)
            self.record(PromptRecord(line=key, waited=delay))
            self.emit(GameEvent.PROMPT, line=key)
            await self.speech.say(key, **values)
        return await answer

    async def point_at(
        self, target_name: str, target: int, style: PointStyle = PLAIN_POINT
    ) -> None:
        """Point at a target (a bag or a location) where a pose for it is known."""
        pose = self.state.poses.get(target_name) or self.settings.poses.get(target_name)
        if pose:
            self.emit(GameEvent.POINT, target=target_name, style=style.words)
            self.body.look_at(GazeKind.BAG, target, target_name)
            # The head stays on the bag while the arm moves; the eyelids blink on.
            self.body.set_alive(False, blinking=True)
            try:
                await point(self.servos, pose, style)
            finally:
                self.body.set_alive(True)
