"""The children-as-teachers game: the paper's five steps as a transitions AsyncMachine.

One task, `Game.run`, owns the game: it takes one event at a time (a keyfob
gesture, a step that finished, a hardware fault) and fires the machine's
triggers. What a step does (speak, point, wait for a child) runs as a step
task started when the step is entered and cancelled when it is left, so a
pause or a fault stops Kaspar mid-sentence and a resume starts the step again
from the saved state. Transitions are fired only by `run`, never from inside a
step task, so a step never cancels itself.

Every change is a record first (fsynced), then applied to GameState, then
snapshotted; only then does Kaspar react. The game sees the hardware only
through the hal interfaces, and the learner never sees the answer key.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import structlog
from transitions.extensions.asyncio import AsyncMachine

from hal.errors import HalError
from hal.keyfob.api import KeyfobBack, KeyfobInput, KeyfobLost
from hal.keyfob.gestures import Gesture, GestureKind, GestureNeeds
from hal.servos.api import Fault, ServoApi
from hal.voice.api import Spoken, SpokenStatus, VoiceOutput
from kasparctl.config import Config, SessionPlan
from kasparctl.game.phrases import PhrasePicker
from kasparctl.game.session import Session
from kasparctl.game.state import STEPS, GameState
from kasparctl.learning.learner import choose, entropy_bits, softmax, update
from kasparctl.log import bind_context

log = structlog.get_logger(__name__)

CHILD_WORDS = ("child one", "child two", "child three", "child four", "child five", "child six")
PAUSABLE = ("placing", "teaching", "revealing", "guessing")
# A fault can stop these; farewell too, since it moves the robot to rest (found by the soak:
# a servo fault during farewell left the game in farewell for good).
FAULTABLE = (*PAUSABLE, "farewell")
# How long a cancelled step may take to end before it is cancelled again.
STEP_CANCEL_GRACE_S = 1.0
STATES = ("idle", *STEPS, "finished", "paused", "fault", "stopped")


def _transitions() -> list[dict[str, Any]]:
    """The machine's transitions as data: the live machine and the diagram share them."""
    table: list[dict[str, Any]] = [
        {"trigger": "start", "source": "idle", "dest": "placing", "conditions": "plays_names"},
        {"trigger": "start", "source": "idle", "dest": "guessing", "unless": "plays_names"},
        {"trigger": "advance", "source": "placing", "dest": "teaching"},
        {
            "trigger": "advance",
            "source": "teaching",
            "dest": "revealing",
            "conditions": "bags_taught",
        },
        {"trigger": "advance", "source": "revealing", "dest": "guessing"},
        {"trigger": "advance", "source": "guessing", "dest": "farewell", "conditions": "all_done"},
        {"trigger": "advance", "source": "farewell", "dest": "finished"},
        {"trigger": "pause", "source": list(PAUSABLE), "dest": "paused"},
        {"trigger": "fail", "source": ["idle", *FAULTABLE, "paused"], "dest": "fault"},
        {"trigger": "stop", "source": [*STEPS, "paused", "fault"], "dest": "stopped"},
    ]
    for step in FAULTABLE:
        table.append(
            {
                "trigger": "resume",
                "source": ["paused", "fault"] if step in PAUSABLE else "fault",
                "dest": step,
                "conditions": f"returns_to_{step}",
            }
        )
    table.append(
        {"trigger": "resume", "source": "fault", "dest": "idle", "conditions": "returns_to_idle"}
    )
    return table


TRANSITIONS = _transitions()


class Command(enum.StrEnum):
    NEXT = "next"
    PAUSE = "pause"
    UNDO = "undo"
    STOP = "stop"


@dataclass(frozen=True, slots=True)
class StepEnded:
    step: str
    error: BaseException | None


@dataclass(frozen=True, slots=True)
class HardwareFault:
    kind: str  # "servo", "keyfob", "voice", "software"
    detail: str
    joint: str | None = None


class VoiceFailed(Exception):
    """Kaspar could not say a line: the session cannot go on unheard."""


class SpeechCut(Exception):
    """A line was cut short by voice.cancel(); not a task cancellation, which must
    never be swallowed (the daemon's stop cancels the game's own task)."""


