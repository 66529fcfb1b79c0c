"""The children-as-teachers game: the paper's five steps as a transitions AsyncMachine.

One task, `Game.run`, owns the game: it takes one input at a time (a keyfob
gesture, a step that finished, a hardware fault) and fires the machine's
triggers. What a step does (speak, point, wait for a child) runs as a step
task started when the step is entered and cancelled when it is left, so a
pause or a fault stops Kaspar mid-sentence and a resume starts the step again
from the saved state. Transitions are fired only by `run`, never from inside a
step task, so a step never cancels itself.

Every change is a record first (fsynced), then applied to GameState, then
snapshotted; only then does Kaspar react. The game sees the hardware only
through the hal interfaces, and the learner never sees the answer key.

Kaspar listens when it has asked (kasparctl.game.presses): a child's press is
an answer from the question's last words on, an early press is acknowledged,
and the children's keyfob carries nothing but answers when the researcher's
commands come from a device of their own (the default). On a robot with one
keyfob the researcher's commands are holds begun while Kaspar asks the
children nothing; so are they while the researcher's own device is away.

Faults, in every stage: a part that fails (a servo, the bus, the keyfob, the
voice, the disk) or a bug (an error in a step, or in handling an input) is
recorded (in the session, or in the daemon's event log when none is open),
logged at its level, kept in `problems` (the daemon's STATUS= shows them) and
said where the voice still works; a running step stops (the fault stage), and
the researcher's resume or stop still work. Nothing the run loop does can end
it but the end of the session: an error while handling an input is itself a
fault. A lost keyfob stops only a running step: in idle or paused there is
nothing to stop, and a keyfob plugged in late starts the session at once.

The rules live beside this module, pure: the machine's table (stages), which
researcher command applies where (researcher), one guess's arithmetic (trial)
and the records (records); the Game speaks, moves and waits.
"""

from __future__ import annotations

import asyncio
import contextlib
import shutil
from collections.abc import Callable, Coroutine, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar, cast

import msgspec
import structlog
from msgspec import UNSET
from transitions.extensions.asyncio import AsyncMachine