GameEvent = Gesture | KeyfobLost | KeyfobBack | StepEnded | HardwareFault
Listener = Callable[[str, dict[str, Any]], None]


@dataclass
class Hardware:
    servos: ServoApi
    keyfob: KeyfobInput
    voice: VoiceOutput


class Game:
    """One session of the game on the given hardware."""

    state: str  # set by the machine

    def __init__(
        self,
        config: Config,
        hardware: Hardware,
        picker: PhrasePicker,
        open_session: Callable[[], tuple[Session, SessionPlan, GameState]],
        resumed: tuple[Session, SessionPlan, GameState] | None = None,
    ) -> None:
        self.config = config
        self.game = config.game
        self.hw = hardware
        self.picker = picker
        self._open_session = open_session
        self.session: Session | None = None
        self.plan: SessionPlan | None = None
        self.data: GameState | None = None
        self.resumed = resumed is not None
        self._resume_to = "idle"
        self._events: asyncio.Queue[GameEvent] = asyncio.Queue()
        self._step_task: asyncio.Task[None] | None = None
        self._answer: asyncio.Future[tuple[str, float]] | None = None
        self._question_end = 0.0
        self._last_answer_at: float | None = None
        self._last_answer_trial = 0
        self._seen_faults: set[Fault] = set()
        self.listeners: list[Listener] = []
        self.commands = {gesture: Command(name) for gesture, name in self.game.commands.items()}
        initial = "idle"
        if resumed is not None:
            self.session, self.plan, self.data = resumed
            initial = self.data.step if self.data.step in STATES else "idle"
            if self.data.paused and initial in PAUSABLE:
                self._resume_to, initial = initial, "paused"
        for step in ("idle", *FAULTABLE):
            setattr(self, f"returns_to_{step}", lambda step=step: self._resume_to == step)
        self.machine = AsyncMachine(
            model=self,
            states=[
                {"name": name, "on_enter": "_entered", "on_exit": "_leaving"} for name in STATES
            ],
            transitions=TRANSITIONS,
            initial=initial,
            queued=True,
            auto_transitions=False,
            ignore_invalid_triggers=True,
        )

    # -- conditions -------------------------------------------------------------

    def plays_names(self) -> bool:
        return self.game.variant == "names"

    def bags_taught(self) -> bool:
        return self.data is not None and all(t in self.data.poses for t in self.game.targets)

    def all_done(self) -> bool:
        return self.data is not None and self.data.all_done

    # -- the run loop -----------------------------------------------------------

    async def run(self) -> str:
        """Play until the session is finished or stopped; returns the final state."""
        readers = [asyncio.create_task(self._read_keyfob(), name="keyfob reader")]
        # The HAL latches faults and takes the safe action itself; the game only has
        # to stop the step and say so, once per fault, including any latched already.
        self.hw.servos.on_fault(self._fault_latched)
        for fault in self.hw.servos.faults:
            self._fault_latched(fault)
        self.hw.keyfob.set_needs(self._gesture_needs())
        try:
            if self.resumed:
                assert self.session is not None
                bind_context(session=self.session.id)
                self._record(
                    "session", event="resumed", step=self.state, trials=self._require_data().trials
                )
                self._emit("resumed", step=self.state)
                await self._announce("session.resumed")
                if self.state != "paused":
                    await self._entered()
            elif self.state == "idle":
                await self._entered()
            while self.state not in ("finished", "stopped"):
                await self._handle(await self._events.get())
        finally:
            await self._cancel_step()
            self.hw.servos.off_fault(self._fault_latched)
            for task in readers:
                task.cancel()
            await asyncio.gather(*readers, return_exceptions=True)
        return self.state

    async def _handle(self, event: GameEvent) -> None:
        if isinstance(event, Gesture):
            await self._on_gesture(event)
        elif isinstance(event, StepEnded):
            await self._on_step_ended(event)
        elif isinstance(event, HardwareFault):
            await self._on_fault(event)
        elif isinstance(event, KeyfobLost):
            self._record("hal", event="keyfob_lost", reason=event.reason)
            await self._on_fault(HardwareFault("keyfob", event.reason))
        elif isinstance(event, KeyfobBack):
            self._record("hal", event="keyfob_back", device=event.device)
            self._emit("keyfob_back")
            await self._announce("fault.keyfob_back")

    def _gesture_needs(self) -> GestureNeeds:
        """Only the gestures some command uses: a red press need not wait for a double
        unless a double red means something."""
        kinds = {"long": GestureKind.LONG, "double": GestureKind.DOUBLE}
        needs: dict[str, set[GestureKind]] = {
            "green": {GestureKind.PRESS},
            "red": {GestureKind.PRESS},
        }
        for gesture in self.commands:
            words = gesture.split()
            if len(words) == 2:
                needs[words[1]].add(kinds[words[0]])
        return GestureNeeds(
            green=frozenset(needs["green"]),
            red=frozenset(needs["red"]),
            both="both" in self.commands,
        )

    async def _read_keyfob(self) -> None:
        while True:
            await self._events.put(await self.hw.keyfob.next_event())

    def _fault_latched(self, fault: Fault) -> None:
        if fault not in self._seen_faults:
            self._seen_faults.add(fault)
            detail = f"{fault.kind.value}: {fault.detail}"
            self._events.put_nowait(HardwareFault("servo", detail, fault.joint))

    # -- gestures ---------------------------------------------------------------

    async def _on_gesture(self, gesture: Gesture) -> None:
        if gesture.kind is GestureKind.PRESS and gesture.button in ("green", "red"):
            self._on_child_press(gesture)
            return
        if gesture.kind is GestureKind.COMMAND:
            name = gesture.button
        elif gesture.kind is GestureKind.BOTH:
            name = "both"
        else:
            name = f"{gesture.kind.value} {gesture.button}"
        command = self.commands.get(name)
        if command is None:
            self._record(
                "press", button=gesture.button, gesture=name, at=gesture.at, ignored="no command"
            )
            return
        await self._on_command(command, name, gesture.at)

    def _on_child_press(self, gesture: Gesture) -> None:
        answer = self._answer
        if answer is not None and not answer.done():
            if gesture.at >= self._question_end:
                answer.set_result((gesture.button, gesture.at))
                return
            reason = "before the question was finished"
        elif self._last_answer_at is not None and (
            gesture.at - self._last_answer_at <= self.game.extra_press_gap_s
        ):
            self._record(
                "press",
                button=gesture.button,
                at=gesture.at,
                extra=True,
                trial=self._last_answer_trial,
            )
            return
        else:
            reason = f"no question open ({self.state})"
        self._record("press", button=gesture.button, at=gesture.at, ignored=reason)

    async def _on_command(self, command: Command, gesture: str, at: float) -> None:
        key = self._applicable(command)
        fields = {"command": command.value, "gesture": gesture, "at": at, "state": self.state}
        if key is None:
            self._record("command", applied=False, ignored="does not apply", **fields)
            return
        if self.state == "fault" and command is Command.PAUSE and not await self._rearm():
            self._record("command", applied=False, ignored="the hardware is still faulty", **fields)
            self._emit("resume_refused")
            await self._announce("fault.problem")
            return
        if command is Command.PAUSE and self.data is not None:
            self._change("command", applied=True, confirm=key, **fields)  # sets data.paused
        elif self.session is not None:
            self._record("command", applied=True, confirm=key, **fields)
        # Kaspar confirms before what the command starts, and after what it stops.
        speaks_first = key in ("start", "next_step", "resume")
        if speaks_first:
            await self._announce(f"confirm.{key}")
        if self.session is None:
            await self._fire(command)  # "start" opens the session: its command is its first record
            self._record("command", applied=True, confirm=key, **fields)
        else:
            await self._fire(command)
        if command is Command.STOP:
            # To rest at once, saying goodbye on the way: safety does not wait for words.
            await asyncio.gather(self._announce(f"confirm.{key}"), self._rest_safely())
        elif not speaks_first:
            await self._announce(f"confirm.{key}")

    def _applicable(self, command: Command) -> str | None:
        """The confirmation key of a command in the current state, or None if it does not apply."""
        state = self.state
        if command is Command.STOP:
            return "stop" if state in (*STEPS, "paused", "fault") else None
        if command is Command.PAUSE:
            if state in PAUSABLE:
                return "pause"
            if state == "paused" or (state == "fault" and self._hardware_ready()):
                return "resume"
            return None
        if command is Command.UNDO:
            ready = state == "guessing" and self.data is not None and self.data.undo is not None
            return "undo" if ready else None
        if state == "idle":
            return "start"
        if state in ("placing", "revealing") or (state == "teaching" and self.bags_taught()):
            return "next_step"
        return None

    async def _fire(self, command: Command) -> None:
        state = self.state
        if command is Command.STOP:
            await self.stop()
        elif command is Command.PAUSE and state in PAUSABLE:
            self._resume_to = state
            await self.pause()
        elif command is Command.PAUSE:
            await self.resume()
        elif command is Command.UNDO:
            await self._undo()
        elif state == "idle":
            if self.session is None:  # a session resumed before its first step has one
                await self._start_session()
            await self.start()
        else:
            await self.advance()

    async def _rest_safely(self) -> None:
        try:
            await self.hw.servos.rest()
        except HalError as error:
            self._record(
                "fault", fault="servo", detail=f"rest after stop: {error}", state=self.state
            )

    async def _rearm(self) -> bool:
        """After a fault: forget it, and turn every joint's torque back on holding where it is.

        False when that fails (a servo still silent, an arm left outside its range):
        the game stays in the fault state and the failure is recorded.
        """
        await self.hw.servos.clear_faults()
        self._seen_faults.clear()
        try:
            for group in self.hw.servos.groups:
                await self.hw.servos.set_compliant(group, False)
        except HalError as error:
            self._record(
                "fault", fault="servo", detail=f"resume refused: {error}", state=self.state
            )
            return False
        return True

    def _hardware_ready(self) -> bool:
        return self.hw.keyfob.connected

    async def _start_session(self) -> None:
        self.session, self.plan, self.data = self._open_session()
        bind_context(session=self.session.id)
        self._record("session", event="start", plan=self.session.plan)
        self._emit("session", session=self.session.id)

    # -- entering and leaving states -------------------------------------------

    async def _entered(self) -> None:
        state = self.state
        bind_context(step=state)
        self._emit("state", state=state)
        if (
            self.data is not None
            and state in (*STEPS, "finished", "stopped")
            and self.data.step != state
        ):
            self._change("step", to=state)
        if state in STEPS:
            self._start_step(state)
        elif state == "idle":
            self._emit("waiting_for_researcher", step="idle")
        elif (
            state in ("finished", "stopped") and self.session is not None and self.data is not None
        ):
            self.session.save_state(self.data.to_plain(), finished=True)

    async def _leaving(self) -> None:
        await self._cancel_step()

    def _start_step(self, step: str) -> None:
        runner = getattr(self, f"_step_{step}")
        task = asyncio.create_task(runner(), name=f"step {step}")
        self._step_task = task

        def ended(done: asyncio.Task[None]) -> None:
            if not done.cancelled():
                self._events.put_nowait(StepEnded(step, done.exception()))

        task.add_done_callback(ended)

    async def _cancel_step(self) -> None:
        task, self._step_task = self._step_task, None
        if task is not None and not task.done():
            self.hw.voice.cancel()
            # wait(), not `await task`: the step's own CancelledError stays inside it,
            # while a cancellation of this task (the daemon stopping) still gets through.
            # Again and again: a library that swallowed the cancellation (as wait_for can
            # on 3.11) must not leave the game waiting for ever, deaf to every gesture.
            while True:
                task.cancel()
                done, _ = await asyncio.wait({task}, timeout=STEP_CANCEL_GRACE_S)
                if done:
                    break
                log.warning("a step carried on after being cancelled; cancelling again",
                            step=task.get_name())
        if self._answer is not None and not self._answer.done():
            self._answer.cancel()
        self._answer = None

    async def _on_step_ended(self, event: StepEnded) -> None:
        if event.step != self.state:
            return
        if event.error is None:
            await self.advance()
        elif isinstance(event.error, VoiceFailed):
            await self._on_fault(HardwareFault("voice", str(event.error)))
        elif isinstance(event.error, HalError):
            await self._on_fault(HardwareFault("servo", str(event.error)))
        else:
            log.error("step failed", step=event.step, error=repr(event.error))
            await self._on_fault(HardwareFault("software", f"{event.step}: {event.error!r}"))

    async def _on_fault(self, fault: HardwareFault) -> None:
        self._record(
            "fault", fault=fault.kind, detail=fault.detail, joint=fault.joint, state=self.state
        )
        log.warning("fault", fault=fault.kind, detail=fault.detail, joint=fault.joint)
        if self.state == "fault":
            # Said once per stop: an unplugged bus latches every joint on it, and six
            # announcements would keep the researcher's resume waiting for half a minute.
            return
        if self.state in (*FAULTABLE, "paused", "idle"):
            if self.state != "paused":
                self._resume_to = self.state
            await self.fail()
        self._emit("fault", kind=fault.kind)
        if fault.kind == "servo":
            await self._announce("fault.servo", joint=(fault.joint or "a joint").replace("_", " "))
        elif fault.kind == "keyfob":
            await self._announce("fault.keyfob_lost")
        else:
            await self._announce("fault.problem")

    def note_shutdown(self, reason: str) -> None:
        """The daemon is stopping: the session stays unfinished, to be resumed at the next start."""
        self._record("session", event="shutdown", reason=reason, state=self.state)

    # -- the steps --------------------------------------------------------------

    async def _step_placing(self) -> None:
        await self._say("session.greeting")
        await self._say("steps.place_bags")
        self._emit("waiting_for_researcher", step="placing")
        await asyncio.Event().wait()  # the researcher's "next" moves on

    async def _step_revealing(self) -> None:
        await self._say("steps.reveal_toys")
        self._emit("waiting_for_researcher", step="revealing")
        await asyncio.Event().wait()

    async def _step_teaching(self) -> None:
        data = self._require_data()
        group = self.game.pointing_group
        if data.teach_round == 0 and data.teach_bag == 0:
            await self._say("steps.teach_pointing")
        await self.hw.servos.set_compliant(group, True)
        try:
            while data.teach_round < self._group_size():
                if data.teach_bag == 0 and data.teach_round > 0:
                    await self._say("teach.swap_roles")
                await self._teach_one_bag(data.teach_bag, group)
        finally:
            # Torque back on holding where the arm is, also on pause or fault. If the
            # arm was left outside its safe range this fails, and the step fails
            # into the fault state: the researcher moves the arm back and resumes.
            await asyncio.shield(self.hw.servos.set_compliant(group, False))
        await self._say("teach.all_bags_done")

    async def _teach_one_bag(self, bag: int, group: str) -> None:
        round_before = self._require_data().teach_round
        while True:
            await self._say("teach.move_arm", bag=str(bag + 1))
            self._emit("teach", bag=bag, round=round_before)
            button, at = await self._wait_for_press()
            if button == "green":
                pose = await self.hw.servos.read_positions(group)
                outside = self._outside_safe_range(pose)
                if not outside:
                    self._change("pose", bag=bag, round=round_before, pose=pose, at=at)
                    await self._say("teach.pose_logged", bag=str(bag + 1))
                    return
                # Kaspar could never point there: ask again rather than log it.
                self._record("press", button=button, at=at, teach_retry=bag, outside=outside)
            else:
                self._record("press", button=button, at=at, teach_retry=bag)
            await self._say("teach.try_again", bag=str(bag + 1))

    def _outside_safe_range(self, pose: dict[str, float]) -> list[str]:
        ranges = {joint.name: joint.range_deg for joint in self.config.servos.joints}
        return [
            name
            for name, degrees in pose.items()
            if name in ranges and not ranges[name][0] <= degrees <= ranges[name][1]
        ]

    async def _step_guessing(self) -> None:
        data = self._require_data()
        if data.trials == 0:
            await self._say(
                "session.intro_pilot" if self.game.variant == "pilot" else "steps.guessing"
            )
        while not data.all_done:
            await self._one_trial(data)

    async def _step_farewell(self) -> None:
        data = self._require_data()
        if all(p.learned is not None for p in data.progress):
            await self._say("react.all_learned")
        await self._say("session.farewell")
        await self.hw.servos.rest()

    # -- one guess --------------------------------------------------------------

    async def _one_trial(self, data: GameState) -> None:
        plan = self._require_plan()
        params = self.config.profile(plan.profile)
        target = data.target
        target_name = self.game.targets[target]
        child_index = data.turn % self._group_size()
        child = plan.children[child_index] if plan.children else CHILD_WORDS[child_index]
        bind_context(trial=data.trials + 1, target=target_name)
        # Presses from here until the question is finished are recorded and ignored.
        self._answer = asyncio.get_running_loop().create_future()
        self._question_end = math.inf
        await self._say("turn.child", child=child)
        await self._point_at(target_name)
        candidates = data.candidates
        probabilities = softmax(data.learner.table[target], params.beta, candidates)
        entropy = entropy_bits(probabilities)
        # Draw from a copy: the generator moves on only when the trial is recorded,
        # so a pause or a crash before the answer asks the very same question again.
        rng = np.random.Generator(np.random.PCG64())
        rng.bit_generator.state = data.learner.rng.bit_generator.state
        choice = choose(probabilities, rng)
        toy = self.game.toys[choice]
        spoken: list[str] = []
        band = None
        if plan.speak_uncertainty:
            band, line = self.picker.uncertainty(entropy, int(candidates.sum()))
            spoken.append(await self._say_text(line, f"uncertainty.{band}"))
        if self.game.variant == "pilot":
            spoken.append(await self._say("guess.pilot", toy=toy, location=target_name))
        else:
            spoken.append(await self._say("guess.names", toy=toy))
        self._question_end = self._now()
        self._emit("question", target=target, choice=choice, trial=data.trials + 1)
        button, pressed_at = await self._wait_for_answer()
        green = button == "green"
        reward = params.reward(green)
        progress_after = dataclasses.replace(data.progress[target])
        progress_after.record(choice, green)
        next_target = target if not progress_after.done else _next_open(data, target)
        q_after = update(data.learner.table, target, choice, reward, params, next_target)[target]
        previous = data.previous
        answer_key = plan.answer_key
        correct = None if not answer_key else self.game.toys.index(answer_key[target]) == choice
        record = self._change(
            "trial",
            trial=data.trials + 1,
            problem_trial=data.progress[target].trials + 1,
            step="guessing",
            target=target_name,
            target_index=target,
            child=child,
            child_index=child_index,
            candidates=[
                t for t, offered in zip(self.game.toys, data.offered, strict=True) if offered
            ],
            probabilities=probabilities.tolist(),
            entropy=entropy,
            band=band,
            spoken=spoken,
            choice=toy,
            choice_index=choice,
            feedback=button,
            question_end=self._question_end,
            feedback_at=pressed_at,
            reaction_time=pressed_at - self._question_end,
            reward=reward,
            q_before=data.learner.table[target].tolist(),
            q_after=q_after.tolist(),
            learner_rng=rng.bit_generator.state,
            perseverative=previous is not None and not previous[1] and previous[0] == choice,
            win_shift=previous is not None and previous[1] and previous[0] != choice,
            correct=correct,
            feedback_right=None if correct is None else correct == green,
            learned=progress_after.learned is not None,
        )
        self._last_answer_at, self._last_answer_trial = pressed_at, record["trial"]
        self._emit("answered", trial=record["trial"], feedback=button)
        await self._react(green)
        if progress_after.learned is not None:
            if self.game.variant == "pilot":
                await self._say("react.learned_pilot", toy=toy, location=target_name)
            else:
                await self._say("react.learned", toy=toy)
        elif progress_after.given_up:
            await self._say("prompt.ask_researcher")

    async def _undo(self) -> bool:
        data = self._require_data()
        if data.undo is None:
            return False
        await self._cancel_step()
        self._change("undo", trial=data.undo["trial"])
        self._last_answer_at = None
        self._start_step("guessing")
        return True

    async def _react(self, green: bool) -> None:
        expression = self.game.happy_pose if green else self.game.sad_pose
        line = self._say("react.happy" if green else "react.sad")
        if not expression:
            await line
            return
        # Face and words together; gather cancels both with the step and
        # retrieves a servo error from either, so none is left unheard.
        await asyncio.gather(line, self._express(dict(expression)))

    async def _express(self, pose: dict[str, float]) -> None:
        before = await self.hw.servos.read_positions()
        await self.hw.servos.move(pose, duration=0.6)
        await self.hw.servos.move({joint: before[joint] for joint in pose}, duration=0.6)

    async def _point_at(self, target_name: str) -> None:
        data = self._require_data()
        pose = data.poses.get(target_name) or self.game.poses.get(target_name)
        if pose:
            self._emit("point", target=target_name)
            await self.hw.servos.move(pose, duration=1.0)

    # -- waiting for children ---------------------------------------------------

    async def _wait_for_press(self) -> tuple[str, float]:
        self._question_end = self._now()
        self._answer = asyncio.get_running_loop().create_future()
        return await self._answer

    async def _wait_for_answer(self) -> tuple[str, float]:
        """The first green or red after the question; prompts while nobody answers."""
        answer = self._answer
        assert answer is not None
        prompts = ("prompt.nobody_first", "prompt.nobody_second", "prompt.ask_researcher")
        delays = self.game.prompt_after_s
        for index, key in enumerate(prompts):
            delay = delays[min(index, len(delays) - 1)]
            with contextlib.suppress(TimeoutError):
                # Not wait_for: on Python 3.11 it can drop a pause that lands as the answer does.
                async with asyncio.timeout(delay):
                    return await asyncio.shield(answer)
            self._record("prompt", line=key, waited=delay)
            self._emit("prompt", line=key)
            await self._say(key)
        return await answer

    # -- speaking, recording ----------------------------------------------------

    async def _announce(self, key: str, **values: str) -> None:
        """Speech from the run loop: a failing voice is recorded, never raised here."""
        with contextlib.suppress(VoiceFailed, SpeechCut):
            await self._say(key, **values)

    async def _say(self, key: str, **values: str) -> str:
        return await self._say_text(self.picker.line(key, **values), key)

    async def _say_text(self, text: str, key: str) -> str:
        spoken: Spoken = await self.hw.voice.say(text, key)
        if spoken.status is SpokenStatus.CANCELLED:
            raise SpeechCut(text)
        if spoken.status is not SpokenStatus.FINISHED:
            self._record(
                "hal", event="voice", status=spoken.status.value, text=text, error=spoken.error
            )
            if spoken.status is SpokenStatus.FAILED:
                raise VoiceFailed(spoken.error or "the voice failed")
        return text

    def _record(self, kind: str, **fields: Any) -> dict[str, Any] | None:
        if self.session is None:
            log.info(kind, **fields)
            return None
        return self.session.record(kind, self._now(), **fields)

    def _change(self, kind: str, **fields: Any) -> dict[str, Any]:
        """Record, apply, snapshot: the order that makes a crash lose nothing."""
        session, data = self.session, self._require_data()
        assert session is not None
        record = session.record(kind, self._now(), **fields)
        data.apply(record, self.game)
        session.save_state(data.to_plain())
        return record

    def _emit(self, name: str, **info: Any) -> None:
        for listener in self.listeners:
            listener(name, info)

    def _now(self) -> float:
        return asyncio.get_running_loop().time()

    def _group_size(self) -> int:
        return self.config.group_size(self._require_plan())

    def _require_data(self) -> GameState:
        if self.data is None:
            raise RuntimeError("no session is open")
        return self.data

    def _require_plan(self) -> SessionPlan:
        if self.plan is None:
            raise RuntimeError("no session is open")
        return self.plan


def _next_open(data: GameState, current: int) -> int | None:
    """s_{t+1} of Eq. 1 once a target is done: the next one not done, if any."""
    return next((i for i, p in enumerate(data.progress) if i != current and not p.done), None)