from hal import Hardware
from hal.errors import HalError
from hal.keyfob.api import InputEvent, KeyfobBack, KeyfobLost
from hal.keyfob.gestures import ANSWERS_ONLY, Gesture, GestureKind
from hal.servos.api import Fault
from kasparctl.body.api import Body, GazeKind
from kasparctl.config import Config, SessionPlan
from kasparctl.game import recovery
from kasparctl.game.bodywork import (
    FAREWELL,
    GREETING,
    HAPPY,
    NOD,
    PLAIN_POINT,
    SAD,
    THINKING,
    BodyWork,
    PointStyle,
    point,
    point_style,
)
from kasparctl.game.events import GameEvent, Listener
from kasparctl.game.jsonl import record_to_plain
from kasparctl.game.phrases import PhrasePicker
from kasparctl.game.presses import ChildPresses, Press
from kasparctl.game.records import (
    Button,
    CommandRecord,
    Confirmation,
    ConfusedRecord,
    FaultRecord,
    FaultSource,
    HalEvent,
    HalRecord,
    PoseRecord,
    PressRecord,
    PromptRecord,
    Record,
    SessionEvent,
    SessionRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.researcher import (
    SILENT,
    SPOKEN_FIRST,
    TRIGGERS,
    Facts,
    commands_by_gesture,
    confirmation,
    gesture_name,
    gesture_needs,
)
from kasparctl.game.scripts import LEGACY_SCRIPT, Script, script
from kasparctl.game.session import EventLog, Session, frozen_learner
from kasparctl.game.speech import Speech, VoiceFailed
from kasparctl.game.stages import (
    ENDS,
    FAULTABLE,
    PAUSABLE,
    STATES,
    STEPS,
    Conditions,
    bound_transitions,
)
from kasparctl.game.state import GameState, far_from
from kasparctl.game.storage import StorageFailed
from kasparctl.game.trial import Answer, TrialPlan, plan_trial, question_record, score_answer
from kasparctl.log import bind_context
from kasparctl.vocabulary import Command

log = structlog.get_logger(__name__)

# How long a cancelled step may take to end before it is cancelled again.
STEP_CANCEL_GRACE_S = 1.0
# Records that could not be written (the disk full) are kept to write once it takes
# them again, up to this many; beyond, they are in the journal only.
UNWRITTEN_LIMIT = 200
# The stages each kind of fault stops (into the fault stage); in the others it is
# recorded and said, and the stage stays. A lost keyfob stops a running step only.
STOPPED_BY: dict[FaultSource, tuple[str, ...]] = {
    kind: ("idle", *FAULTABLE, "paused") if kind is not FaultSource.KEYFOB else FAULTABLE
    for kind in FaultSource
}
# The researcher's own device going away stops nothing: their commands go to the
# children's keyfob as holds meanwhile.
STOPPED_BY[FaultSource.RESEARCHER] = ()
# How long Kaspar takes to turn to its listening pose.
LISTEN_MOVE_S = 0.4
# The phrase key whose clip is the listening sound ([voice.clips]).
LISTENING_SOUND = "cue.listening"


RecordT = TypeVar("RecordT", bound=Record)
OpenedSession = tuple[Session, SessionPlan, GameState]


@dataclass(frozen=True, slots=True)
class StepEnded:
    """A step's task ended: by itself (error None), or by failing with `error`."""

    step: str
    error: BaseException | None


@dataclass(frozen=True, slots=True)
class HardwareFault:
    """A part failed (or a bug showed): the game stops (the fault stage) and Kaspar says so."""

    kind: FaultSource
    detail: str
    joint: str | None = None
    # What was raised, when it was (a storage fault's StorageFailed names the file).
    error: Exception | None = None


@dataclass(frozen=True, slots=True)
class FromResearcher:
    """An event of the researcher's own device (a command key, or the device lost or back)."""

    event: InputEvent


# What the run loop takes, one at a time.
GameInput = Gesture | KeyfobLost | KeyfobBack | StepEnded | HardwareFault | FromResearcher


def planned(config: Config, plan: SessionPlan, seed: int | None) -> dict[str, Any]:
    """A session's plan.json (less its id and creation time, which Session.create adds).

    The group, its session number, the condition, the variant, the learner's seed,
    the uncertainty script and its version, the language, and the plan entry itself.
    """
    chosen = script(config.script(plan))
    return {
        "group": plan.group,
        "number": plan.number,
        "condition": plan.condition,
        "variant": config.game.variant,
        "seed": seed,
        "script": chosen.name,
        "script_version": chosen.version,
        # What Kaspar spoke (sessions planned before languages were recorded spoke "en").
        "language": config.language,
        # Confusion noticed, names re-opened (kasparctl.game.recovery); absent before.
        "recovery": recovery.RECOVERY_VERSION,
        "uncertainty": plan.uncertainty_mode,
        "plan": msgspec.to_builtins(plan.resolved()),
        # Frozen at the start: a resume uses these, whatever the configuration says then.
        "learner": frozen_learner(plan.profile, config.profile(plan.profile)),
    }


def session_script(session: Session) -> Script:
    """The script a session was planned with; the five varied bands before scripts existed."""
    return script(str(session.plan.get("script", LEGACY_SCRIPT)))


class Game:
    """One session of the game on the given hardware.

    `stage` is where the machine is (a name of kasparctl.game.stages.STATES);
    `session_state` is what the open session has reached (None before it opens).
    """

    stage: str  # set by the machine

    if TYPE_CHECKING:
        # The machine's triggers, added to the model by transitions; each returns
        # whether a transition happened (kasparctl.game.stages.TRANSITIONS).
        async def start(self) -> bool:
            """Idle to the first step: placing (names) or guessing (pilot)."""

        async def advance(self) -> bool:
            """A step to the next one, farewell to finished."""

        async def pause(self) -> bool:
            """A pausable step to paused."""

        async def resume(self) -> bool:
            """Paused or fault back to the step left (or idle)."""

        async def fail(self) -> bool:
            """To the fault stage."""

        async def stop(self) -> bool:
            """To stopped: the researcher ended the session."""

        async def trigger(self, name: str) -> bool:
            """Fire the trigger called `name`."""

    def __init__(
        self,
        config: Config,
        hardware: Hardware,
        picker: PhrasePicker,
        open_session: Callable[[], OpenedSession],
        resumed: OpenedSession | None = None,
        *,
        stopped: OpenedSession | None = None,
        event_log: EventLog | None = None,
        startup_faults: Sequence[HardwareFault] = (),
        known_problems: Mapping[FaultSource, str] | None = None,
        unwritten: Sequence[tuple[Session | EventLog, Record, float]] = (),
        body: Body | None = None,
    ) -> None:
        """A game that opens its session with `open_session` at the start, or resumes `resumed`.

        `stopped` is a session the researcher stopped and has not closed: in idle their
        "next" reopens it where it stopped, their "stop" closes it for good.

        While no session is open its records go to `event_log` (with none, they are
        only logged). `startup_faults` happened before the game (a servo that did not
        start, sessions that could not be read): the game begins by stopping for them.
        `known_problems` are those an earlier game saw that are not over (the keyfob
        still away, the voice or the disk failing): shown from the start. The keyfob
        itself reports KeyfobLost when it is not there at its start; an earlier game
        may have taken that report, hence these. `unwritten` are records an earlier
        game kept when the disk refused them (its `unwritten`): written first, in order.
        `body` shows Kaspar's gaze, life and behaviours (none: a StillBody, and the
        game's own happy and sad poses).
        """
        self.config = config
        self.settings = config.game
        self.hw = hardware
        self.picker = picker
        self.speech = Speech(picker, hardware.voice, self._record, self._voice_health)
        self.body = BodyWork(
            body, lambda: self.plan, lambda info: self._emit(GameEvent.BODY, **info)
        )
        # Behaviours the game does not wait for (a smile after an answer), kept until done.
        self._showing: set[asyncio.Future[None]] = set()
        self.event_log = event_log
        self._startup_faults = tuple(startup_faults)
        # What is not working now, by part: shown by the daemon, cleared as each comes back.
        self.problems: dict[FaultSource, str] = dict(known_problems or {})
        self.speech.failing = self.problems.get(FaultSource.VOICE)
        # The kinds of fault Kaspar has said since the game last stopped for one.
        self._said_in_fault: set[FaultSource] = set()
        self._unwritten: list[tuple[Session | EventLog, Record, float]] = list(unwritten)
        self._storage_fault_queued = False
        self._storage_failed_in_event_log = False
        self._open_session = open_session
        self.session: Session | None = None
        self.plan: SessionPlan | None = None
        self.session_state: GameState | None = None
        self.resumed = resumed is not None
        self._inputs: asyncio.Queue[GameInput] = asyncio.Queue()
        self._step_task: asyncio.Task[None] | None = None
        self.presses = ChildPresses(self.settings.extra_press_gap_s)
        self._seen_faults: set[Fault] = set()
        self.listeners: list[Listener] = []
        self.commands = commands_by_gesture(self.settings.commands)
        self.researcher = config.researcher
        self.stopped_waiting = stopped
        self.script = script(config.game.script)
        self._use_script(self.script)  # the configured script's words, until a session opens
        # A request to show a bag was asked, and one shown far from before is asked again.
        self._requests_in_step = 0
        initial = "idle"
        if resumed is not None:
            self.session, self.plan, self.session_state = resumed
            self._use_script(session_script(self.session))
            step = self.session_state.step
            initial = step if step in STATES else "idle"
            if self.session_state.paused and initial in PAUSABLE:
                initial = "paused"
        self.machine = AsyncMachine(
            model=self,
            states=[
                {"name": name, "on_enter": "_entered", "on_exit": "_leaving"} for name in STATES
            ],
            transitions=bound_transitions(self._holds),
            initial=initial,
            queued=True,
            auto_transitions=False,
            ignore_invalid_triggers=True,
            model_attribute="stage",
        )

    # -- conditions -------------------------------------------------------------

    def _holds(self, name: str) -> bool:
        return self.conditions().holds(name)

    def conditions(self) -> Conditions:
        """The answers to the machine's conditions now."""
        state = self.session_state
        return Conditions(
            plays_names=self.settings.variant == "names",
            bags_taught=state is not None and state.bags_taught(self.settings),
            all_done=state is not None and state.all_done,
            # A paused or faulted step is the session's step: no second record of it; a
            # stopped session reopened goes back to the step it was stopped in.
            resume_step=_resume_step(state),
        )

    # -- the run loop -----------------------------------------------------------

    async def run(self) -> str:
        """Play until the session is finished or stopped; returns the final stage."""
        readers = [asyncio.create_task(self._read_keyfob(), name="keyfob reader")]
        if self.hw.researcher is not None and self.researcher.source == "device":
            readers.append(asyncio.create_task(self._read_researcher(), name="researcher reader"))
        # The HAL latches faults and takes the safe action itself; the game only has
        # to stop the step and say so, once per fault, including any latched already
        # (those stop the game before it begins: it never shows idle with them).
        self.hw.servos.on_fault(self._fault_latched)
        for fault in self.hw.servos.faults:
            if fault not in self._seen_faults:
                self._seen_faults.add(fault)
                self._startup_faults += (_servo_fault(fault),)
        self._set_keyfob_needs()
        try:
            try:
                await self._begin()
            except Exception as error:
                await self._survive(error, "starting the game")
            while self.stage not in ENDS:
                event = await self._inputs.get()
                try:
                    await self._handle(event)
                except Exception as error:
                    await self._survive(error, _describe(event))
            # No more keyfob events taken (they stay queued in the keyfob for the next
            # game); those already taken are still handled.
            await _cancelled(readers)
            await self._after_the_end()
            await self.speech.finish()  # what Kaspar says of the end is heard to its end
        finally:
            await self._cancel_step()
            await self.speech.close()
            self.hw.servos.off_fault(self._fault_latched)
            await _cancelled(readers)
        return self.stage

    @property
    def unwritten(self) -> list[tuple[Session | EventLog, Record, float]]:
        """The records the disk refused, still to write (for the next game to carry on)."""
        return list(self._unwritten)

    def flush_unwritten(self) -> int:
        """Write the records the disk refused, in order, as far as it takes them now.

        Returns how many are still unwritten (each is in the journal whole); for the
        daemon to try once more as the game ends, before its session is closed.
        """
        try:
            self._write_unwritten()
        except StorageFailed as error:
            log.error(
                "records not written; the journal holds them",
                count=len(self._unwritten),
                error=str(error),
            )
        return len(self._unwritten)

    async def _begin(self) -> None:
        if self.resumed:
            session = self._require_session()
            bind_context(session=session.id)
            trials = self._require_state().trials
            self._record(SessionRecord(event=SessionEvent.RESUMED, step=self.stage, trials=trials))
            self._emit(GameEvent.RESUMED, step=self.stage)
            await self.speech.announce("session.resumed")
        # What went wrong before the game began stops it before a step starts.
        for fault in self._startup_faults:
            await self._on_fault(fault)
        if self.stage not in ("paused", "fault"):
            await self._entered()

    async def _after_the_end(self) -> None:
        """What came while the session ended (a fault as Kaspar said goodbye) is still handled."""
        while not self._inputs.empty():
            event = self._inputs.get_nowait()
            if isinstance(event, StepEnded):
                continue
            try:
                await self._handle(event)
            except Exception as error:
                await self._survive(error, _describe(event))

    async def _survive(self, error: Exception, doing: str) -> None:
        """An error escaped while `doing` something: a fault like any other, never the end."""
        if isinstance(error, StorageFailed):
            fault = HardwareFault(FaultSource.STORAGE, str(error), error=error)
        else:
            log.error("software error", doing=doing, exc_info=error)
            fault = HardwareFault(
                FaultSource.SOFTWARE, f"{type(error).__name__}: {error} (while {doing})"
            )
        try:
            await self._on_fault(fault)
        except Exception as again:
            # Even saying so failed: the loop still goes on to the next input.
            log.critical("the fault could not be handled", fault=fault.detail, exc_info=again)

    async def _handle(self, event: GameInput) -> None:
        if isinstance(event, FromResearcher):
            await self._on_researcher_input(event.event)
        elif isinstance(event, Gesture):
            await self._on_gesture(event)
        elif isinstance(event, StepEnded):
            await self._on_step_ended(event)
        elif isinstance(event, HardwareFault):
            await self._on_fault(event)
        elif isinstance(event, KeyfobLost):
            await self._on_keyfob_lost(event)
        elif isinstance(event, KeyfobBack):
            self._record(HalRecord(event=HalEvent.KEYFOB_BACK, device=event.device))
            self._set_problem(FaultSource.KEYFOB, None)
            self._emit(GameEvent.KEYFOB_BACK)
            self.speech.announce_soon("fault.keyfob_back")

    async def _on_keyfob_lost(self, event: KeyfobLost) -> None:
        self._record(HalRecord(event=HalEvent.KEYFOB_LOST, reason=event.reason))
        if FaultSource.KEYFOB in self.problems and self.stage not in FAULTABLE:
            # Known already (not there at the start, and the reader says so too).
            self._set_problem(FaultSource.KEYFOB, event.reason)
            return
        await self._on_fault(HardwareFault(FaultSource.KEYFOB, event.reason))

    async def _read_keyfob(self) -> None:
        while True:
            await self._inputs.put(await self.hw.keyfob.next_event())

    async def _read_researcher(self) -> None:
        device = self.hw.researcher
        assert device is not None
        while True:
            await self._inputs.put(FromResearcher(await device.next_event()))

    # -- where the researcher's commands come from ---------------------------------

    def commands_on_keyfob(self) -> bool:
        """The researcher's commands are holds on the children's keyfob: there is no
        device of their own, or it is away."""
        source = self.researcher.source
        if source == "keyfob":
            return True
        if source == "keypad":
            return False
        device = self.hw.researcher
        return device is None or not device.connected

    def _set_keyfob_needs(self) -> None:
        if self.commands_on_keyfob():
            self.hw.keyfob.set_needs(gesture_needs(self.commands, self.researcher.hold_s))
        else:
            # Nothing the children do is a command: every key-down is a press, at once.
            self.hw.keyfob.set_needs(ANSWERS_ONLY)

    async def _on_researcher_input(self, event: InputEvent) -> None:
        if isinstance(event, KeyfobLost):
            self._record(HalRecord(event=HalEvent.RESEARCHER_LOST, reason=event.reason))
            first = FaultSource.RESEARCHER not in self.problems
            self._set_problem(FaultSource.RESEARCHER, f"researcher's device: {event.reason}")
            self._set_keyfob_needs()
            if first:
                self.speech.announce_soon("fault.researcher_lost")
            return
        if isinstance(event, KeyfobBack):
            self._record(HalRecord(event=HalEvent.RESEARCHER_BACK, device=event.device))
            self._set_problem(FaultSource.RESEARCHER, None)
            self._set_keyfob_needs()
            self.speech.announce_soon("fault.researcher_back")
            return
        if event.kind is GestureKind.COMMAND and event.button in tuple(Command):
            await self._on_command(Command(event.button), event.button, event.at, "researcher")
            return
        self._record(
            PressRecord(
                button=event.button, gesture=gesture_name(event), at=event.at, ignored="no command"
            )
        )

    def _fault_latched(self, fault: Fault) -> None:
        if fault not in self._seen_faults:
            self._seen_faults.add(fault)
            self._inputs.put_nowait(_servo_fault(fault))

    # -- gestures ---------------------------------------------------------------

    async def _on_gesture(self, gesture: Gesture) -> None:
        """A gesture of the children's keyfob: their answer, or (a hold, on one keyfob
        only, begun while nobody is asked) the researcher's command."""
        if gesture.kind is GestureKind.PRESS and gesture.button in ("green", "red"):
            self._child_press(gesture.button, gesture.at)
            return
        name = gesture_name(gesture)
        if gesture.kind is GestureKind.COMMAND:
            # An extra key of the children's keypad ([keyfob.commands]).
            if self.researcher.source == "keypad" and gesture.button in tuple(Command):
                await self._on_command(Command(gesture.button), name, gesture.at, "keypad")
            else:
                ignored = PressRecord(
                    button=gesture.button, gesture=name, at=gesture.at, ignored="no command"
                )
                self._record(ignored)
            return
        # A hold, a chord or a double: the children's, or the researcher's on one keyfob.
        button = gesture.first if gesture.kind is GestureKind.BOTH else gesture.button
        command = self.commands.get(name) if self.commands_on_keyfob() else None
        if command is None or self.presses.asking_at(gesture.at):
            self._child_gesture(button or "green", name, gesture.at)
            return
        await self._on_command(command, name, gesture.at, "keyfob")

    def _child_press(self, button: str, at: float) -> None:
        outcome = self.presses.press(button, at, self.stage, self._now())
        if outcome.record is not None:
            self._record(outcome.record)
        if outcome.acknowledge:
            self.speech.announce_soon("listen.wait")

    def _child_gesture(self, button: str, name: str, at: float) -> None:
        """A child's hold or squeeze: its first key-down is a press like any other (the
        answer, if one is awaited), and what it went on to be is recorded, never acted on."""
        answering = self.presses.waiting
        self._child_press(button, at)
        if answering and not self.presses.waiting:
            self._record(self.presses.extra(button, at, gesture=name))

    async def _on_command(self, command: Command, gesture: str, at: float, source: str) -> None:
        stage = self.stage
        state = self.session_state
        facts = Facts(
            self.conditions(),
            undo_available=state is not None and state.undo is not None,
            hardware_ready=self.hw.keyfob.connected,
            stopped_waiting=self.stopped_waiting is not None and self.session is None,
            reopen_available=(
                state is not None and recovery.reopen_record(state, self.settings) is not None
            ),
        )
        key = confirmation(stage, command, facts)
        given = CommandRecord(
            command=command, gesture=gesture, at=at, state=stage, applied=False, source=source
        )
        if key is None:
            self._record(msgspec.structs.replace(given, ignored="does not apply"))
            return
        if stage == "fault" and key is Confirmation.RESUME and not await self._rearm():
            self._record(msgspec.structs.replace(given, ignored="the hardware is still faulty"))
            self._emit(GameEvent.RESUME_REFUSED)
            await self.speech.announce("fault.problem")
            return
        applied = msgspec.structs.replace(given, applied=True, confirm=key)
        self.body.look_at(GazeKind.RESEARCHER, name="the researcher")
        if key is Confirmation.CLOSE:
            try:
                self._close_stopped(applied)
            except StorageFailed as error:
                await self._on_fault(HardwareFault(FaultSource.STORAGE, str(error), error=error))
                return
            await self.speech.announce("confirm.close")
            return
        opens_session = key is Confirmation.START and self.session is None
        try:
            if command is Command.PAUSE and state is not None:
                self._change(applied)  # sets session_state.paused
            elif key is Confirmation.STOP:
                self._record(applied)  # a stop never waits for the disk: safety first
            elif not opens_session:
                self._write(applied)  # record first: a command not on disk is not applied
        except StorageFailed as error:
            if stage == "fault":
                self._emit(GameEvent.RESUME_REFUSED)
            await self._on_fault(HardwareFault(FaultSource.STORAGE, str(error), error=error))
            return
        if stage == "fault" and key is Confirmation.RESUME:
            self._set_problem(FaultSource.SOFTWARE, None)  # the researcher carries on
        # Kaspar confirms before what the command starts, and after what it stops.
        if key in SPOKEN_FIRST:
            await self.speech.announce(f"confirm.{key}")
        await self._fire(key)
        if opens_session:
            self._write(applied)  # "start" opens the session: its command is its first record
        if key is Confirmation.STOP:
            self.body.cancel()
            # To rest at once, saying goodbye on the way: safety does not wait for words,
            # and a line that fails does not keep Kaspar from resting.
            outcomes = await asyncio.gather(
                self.speech.announce(f"confirm.{key}"), self._rest_safely(), return_exceptions=True
            )
            for outcome in outcomes:
                if isinstance(outcome, BaseException):
                    raise outcome
        elif key not in SPOKEN_FIRST and key not in SILENT:
            await self.speech.announce(f"confirm.{key}")

    async def _fire(self, key: Confirmation) -> None:
        if key is Confirmation.UNDO:
            await self._undo()
            return
        if key is Confirmation.REOPEN:
            await self._reopen()
            return
        if key is Confirmation.START and self.session is None:
            if self.stopped_waiting is not None:
                await self._reopen_stopped()
                await self.trigger("reopen")
                return
            # A session resumed before its first step has one already.
            await self._start_session()
        await self.trigger(TRIGGERS[key])

    async def _reopen_stopped(self) -> None:
        """The stopped session carries on: its step again, from where it was stopped."""
        assert self.stopped_waiting is not None
        session, plan, state = self.stopped_waiting
        self.stopped_waiting = None
        self.session, self.plan, self.session_state = session, plan, state
        self._use_script(session_script(session))
        bind_context(session=session.id)
        self._record(
            SessionRecord(event=SessionEvent.RESUMED, step=_resume_step(state), trials=state.trials)
        )
        self._emit(GameEvent.SESSION, session=session.id)
        # The children may be new to Kaspar today: the greeting first, as at any start.
        await asyncio.gather(self.speech.announce("session.greeting"), self.body.perform(GREETING))

    def _close_stopped(self, command: CommandRecord) -> None:
        """The stopped session is closed for good: its plan is done."""
        assert self.stopped_waiting is not None
        session = self.stopped_waiting[0]
        self.stopped_waiting = None
        session.record(command, self._now())
        session.record(SessionRecord(event=SessionEvent.CLOSED), self._now())
        session.close()

    def _use_script(self, chosen: Script) -> None:
        self.script = chosen
        self.picker.fixed = chosen.fixed

    async def _rest_safely(self) -> None:
        try:
            await self.hw.servos.rest()
        except HalError as error:
            self._record(
                FaultRecord(
                    fault=FaultSource.SERVO, detail=f"rest after stop: {error}", state=self.stage
                )
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
                FaultRecord(
                    fault=FaultSource.SERVO, detail=f"resume refused: {error}", state=self.stage
                )
            )
            return False
        self._set_problem(FaultSource.SERVO, None)
        return True

    async def _start_session(self) -> None:
        session, plan, state = self._open_session()
        try:
            session.record(SessionRecord(event=SessionEvent.START, plan=session.plan), self._now())
        except StorageFailed:
            # A session without its start record is no session: gone, and the next
            # long green opens a new one once the disk takes records again.
            session.close()
            shutil.rmtree(session.directory, ignore_errors=True)
            raise
        self.session, self.plan, self.session_state = session, plan, state
        self._use_script(session_script(session))
        bind_context(session=session.id)
        self._set_problem(FaultSource.STORAGE, None)
        self._emit(GameEvent.SESSION, session=session.id)

    # -- entering and leaving states -------------------------------------------

    async def _entered(self) -> None:
        stage = self.stage
        if stage != "fault":
            self._said_in_fault = set()  # what was said about the last stop is no news now
        bind_context(step=stage)
        self._emit(GameEvent.STATE, state=stage)
        # Life in every stage but a fault and the end (teaching and pointing say so too).
        self.body.set_alive(stage not in ("fault", *ENDS))
        state = self.session_state
        if stage in ENDS:
            # The session ends whatever the disk says: a stop must never wait for it.
            try:
                if state is not None and state.step != stage:
                    self._change(StepRecord(to=stage))
                if self.session is not None and state is not None:
                    self.session.save_state(state, finished=True)
            except StorageFailed as error:
                self._storage_failed(error)
            return
        if state is not None and stage in STEPS and state.step != stage:
            self._change(StepRecord(to=stage))  # a step not on disk is not entered
        if stage in STEPS:
            self._start_step(stage)
        elif stage == "idle":
            self._emit(GameEvent.WAITING_FOR_RESEARCHER, step="idle")

    async def _leaving(self) -> None:
        await self._cancel_step()

    def _start_step(self, step: str) -> None:
        self._requests_in_step = 0
        runners: dict[str, Callable[[], Coroutine[Any, Any, None]]] = {
            "placing": self._step_placing,
            "teaching": self._step_teaching,
            "revealing": self._step_revealing,
            "guessing": self._step_guessing,
            "farewell": self._step_farewell,
        }
        task = asyncio.create_task(runners[step](), name=f"step {step}")
        self._step_task = task

        def ended(done: asyncio.Task[None]) -> None:
            if not done.cancelled():
                self._inputs.put_nowait(StepEnded(step, done.exception()))

        task.add_done_callback(ended)

    async def _cancel_step(self) -> None:
        task, self._step_task = self._step_task, None
        if task is not None and not task.done():
            self.speech.cut()
            self.body.cancel()
            # wait(), not `await task`: the step's own CancelledError stays inside it,
            # while a cancellation of this task (the daemon stopping) still gets through.
            # Again and again: a library that swallowed the cancellation (as wait_for can
            # on 3.11) must not leave the game waiting for ever, deaf to every gesture.
            while True:
                task.cancel()
                done, _ = await asyncio.wait({task}, timeout=STEP_CANCEL_GRACE_S)
                if done:
                    break
                log.warning(
                    "a step carried on after being cancelled; cancelling again",
                    step=task.get_name(),
                )
        self.presses.close(self._now())

    async def _on_step_ended(self, event: StepEnded) -> None:
        if event.step != self.stage:
            return
        error = event.error
        if error is None:
            await self.advance()
        elif isinstance(error, VoiceFailed):
            await self._on_fault(HardwareFault(FaultSource.VOICE, str(error)))
        elif isinstance(error, StorageFailed):
            await self._on_fault(HardwareFault(FaultSource.STORAGE, str(error), error=error))
        elif isinstance(error, HalError):
            await self._on_fault(HardwareFault(FaultSource.SERVO, str(error)))
        else:
            log.error("step failed", step=event.step, exc_info=error)
            detail = f"{event.step}: {error!r}"
            await self._on_fault(HardwareFault(FaultSource.SOFTWARE, detail))

    async def _on_fault(self, fault: HardwareFault) -> None:
        """Record, log, show and say a fault; stop the running step where the kind stops it."""
        stage = self.stage
        self.body.cancel()  # whatever Kaspar's body was doing ends at once, safely
        if fault.kind is FaultSource.STORAGE:
            self._storage_fault_queued = False
            if isinstance(fault.error, StorageFailed):
                self._storage_failed_in_event_log = fault.error.in_event_log
        # Known before it is recorded: a record that fails for the same disk is not a new fault.
        self._set_problem(fault.kind, _problem(fault), logged=True)
        self._record(
            FaultRecord(fault=fault.kind, detail=fault.detail, joint=fault.joint, state=stage)
        )
        say = log.warning if fault.kind is FaultSource.KEYFOB else log.error
        say("fault", fault=fault.kind.value, detail=fault.detail, joint=fault.joint, state=stage)
        if stage == "fault":
            # Said once per stop and kind: an unplugged bus latches every joint on it, and
            # six announcements would keep the researcher's resume waiting for half a minute.
            if fault.kind in self._said_in_fault:
                return
        elif stage in STOPPED_BY[fault.kind]:
            await self.fail()
            self._said_in_fault = set()
            self._emit(GameEvent.FAULT, kind=fault.kind, detail=fault.detail)
        self._said_in_fault.add(fault.kind)
        # Said while the game goes on listening: the keyfob coming back, the researcher's
        # resume or stop are heard before the line ends.
        # Words for the children; the joint, the bus and the reason are in the record,
        # the journal and STATUS=.
        if fault.kind is FaultSource.SERVO:
            self.speech.announce_soon("fault.servo")
        elif fault.kind is FaultSource.KEYFOB:
            self.speech.announce_soon("fault.keyfob_lost")
        elif fault.kind is FaultSource.STORAGE:
            self.speech.announce_soon("fault.storage")
        else:
            self.speech.announce_soon("fault.problem")

    def _set_problem(self, kind: FaultSource, detail: str | None, logged: bool = False) -> None:
        """`kind` is not working (`detail` says why), or works again (None); listeners are told.

        A new problem is logged (at warning for the keyfob, error for the rest) unless
        the caller logs it (`logged`); one that clears is logged at info.
        """
        before = self.problems.get(kind)
        if detail == before:
            return
        if detail is None:
            del self.problems[kind]
            log.info("working again", part=kind.value)
        else:
            self.problems[kind] = detail
            if before is None and not logged:
                say = log.warning if kind is FaultSource.KEYFOB else log.error
                say("not working", part=kind.value, detail=detail)
        self._emit(GameEvent.PROBLEMS, problems=dict(self.problems))

    def _voice_health(self, failing: str | None) -> None:
        self._set_problem(FaultSource.VOICE, failing)

    def note_shutdown(self, reason: str) -> None:
        """The daemon is stopping: the session stays unfinished, to be resumed at the next start."""
        self._record(SessionRecord(event=SessionEvent.SHUTDOWN, reason=reason, state=self.stage))

    # -- the steps --------------------------------------------------------------

    async def _step_placing(self) -> None:
        # The greeting first: the researcher's start has no words of its own.
        await self._greet()
        await self.speech.say("steps.place_bags", bags=str(len(self.settings.targets)))
        await self._wait_for_researcher("placing")

    async def _step_revealing(self) -> None:
        await self.speech.say("steps.reveal_toys")
        await self._wait_for_researcher("revealing")

    async def _wait_for_researcher(self, step: str) -> None:
        """Wait for the researcher's "next"; after a long quiet, say once that Kaspar is ready."""
        self._emit(GameEvent.WAITING_FOR_RESEARCHER, step=step)
        delay = self.settings.step_prompt_after_s
        await asyncio.sleep(delay)
        self._record(PromptRecord(line="steps.ready", waited=delay))
        self._emit(GameEvent.PROMPT, line="steps.ready")
        await self.speech.say("steps.ready")
        await asyncio.Event().wait()  # the researcher's "next" moves on

    async def _step_teaching(self) -> None:
        state = self._require_state()
        group = self.settings.pointing_group
        if state.teach_round == 0 and state.teach_bag == 0:
            await self.speech.say("steps.teach_pointing")
            await self.speech.say("instructions.teach")
        self.body.set_alive(False)  # no gaze or idle while the children move the arm
        await self.hw.servos.set_compliant(group, True)
        try:
            while state.teach_round < self._group_size():
                await self._teach_one_bag(state.teach_bag, state.teach_round, group)
        finally:
            self.body.set_alive(True)
            # Torque back on holding where the arm is, also on pause or fault. If the
            # arm was left outside its safe range this fails, and the step fails
            # into the fault state: the researcher moves the arm back and resumes.
            await asyncio.shield(self.hw.servos.set_compliant(group, False))
        await self.speech.say("teach.all_done")

    def roles(self, teach_round: int) -> tuple[str, str]:
        """Who moves the arm and who presses in a round of step 2: every child does each
        job once over the rounds (one round per child); a child alone does both."""
        size = self._group_size()
        return self._child_name(teach_round % size), self._child_name((teach_round + 1) % size)

    async def _say_roles(self, teach_round: int) -> None:
        mover, presser = self.roles(teach_round)
        if mover == presser:
            await self.speech.say("teach.roles_alone", mover=mover)
        else:
            await self.speech.say("teach.roles", mover=mover, presser=presser)

    async def _teach_one_bag(self, bag: int, teach_round: int, group: str) -> None:
        """Ask for one bag's pose until a child shows it; a pose far from where the bag
        was shown before is asked for once more (both count for the median)."""
        mover, presser = self.roles(teach_round)
        number = str(bag + 1)
        checked = False
        retry: str | None = None
        while True:
            opened = self.presses.open(self._now())
            self._emit(
                GameEvent.ASKING, bag=bag, round=teach_round, mover=mover, presser=presser
            )
            if retry is not None:
                await self.speech.say(retry, bag=number)
            elif self._requests_in_step == 0 or bag == 0:
                # A round's first request (or the first after a pause) says who does what.
                if bag == 0 and teach_round > 0:
                    await self.speech.say("teach.swap")
                await self._say_roles(teach_round)
                await self.speech.say("teach.bag_first", bag=number)
            else:
                await self.speech.say("teach.bag", bag=number)
            self._requests_in_step += 1
            self.presses.asked(self._now())
            self._emit(GameEvent.TEACH, bag=bag, round=teach_round, mover=mover, presser=presser)
            button, at = await self._wait_with_prompts(
                opened,
                (
                    ("prompt.teach", {"presser": presser, "bag": number}),
                    ("instructions.teach", {}),
                    ("prompt.ask_researcher", {}),
                ),
            )
            self.presses.answered(at, None)
            if button != "green":
                self._record(PressRecord(button=button, at=at, teach_retry=bag))
                retry = "teach.try_again"
                continue
            pose = await self.hw.servos.read_positions(group)
            outside = self._outside_safe_range(pose)
            if outside:
                # Kaspar could never point there: ask again rather than log it.
                self._record(PressRecord(button=button, at=at, teach_retry=bag, outside=outside))
                retry = "teach.out_of_reach"
                continue
            state = self._require_state()
            shown = _shown(state, self.settings.targets[bag])
            far = not checked and bool(far_from(pose, shown, self.settings.pose_check_deg))
            self._change(
                PoseRecord(
                    bag=bag,
                    round=teach_round,
                    pose=pose,
                    at=at,
                    rule="median",
                    mover=mover,
                    presser=presser,
                    check_again=True if far else UNSET,
                )
            )
            if far:
                checked, retry = True, "teach.check_again"
                continue
            if bag == 0 and teach_round == 0:
                await self.speech.say("teach.logged_first", bag=number)
            else:
                await self.speech.say("teach.logged")
            return

    def _outside_safe_range(self, pose: dict[str, float]) -> list[str]:
        ranges = {joint.name: joint.range_deg for joint in self.config.servos.joints}
        return [
            name
            for name, degrees in pose.items()
            if name in ranges and not ranges[name][0] <= degrees <= ranges[name][1]
        ]

    async def _step_guessing(self) -> None:
        state = self._require_state()
        if state.trials == 0:
            if self.settings.variant == "pilot":
                # The pilot starts here: the greeting first.
                await self._greet()
                await self.speech.say("steps.pilot")
            else:
                await self.speech.say("steps.guessing")
            await self.speech.say("instructions.buttons")
        while not state.all_done:
            await self._one_trial(state)

    async def _step_farewell(self) -> None:
        state = self._require_state()
        if all(p.learned is not None for p in state.progress):
            pilot = self.settings.variant == "pilot"
            await self.speech.say("react.all_learned_pilot" if pilot else "react.all_learned")
        await asyncio.gather(self.speech.say("session.thanks"), self.body.perform(FAREWELL))
        await self.hw.servos.rest()

    async def _greet(self) -> None:
        """Hello, said and shown together."""
        await asyncio.gather(self.speech.say("session.greeting"), self.body.perform(GREETING))

    # -- one guess --------------------------------------------------------------

    async def _one_trial(self, state: GameState) -> None:
        """Ask, wait for the answer, record it (kasparctl.game.trial does the arithmetic), react."""
        session_plan = self._require_plan()
        params = self.config.profile(session_plan.profile)
        group_size = self._group_size()
        book = self.speech.book
        plan = plan_trial(state, params, self.settings, session_plan, group_size, book, self.script)
        bind_context(trial=plan.trial, target=plan.target_name)
        self._record(question_record(plan))  # history only: the open question, for readers
        # From here a press is early, until the guess itself is said.
        answer = self.presses.open(self._now())
        self.body.look_at(GazeKind.CHILD, plan.child_index, plan.child)
        self._emit(
            GameEvent.ASKING,
            target=plan.target,
            choice=plan.choice,
            trial=plan.trial,
            child=plan.child,
        )
        if group_size > 1 and state.turn < group_size:
            await self.speech.say("turn.first", child=plan.child)  # each child's first turn
        spoken = await self._ask(plan)
        self.presses.asked(self._now())
        self._emit(
            GameEvent.QUESTION,
            target=plan.target,
            choice=plan.choice,
            trial=plan.trial,
            child=plan.child,
        )
        listened = await self._listen() if self.presses.waiting else None
        button, pressed_at = await self._wait_with_prompts(
            answer,
            (
                ("instructions.buttons", {}),
                ("prompt.answer_again", {"child": plan.child}),
                ("prompt.ask_researcher", {}),
            ),
        )
        question_end = self.presses.question_end
        heard = Answer(
            spoken, question_end, cast(Button, button), pressed_at, pressed_at < question_end
        )
        planned_with = "recovery" in self._require_session().plan
        scored = score_answer(
            plan, heard, state, params, self.settings, session_plan, recovery=planned_with
        )
        record = self._change(scored)
        self.presses.answered(pressed_at, record.trial)
        self._emit(GameEvent.ANSWERED, trial=record.trial, feedback=button)
        confused = self._notice(record)
        await self._react(plan, record.green, record.learned, listened)
        if state.progress[plan.target].given_up:
            await self.speech.say("react.given_up")
        if confused is not None:
            await self._say_confused(confused)

    def _notice(self, record: TrialRecord) -> ConfusedRecord | None:
        """What the answer showed the researcher should know (kasparctl.game.recovery):
        a right toy no longer offered, and whether Kaspar is confused; recorded."""
        state, key = self._require_state(), self._require_plan().answer_key
        for alert in recovery.alerts(state, record, self.settings, key):
            self._record(alert)
            self._emit(GameEvent.ALERT, target=alert.target, toy=alert.toy)
        confused = recovery.confusion(state, record, self.settings)
        if confused is None:
            return None
        return self._change(confused)

    async def _say_confused(self, confused: ConfusedRecord) -> None:
        """Said once; the researcher is told (GameEvent.CONFUSED) once Kaspar has asked."""
        if confused.reason == recovery.LEARNED_ELSEWHERE and isinstance(confused.name, str):
            await self.speech.say("recovery.confused_learned", toy=confused.name)
        else:
            await self.speech.say("recovery.confused")
        if confused.reopen_name is not None:
            await self.speech.say("recovery.ask_researcher")
        state = self._require_state()
        learned = [(t, state.progress[t].learned) for t in state.learned_targets()]
        self._emit(
            GameEvent.CONFUSED,
            target=confused.target_index,
            reason=confused.reason,
            learned=learned,
            reopen=confused.reopen_name,
        )

    async def _ask(self, plan: TrialPlan) -> tuple[str, ...]:
        """Point while saying how sure (if the plan says it), then the guess; the lines said.

        From the guess on, a press is the answer: it is the question's last words.
        """
        spoken: list[str] = []
        key = plan.uncertainty_line
        strength = self.body.strength(plan.entropy, len(plan.candidates))
        style = point_style(strength)
        if key is not None:
            said, _ = await asyncio.gather(
                self.speech.say(key), self._think_and_point(plan, strength, style)
            )
            spoken.append(said)
        else:
            await self._think_and_point(plan, strength, style)
        self.presses.last_words(self._now())
        self.body.look_at(GazeKind.CHILD, plan.child_index, plan.child)
        if self.settings.variant == "pilot":
            guess = self.speech.say(
                "guess.pilot", child=plan.child, toy=plan.toy, where=self._where(plan)
            )
        else:
            guess = self.speech.say("guess.names", child=plan.child, toy=plan.toy)
        if style.nod:
            # Sure: a nod as it asks.
            said, _ = await asyncio.gather(guess, self.body.perform(NOD, 1.0 - (strength or 0.0)))
            spoken.append(said)
        else:
            spoken.append(await guess)
        return tuple(spoken)

    async def _think_and_point(
        self, plan: TrialPlan, strength: float | None, style: PointStyle
    ) -> None:
        """Thinking first, as hard as Kaspar is unsure, where the body shows it; then the point."""
        if strength is not None:
            await self.body.perform(THINKING, strength)
        await self._point_at(plan.target_name, plan.target, style)

    def _where(self, plan: TrialPlan) -> str:
        """How the pilot location of `plan` is said in a sentence ("on the shelf")."""
        location = plan.target_name
        phrase = self.settings.location_phrases.get(location)
        return phrase or self.speech.book.fill("names.where", location=location)

    def _child_name(self, index: int) -> str:
        children = self._require_plan().children
        if children:
            return children[index]
        return self.speech.book.fill("names.child", number=str(index + 1))

    async def _undo(self) -> bool:
        state = self._require_state()
        if state.undo is None:
            return False
        back = recovery.taken_back(state, self.settings)  # the last was a re-open
        await self._cancel_step()
        self._change(back if back is not None else UndoRecord(trial=state.undo.trial))
        self.presses.forget_answer()
        self._start_step("guessing")
        return True

    async def _reopen(self) -> bool:
        """The name learned last is learned no more; Kaspar says so and asks on."""
        state = self._require_state()
        record = recovery.reopen_record(state, self.settings)
        if record is None:
            return False
        await self._cancel_step()
        self._change(record)
        self._emit(GameEvent.REOPENED, target=record.target_index, name=record.name_index)
        await self.speech.announce("confirm.reopen", toy=record.name)
        self._start_step("guessing")
        return True

    async def _react(
        self, plan: TrialPlan, green: bool, learned: bool, listened: dict[str, float] | None
    ) -> None:
        """What the answer means, in words that agree with the learned rule, and the face."""
        pilot = self.settings.variant == "pilot"
        if green and learned:
            key = "react.learned"
        elif green:
            key = "react.right_check"
        else:
            key = "react.wrong"
        values = {"toy": plan.toy}
        if pilot:
            key += "_pilot"
            values["where"] = self._where(plan)
        expression = self.settings.happy_pose if green else self.settings.sad_pose
        # Face and words together; gather cancels both with the step and retrieves a
        # servo error from either, so none is left unheard.
        await asyncio.gather(
            self.speech.say(key, **values),
            self._face(listened, dict(expression), HAPPY if green else SAD),
        )

    async def _face(
        self, listened: dict[str, float] | None, expression: dict[str, float], behaviour: str
    ) -> None:
        """Back from listening, then the body's behaviour; without a body, the expression
        pose (held briefly, then undone)."""
        if listened:
            await self.hw.servos.move(listened, duration=LISTEN_MOVE_S)
        if expression and self.body.fallback:
            await self._express(expression)
            return
        # The behaviour goes on while the game does: the next question must not wait for
        # the end of a smile (the body's own loop plays it; a move or a cancel ends it).
        shown = asyncio.ensure_future(self.body.perform(behaviour))
        self._showing.add(shown)
        shown.add_done_callback(self._showing.discard)

    async def _express(self, pose: dict[str, float]) -> None:
        before = await self.hw.servos.read_positions()
        await self.hw.servos.move(pose, duration=0.6)
        await self.hw.servos.move({joint: before[joint] for joint in pose}, duration=0.6)

    async def _listen(self) -> dict[str, float] | None:
        """Show that Kaspar listens: its listening pose and sound, where configured.

        Returns where the posed joints were, to go back to once answered.
        """
        self._emit(GameEvent.LISTENING)
        if LISTENING_SOUND in self.config.voice.clips:
            self.speech.sound_soon(LISTENING_SOUND)
        pose = self.settings.listening_pose
        if not pose:
            return None
        before = await self.hw.servos.read_positions()
        await self.hw.servos.move(dict(pose), duration=LISTEN_MOVE_S)
        return {joint: before[joint] for joint in pose if joint in before}

    async def _point_at(
        self, target_name: str, target: int, style: PointStyle = PLAIN_POINT
    ) -> None:
        state = self._require_state()
        pose = state.poses.get(target_name) or self.settings.poses.get(target_name)
        if pose:
            self._emit(GameEvent.POINT, target=target_name, style=style.words)
            self.body.look_at(GazeKind.BAG, target, target_name)
            self.body.set_alive(False)  # the head stays on the bag while the arm moves
            try:
                await point(self.hw.servos, pose, style)
            finally:
                self.body.set_alive(True)

    # -- waiting for children ---------------------------------------------------

    async def _wait_with_prompts(
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
                self.presses.hand_to_researcher(self._now())
            self._record(PromptRecord(line=key, waited=delay))
            self._emit(GameEvent.PROMPT, line=key)
            await self.speech.say(key, **values)
        return await answer

    # -- speaking, recording ----------------------------------------------------

    def _write(self, record: RecordT) -> RecordT | None:
        """Record first, or not at all: to the session, or the event log when none is open.

        StorageFailed when it cannot be written (records kept from an earlier failure
        are written first, in order). None only when there is nowhere to write.
        """
        target: Session | EventLog | None = self.session or self.event_log
        if target is None:
            log.info("not recorded: no session is open", record=repr(record))
            return None
        self._write_unwritten()
        written = target.record(record, self._now())
        # Writing works again, where it failed: a session's files show it for both, the
        # event log only for itself (sessions/ can be broken while the log is not).
        if isinstance(target, Session) or self._storage_failed_in_event_log:
            self._set_problem(FaultSource.STORAGE, None)
        return written

    def _write_unwritten(self) -> None:
        while self._unwritten:
            kept_target, kept, at = self._unwritten[0]
            kept_target.record(kept, at)
            self._unwritten.pop(0)

    def _record(self, record: RecordT) -> RecordT | None:
        """Record history (a fault, an ignored press): never raises. One the disk refuses is
        kept to write later, logged whole, and stops the game (a storage fault)."""
        target: Session | EventLog | None = self.session or self.event_log
        try:
            return self._write(record)
        except StorageFailed as error:
            if target is not None and len(self._unwritten) < UNWRITTEN_LIMIT:
                self._unwritten.append((target, record, self._now()))
            # The journal keeps what the disk could not, whole.
            log.error("record not written", error=str(error), record=_plain(record))
            self._storage_failed(error)
            return None

    def _storage_failed(self, error: StorageFailed) -> None:
        """A write failed where nothing else stops for it: a storage fault, once per stop."""
        self._storage_failed_in_event_log = error.in_event_log
        self._set_problem(FaultSource.STORAGE, str(error), logged=True)
        # Once per stop: in the fault stage, or once the session is over, it is said once.
        said = FaultSource.STORAGE in self._said_in_fault and self.stage in ("fault", *ENDS)
        if not (said or self._storage_fault_queued):
            self._storage_fault_queued = True
            self._inputs.put_nowait(HardwareFault(FaultSource.STORAGE, str(error), error=error))

    def _change(self, record: RecordT) -> RecordT:
        """Record, apply, snapshot: the order that makes a crash lose nothing.

        StorageFailed when the record cannot be written (nothing is applied) or the
        snapshot cannot (the record is on disk and applied: a resume replays it).
        """
        session, state = self._require_session(), self._require_state()
        written = self._write(record)
        assert written is not None  # a session is open
        state.apply(written, self.settings)
        session.save_state(state)
        return written

    def _emit(self, event: GameEvent, **info: Any) -> None:
        for listener in self.listeners:
            try:
                listener(event, info)
            except Exception as error:
                # A listener (the daemon's status, a narrator) must never stop the game.
                log.error("a game listener failed", game_event=event.value, exc_info=error)

    def _now(self) -> float:
        return asyncio.get_running_loop().time()

    def _group_size(self) -> int:
        return self.config.group_size(self._require_plan())

    def _require_session(self) -> Session:
        if self.session is None:
            raise RuntimeError("no session is open")
        return self.session

    def _require_state(self) -> GameState:
        if self.session_state is None:
            raise RuntimeError("no session is open")
        return self.session_state

    def _require_plan(self) -> SessionPlan:
        if self.plan is None:
            raise RuntimeError("no session is open")
        return self.plan


async def _cancelled(tasks: list[asyncio.Task[None]]) -> None:
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


def _describe(event: GameInput) -> str:
    """What the run loop was handling, in words, for a fault's detail."""
    if isinstance(event, Gesture):
        return f"handling {gesture_name(event)}"
    if isinstance(event, StepEnded):
        return f"ending the step {event.step}"
    if isinstance(event, HardwareFault):
        return f"handling a {event.kind.value} fault"
    return f"handling the keyfob {'lost' if isinstance(event, KeyfobLost) else 'back'}"


def _resume_step(state: GameState | None) -> str:
    """Where a resume (or a reopen) returns to: the session's step, or the one it stopped in."""
    if state is None:
        return "idle"
    if state.step == "stopped" and isinstance(state.stopped_from, str):
        return state.stopped_from
    return state.step


def _shown(state: GameState, target: str) -> list[dict[str, float]]:
    """Every pose shown for `target` so far (under the median rule)."""
    shown = state.shown_poses
    return [] if isinstance(shown, msgspec.UnsetType) else list(shown.get(target, []))


def _servo_fault(fault: Fault) -> HardwareFault:
    return HardwareFault(FaultSource.SERVO, f"{fault.kind.value}: {fault.detail}", fault.joint)


def _problem(fault: HardwareFault) -> str:
    """A fault as the problem it leaves: the joint first, where there is one."""
    return f"{fault.joint}: {fault.detail}" if fault.joint else fault.detail


def _plain(record: Record) -> dict[str, Any] | str:
    try:
        return record_to_plain(cast(Any, record))
    except (TypeError, ValueError):
        return repr(record)
