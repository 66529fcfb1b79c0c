"""The children-as-teachers game: the paper's five steps as a transitions AsyncMachine.

One task, `Game.run`, owns the game: it takes one input at a time (a keyfob
gesture, a step that finished, a hardware fault: kasparctl.game.inputs) and fires
the machine's triggers. What a step does (speak, point, wait for a child:
kasparctl.game.steps) runs as a step task started when the step is entered and
cancelled when it is left, so a pause or a fault stops Kaspar mid-sentence and a
resume starts the step again from the saved state. Transitions are fired only by
`run`, never from inside a step task, so a step never cancels itself.

Every change is a record first (fsynced), then applied to GameState, then
snapshotted (kasparctl.game.recorder); only then does Kaspar react. The game sees
the hardware only through the hal interfaces, and the learner never sees the
answer key.

Kaspar listens when it has asked (kasparctl.game.presses): a child's press is
an answer from the question's last words on, an early press is acknowledged,
and the children's keyfob carries nothing but answers when the researcher's
commands come from a device of their own (the default). On a robot with one
keyfob the researcher's commands are holds begun while Kaspar asks the
children nothing; so are they while the researcher's own device is away
(kasparctl.game.routing decides whose each gesture is).

Faults, in every stage: a part that fails (a servo, the bus, the keyfob, the
voice, the disk) or a bug (an error in a step, or in handling an input) is
recorded (in the session, or in the daemon's event log when none is open),
logged at its level, kept in `problems` (the daemon's STATUS= shows them) and
said where the voice still works; a running step stops (the fault stage), and
the researcher's resume or stop still work. Nothing the run loop does can end
it but the end of the session: an error while handling an input is itself a
fault. A lost keyfob stops only a running step: in idle or paused there is
nothing to stop, and a keyfob plugged in late starts the session at once.

What outlives one game (the recorder with the records the disk refused, and the
problems) is made once by the daemon and handed to each game (`Lasting`).

The rules live beside this module, pure: the machine's table (stages), which
researcher command applies where (researcher), one guess's arithmetic (trial)
and the records (records); the Game listens, decides and starts the steps.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import msgspec
import structlog
from msgspec import UNSET
from transitions.extensions.asyncio import AsyncMachine

from hal import Hardware
from hal.errors import HalError
from hal.keyfob.api import InputEvent, KeyfobBack, KeyfobLost
from hal.keyfob.gestures import Gesture
from hal.servos.api import Fault
from kasparctl.body.api import Body, GazeKind
from kasparctl.config import Config, SessionPlan, SessionSettings, resolve_session
from kasparctl.game import recovery, rotation
from kasparctl.game.battery import BatteryWatch
from kasparctl.game.bodywork import GREETING, BodyWork
from kasparctl.game.buttons import ButtonCheck
from kasparctl.game.context import StepContext
from kasparctl.game.events import GameEvent, Listener
from kasparctl.game.faults import (
    STOPPED_BY,
    HardwareFault,
    Problems,
    error_fault,
    servo_fault,
    step_fault,
    storage_fault,
)
from kasparctl.game.guess import LISTENING_SOUND
from kasparctl.game.inputs import FromResearcher, GameInput, Inputs, StepEnded, describe
from kasparctl.game.language import phrasebook_for
from kasparctl.game.opening import OpenedSession, PlanQueue, session_script
from kasparctl.game.phrases import PhrasePicker
from kasparctl.game.presses import ChildPresses
from kasparctl.game.recorder import Recorder, loop_time
from kasparctl.game.records import (
    CommandRecord,
    Confirmation,
    FaultRecord,
    FaultSource,
    HalEvent,
    HalRecord,
    PressRecord,
    Record,
    RotationRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    UndoRecord,
)
from kasparctl.game.researcher import SILENT, SPOKEN_FIRST, TRIGGERS, Facts, confirmation
from kasparctl.game.routing import (
    ChildGesture,
    ChildPress,
    HeldPress,
    ResearcherCommand,
    Routed,
    Router,
)
from kasparctl.game.scripts import Script, script
from kasparctl.game.session import EventLog, Session
from kasparctl.game.speech import Speech
from kasparctl.game.stages import (
    ENDS,
    FAULTABLE,
    PAUSABLE,
    STATES,
    STEPS,
    Conditions,
    bound_transitions,
)
from kasparctl.game.state import GameState
from kasparctl.game.steps import Steps
from kasparctl.game.storage import StorageFailed, remove_tree
from kasparctl.game.wallclock import ClockWatch, clock_record
from kasparctl.log import bind_context
from kasparctl.vocabulary import Command

log = structlog.get_logger(__name__)

# The phrase key whose clip ([voice.clips]) chimes when the researcher chooses in idle.
CHOSEN_SOUND = "cue.chosen"
# How long a cancelled step may take to end before it is cancelled again.
STEP_CANCEL_GRACE_S = 1.0

RecordT = TypeVar("RecordT", bound=Record)


@dataclass(frozen=True, slots=True)
class Setup:
    """What a game plays with: the configuration, the hardware, the phrase picker, and
    Kaspar's body (None: a StillBody, and the game's own happy and sad poses)."""

    config: Config
    hardware: Hardware
    picker: PhrasePicker
    body: Body | None = None


@dataclass(frozen=True, slots=True)
class Lasting:
    """What outlives one game, made once and handed to each: the recorder (and the
    records the disk refused), the problems, and how a new session is opened."""

    recorder: Recorder
    problems: Problems
    open_session: Callable[[], OpenedSession]
    # Whether the battery is known to be low: said once per fall, whatever the session.
    battery: BatteryWatch = field(default_factory=BatteryWatch)
    # The planned sessions the researcher chooses from in idle (None: nothing to choose).
    queue: PlanQueue | None = None
    # The wall clock watched (the daemon's): its state recorded at each session's start
    # and each jump; None where nothing watches it (the demo, on a simulated clock).
    clock: ClockWatch | None = None

    @classmethod
    def new(
        cls,
        event_log: EventLog | None,
        open_session: Callable[[], OpenedSession],
        queue: PlanQueue | None = None,
        clock: ClockWatch | None = None,
    ) -> Lasting:
        """No problems yet; records go to `event_log` while no session is open (with none,
        they are only logged)."""
        problems = Problems()
        return cls(
            Recorder(event_log, problems), problems, open_session, queue=queue, clock=clock
        )


@dataclass(frozen=True, slots=True)
class Start:
    """Where a game begins.

    `resumed` is a session to carry on; `stopped` a session the researcher stopped and
    has not closed (in idle their "next" reopens it where it stopped, their "stop"
    closes it for good). `faults` happened before the game (a servo that did not
    start, sessions that could not be read): the game begins by stopping for them.
    """

    resumed: OpenedSession | None = None
    stopped: OpenedSession | None = None
    faults: Sequence[HardwareFault] = ()


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

    def __init__(self, setup: Setup, lasting: Lasting, start: Start | None = None) -> None:
        """A game that opens its session with `lasting.open_session` at the start, or
        carries on where `start` says.

        Its records go through `lasting.recorder`, which writes first what an earlier
        game kept when the disk refused it; `lasting.problems` may hold what an earlier
        game saw that is not over (the keyfob still away, the voice or the disk
        failing): shown from the start. The keyfob itself reports KeyfobLost when it is
        not there at its start; an earlier game may have taken that report, hence these.
        """
        start = start or Start()
        self.config = config = setup.config
        self.settings = config.game
        self.hw = setup.hardware
        self.picker = setup.picker
        self.recorder = lasting.recorder
        self.problems = lasting.problems
        self._open_session = lasting.open_session
        self._battery = lasting.battery
        self.queue = lasting.queue
        # One keyfob per child ([[keyfob.children]]): whose each seat is, whose turn it is.
        seats = config.keyfob.children
        self.turn = rotation.Turn(tuple(rotation.Seat(s.child - 1, s.where) for s in seats))
        self._clock = lasting.clock
        self.speech = Speech(self.picker, self.hw.voice, self._record, self._voice_health)
        self.speech.failing = self.problems.get(FaultSource.VOICE)
        self.body = BodyWork(
            setup.body, lambda: self.plan, lambda info: self._emit(GameEvent.BODY, **info)
        )
        # Behaviours the game does not wait for (a smile after an answer), kept until done.
        self._showing: set[asyncio.Future[None]] = set()
        self._startup_faults = tuple(start.faults)
        # The kinds of fault Kaspar has said since the game last stopped for one.
        self._said_in_fault: set[FaultSource] = set()
        self._storage_fault_queued = False
        self._seen_faults: set[Fault] = set()
        self.plan: SessionPlan | None = None
        self.session_state: GameState | None = None
        # The open session's settings; until one opens, the robot-wide ones apply.
        self.session_settings: SessionSettings | None = None
        self.picker.robot = config.robot_settings.name
        self.resumed = start.resumed is not None
        self.stopped_waiting = start.stopped
        self._inputs = Inputs()
        self._step_task: asyncio.Task[None] | None = None
        self.presses = ChildPresses(self.settings.extra_press_gap_s)
        self.buttons = ButtonCheck()
        # When the children's keyfob last sent a key, and whether Kaspar has said it
        # seems silent (a flat battery) in this game.
        self._keyfob_heard_at = -math.inf
        self._said_keyfob_silent = False
        # The command being applied was the researcher's hold on the children's keyfob.
        self._command_on_keyfob = False
        self.router = Router(config.researcher, self.settings.commands, self.hw.researcher)
        self.listeners: list[Listener] = []
        self.script = script(config.game.script)
        self._use_script(self.script)  # the configured script's words, until a session opens
        self.recorder.to(None)
        initial = "idle"
        if start.resumed is not None:
            self._take_session(start.resumed)
            initial = _resumed_stage(start.resumed.state)
        self.recorder.attach(self._storage_refused)
        self.problems.follow(lambda problems: self._emit(GameEvent.PROBLEMS, problems=problems))
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

    @property
    def session(self) -> Session | None:
        """The open session (None before it opens): where the game's records go."""
        return self.recorder.session

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

    def _facts(self) -> Facts:
        """What, besides the stage, decides whether a researcher's command applies."""
        state = self.session_state
        away = self._away_record()
        return Facts(
            self.conditions(),
            undo_available=state is not None and state.undo is not None,
            hardware_ready=self.hw.keyfob.connected,
            stopped_waiting=self.stopped_waiting is not None and self.session is None,
            reopen_available=(
                state is not None and recovery.reopen_record(state, self.settings) is not None
            ),
            away=None if away is None else Confirmation(away.event),
            plans_to_choose=(
                self.queue is not None
                and self.session is None
                and self.stopped_waiting is None
                and bool(self.queue.offered())
            ),
            checking_buttons=self.buttons.running,
        )

    # -- the run loop -----------------------------------------------------------

    async def run(self) -> str:
        """Play until the session is finished or stopped; returns the final stage."""
        device = self.hw.researcher if self.router.reads_device else None
        self._inputs.read(self.hw.keyfob, device)
        # The HAL latches faults and takes the safe action itself; the game only has
        # to stop the step and say so, once per fault, including any latched already
        # (those stop the game before it begins: it never shows idle with them).
        self.hw.servos.on_fault(self._fault_latched)
        for fault in self.hw.servos.faults:
            if fault not in self._seen_faults:
                self._seen_faults.add(fault)
                self._startup_faults += (servo_fault(fault),)
        self._set_keyfob_needs()
        try:
            try:
                await self._begin()
            except Exception as error:
                await self._survive(error, "starting the game")
            while self.stage not in ENDS:
                await self._take(await self._inputs.get())
                self._record_clock_jump()
            # No more keyfob events taken (they stay queued in the keyfob for the next
            # game); those already taken are still handled.
            await self._inputs.stop_reading()
            await self._after_the_end()
            await self.speech.finish()  # what Kaspar says of the end is heard to its end
        finally:
            await self._cancel_step()
            await self.speech.close()
            self.hw.servos.off_fault(self._fault_latched)
            await self._inputs.stop_reading()
        return self.stage

    async def _begin(self) -> None:
        if self.resumed:
            session = self._require_session()
            bind_context(session=session.id)
            trials = self._require_state().trials
            repaired = session.repairs or UNSET
            self._record(
                SessionRecord(
                    event=SessionEvent.RESUMED, step=self.stage, trials=trials, repaired=repaired
                )
            )
            self._record_clock()
            self._emit(GameEvent.RESUMED, step=self.stage)
            await self.speech.announce("session.resumed")
        # What went wrong before the game began stops it before a step starts.
        for fault in self._startup_faults:
            await self._on_fault(fault)
        if self.stage not in ("paused", "fault"):
            await self._entered()

    async def _after_the_end(self) -> None:
        """What came while the session ended (a fault as Kaspar said goodbye) is still handled."""
        while (event := self._inputs.pending()) is not None:
            if not isinstance(event, StepEnded):
                await self._take(event)

    async def _take(self, event: GameInput) -> None:
        """Handle one input; an error on the way is a fault, never the end of the loop."""
        try:
            await self._handle(event)
        except Exception as error:
            await self._survive(error, describe(event))

    async def _survive(self, error: Exception, doing: str) -> None:
        """An error escaped while `doing` something: a fault like any other, never the end."""
        fault = error_fault(error, doing)
        try:
            await self._on_fault(fault)
        except Exception as again:
            # Even saying so failed: the loop still goes on to the next input.
            log.critical("the fault could not be handled", fault=fault.detail, exc_info=again)

    async def _handle(self, event: GameInput) -> None:
        if isinstance(event, FromResearcher):
            await self._on_researcher_input(event.event)
        elif isinstance(event, Gesture):
            self._heard_keyfob(event.at)
            await self._act(self.router.from_keyfob(event, self.presses.asking_at), event.seat)
        elif isinstance(event, StepEnded):
            await self._on_step_ended(event)
        elif isinstance(event, HardwareFault):
            await self._on_fault(event)
        elif isinstance(event, KeyfobLost):
            # One seat of several away is passed over; the last one is the keyfob lost.
            if event.seat is not None:
                self.turn.absent_seats.add(event.seat)
            if event.seat is not None and self.hw.keyfob.connected:
                await self._on_seat_lost(event, event.seat)
            else:
                await self._on_keyfob_lost(event)
        else:
            if event.seat is not None:
                self.turn.absent_seats.discard(event.seat)
            if event.seat is not None and FaultSource.KEYFOB not in self.problems:
                self._on_seat_back(event, event.seat)
            else:
                self._on_keyfob_back(event)

    # -- whose input it is --------------------------------------------------------

    def _set_keyfob_needs(self) -> None:
        self.hw.keyfob.set_needs(self.router.keyfob_needs())

    async def _on_researcher_input(self, event: InputEvent) -> None:
        if isinstance(event, KeyfobLost):
            self._on_researcher_lost(event)
        elif isinstance(event, KeyfobBack):
            self._on_researcher_back(event)
        else:
            await self._act(self.router.from_device(event))

    async def _act(self, routed: Routed, seat: int | None = None) -> None:
        """Do what a gesture is: a child's answer, the researcher's command, or nothing."""
        if isinstance(routed, ChildPress | ChildGesture) and seat is not None:
            self._seated(routed, seat)
        elif isinstance(routed, ChildPress):
            self._child_press(routed.button, routed.at)
        elif isinstance(routed, ChildGesture):
            self._child_gesture(routed)
        elif isinstance(routed, HeldPress):
            self._record(self.presses.held(routed.button, routed.at, routed.name, self.stage))
        elif isinstance(routed, ResearcherCommand):
            await self._on_command(routed)
        else:
            self._record(routed.record)

    def _child_press(self, button: str, at: float, seat: int | None = None) -> None:
        answering = self.presses.waiting
        outcome = self.presses.press(button, at, self.stage, self._now())
        if outcome.record is not None:
            self._record(self._from_seat(outcome.record, seat))
        elif answering and not self.presses.waiting:
            self.turn.answered_by = seat
        if outcome.acknowledge:
            self.speech.announce_soon("listen.wait")

    def _child_gesture(self, gesture: ChildGesture, seat: int | None = None) -> None:
        """A child's hold or squeeze: its first key-down is a press like any other (the
        answer, if one is awaited), and what it went on to be is recorded, never acted on."""
        answering = self.presses.waiting
        self._child_press(gesture.button, gesture.at, seat)
        if answering and not self.presses.waiting:
            extra = self.presses.extra(gesture.button, gesture.at, gesture=gesture.name)
            self._record(self._from_seat(extra, seat))

    def _seated(self, routed: ChildPress | ChildGesture, seat: int) -> None:
        """A press of a seat's own keyfob: credited to its child; from a child whose turn it
        is not, recorded and not taken (or taken, by the session's answer_out_of_turn)."""
        refused = None
        if self.presses.waiting and self.plan is not None:
            rule = self.plan.answer_out_of_turn or self.settings.answer_out_of_turn
            refused = self.turn.refused(seat, self._group_size(), rule)
        if refused is not None:
            gesture = routed.name if isinstance(routed, ChildGesture) else msgspec.UNSET
            record = PressRecord(
                button=routed.button, at=routed.at, gesture=gesture, ignored=refused
            )
            self._record(self._from_seat(record, seat, turn_of=self.turn.asking))
        elif isinstance(routed, ChildPress):
            self._child_press(routed.button, routed.at, seat)
        else:
            self._child_gesture(routed, seat)

    def _from_seat(
        self, record: PressRecord, seat: int | None, turn_of: int | None = None
    ) -> PressRecord:
        """A press record saying which seat, device and child pressed."""
        return self.turn.pressed(record, seat, self._group_size(), self._child_name, turn_of)

    def _group_size(self) -> int:
        return self.config.group_size(self.plan) if self.plan is not None else 0

    def _child_name(self, index: int) -> str:
        children = self.plan.children if self.plan is not None else ()
        if index < len(children):
            return children[index]
        return self.speech.book.fill("names.child", number=str(index + 1))

    # -- the researcher's commands ------------------------------------------------

    async def _on_command(self, given: ResearcherCommand) -> None:
        self._command_on_keyfob = given.source == "keyfob"
        try:
            await self._command(given)
        finally:
            self._command_on_keyfob = False

    async def _command(self, given: ResearcherCommand) -> None:
        stage = self.stage
        key = confirmation(stage, given.command, self._facts())
        command = CommandRecord(
            command=given.command,
            gesture=given.gesture,
            at=given.at,
            state=stage,
            applied=False,
            source=given.source,
        )
        if key is None:
            self._record(msgspec.structs.replace(command, ignored="does not apply"))
            return
        if stage == "fault" and key is Confirmation.RESUME and not await self._rearm():
            await self._refuse_resume(command)
            return
        applied = msgspec.structs.replace(command, applied=True, confirm=key)
        away = self._away_record() if key in (Confirmation.AWAY, Confirmation.BACK) else None
        if away is not None:
            applied = msgspec.structs.replace(
                applied, child=away.child, child_index=away.child_index
            )
        if key in (Confirmation.CHOOSE, Confirmation.ABSENT):
            self._choose(key, applied)  # Kaspar does not even look: the children are there
            return
        self.body.look_at(GazeKind.RESEARCHER, name="the researcher")
        if key is Confirmation.CLOSE:
            await self._close_stopped(applied)
        else:
            await self._apply(given.command, key, applied)

    async def _apply(self, command: Command, key: Confirmation, applied: CommandRecord) -> None:
        """Record first, confirm, fire, confirm what was stopped: a command that applies."""
        opens_session = key is Confirmation.START and self.session is None
        # "start" opens the session: its command is its first record, once it is open.
        if not opens_session and not await self._record_command(command, key, applied):
            return
        if applied.state == "fault" and key is Confirmation.RESUME:
            self.problems.set(FaultSource.SOFTWARE, None)  # the researcher carries on
        # Kaspar confirms before what the command starts, and after what it stops.
        if key in SPOKEN_FIRST:
            await self.speech.announce(f"confirm.{key}")
        await self._fire(key)
        if opens_session:
            plan = self.plan
            if plan is not None and self.queue is not None:
                applied = msgspec.structs.replace(applied, group=plan.group, number=plan.number)
            self._write(applied)
        await self._confirm_after(key)

    async def _confirm_after(self, key: Confirmation) -> None:
        """Kaspar confirms what a command stopped, once it has; a stop on the way to rest."""
        if key is Confirmation.STOP:
            await self._stop_safely()
        elif key not in SPOKEN_FIRST and key not in SILENT:
            await self.speech.announce(f"confirm.{key}")

    async def _record_command(
        self, command: Command, key: Confirmation, applied: CommandRecord
    ) -> bool:
        """The command on disk before it is applied; False (a storage fault) if it cannot be."""
        try:
            if command is Command.PAUSE and self.session_state is not None:
                self._change(applied)  # sets session_state.paused
            elif key is Confirmation.STOP:
                self._record(applied)  # a stop never waits for the disk: safety first
            else:
                self._write(applied)  # record first: a command not on disk is not applied
        except StorageFailed as error:
            if applied.state == "fault":
                self._emit(GameEvent.RESUME_REFUSED)
            await self._on_fault(storage_fault(error))
            return False
        return True

    async def _refuse_resume(self, command: CommandRecord) -> None:
        self._record(msgspec.structs.replace(command, ignored="the hardware is still faulty"))
        self._emit(GameEvent.RESUME_REFUSED)
        await self.speech.announce("fault.problem")

    async def _stop_safely(self) -> None:
        """To rest at once, saying goodbye on the way: safety does not wait for words, and
        a line that fails does not keep Kaspar from resting."""
        self.body.cancel()
        outcomes = await asyncio.gather(
            self.speech.announce(f"confirm.{Confirmation.STOP}"),
            self._rest_safely(),
            return_exceptions=True,
        )
        for outcome in outcomes:
            if isinstance(outcome, BaseException):
                raise outcome

    async def _fire(self, key: Confirmation) -> None:
        if key is Confirmation.SKIP_CHECK:
            self.buttons.skip()
            return
        if key is Confirmation.UNDO:
            await self._undo()
            return
        if key is Confirmation.REOPEN:
            await self._reopen()
            return
        if key in (Confirmation.AWAY, Confirmation.BACK):
            await self._away()
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
        opened, self.stopped_waiting = self.stopped_waiting, None
        self._take_session(opened)
        bind_context(session=opened.session.id)
        state = opened.state
        self._record(
            SessionRecord(event=SessionEvent.RESUMED, step=_resume_step(state), trials=state.trials)
        )
        self._record_clock()
        self._emit(GameEvent.SESSION, session=opened.session.id)
        # The children may be new to Kaspar today: the greeting first, as at any start.
        await asyncio.gather(self.speech.announce("session.greeting"), self.body.perform(GREETING))

    async def _close_stopped(self, command: CommandRecord) -> None:
        """The stopped session is closed for good: its plan is done."""
        assert self.stopped_waiting is not None
        session = self.stopped_waiting.session
        self.stopped_waiting = None
        try:
            session.record(command, self._now())
            session.record(SessionRecord(event=SessionEvent.CLOSED), self._now())
            session.close()
        except StorageFailed as error:
            await self._on_fault(storage_fault(error))
            return
        # Idle again with nothing waiting: what "next" opens now is the plan's (STATUS=).
        self._emit(GameEvent.WAITING_FOR_RESEARCHER, step="idle")
        await self.speech.announce("confirm.close")

    async def _start_session(self) -> None:
        opened = self._open_session()
        session = opened.session
        try:
            session.record(SessionRecord(event=SessionEvent.START, plan=session.plan), self._now())
        except StorageFailed:
            # A session without its start record is no session: gone, and the next
            # long green opens a new one once the disk takes records again.
            session.close()
            remove_tree(session.directory)
            raise
        self._take_session(opened)
        bind_context(session=session.id)
        self._record_clock()
        self.problems.set(FaultSource.STORAGE, None)
        self._emit(GameEvent.SESSION, session=session.id)

    def _take_session(self, opened: OpenedSession) -> None:
        """The game plays `opened` from now on: its records go there, in its script's words,
        with its own settings (game, learner, voice, speed, language: SessionSettings)."""
        session, plan, self.session_state, settings = opened
        self.session_settings = settings or resolve_session(self.config, plan)
        self.plan = self.session_settings.plan
        self.settings = self.session_settings.game
        self.recorder.to(session)
        self._use_script(session_script(session))
        self._apply_session_settings(self.session_settings)

    def _apply_session_settings(self, settings: SessionSettings) -> None:
        """The voice, the joints' speed and the phrase book as the session has them."""
        self.hw.voice.configure(settings.voice)
        self.hw.servos.scale_speeds(settings.speed_scale)
        config = self.config
        if settings.language != config.language or settings.game.toys != config.game.toys:
            self.picker.book = phrasebook_for(settings.config(config))
        self.picker.robot = settings.robot_name

    def _use_script(self, chosen: Script) -> None:
        self.script = chosen
        self.picker.fixed = chosen.fixed

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

    def _choose(self, key: Confirmation, command: CommandRecord) -> None:
        """In idle: the next planned session chosen, or the chosen one's group marked absent
        (or the mark taken back). Recorded in the event log (the absence in a session
        directory of its own, kasparctl.game.opening); a chime, where one is configured,
        and STATUS= and the live view name the group: the children hear no words."""
        assert self.queue is not None  # the command applies only with a queue
        try:
            if key is Confirmation.CHOOSE:
                offer = self.queue.choose()
            else:
                offer = self.queue.toggle_absent(self._now())
                if not offer.absent:
                    key = Confirmation.PRESENT
        except StorageFailed as error:
            self._inputs.put(storage_fault(error))
            return
        self._record(
            msgspec.structs.replace(command, confirm=key, group=offer.group, number=offer.number)
        )
        if CHOSEN_SOUND in self.config.voice.clips:
            self.speech.sound_soon(CHOSEN_SOUND)
        self._emit(GameEvent.CHOSEN, group=offer.group, number=offer.number, absent=offer.absent)

    def _away_record(self) -> RotationRecord | None:
        """What the researcher's "away" would do now (kasparctl.game.rotation)."""
        state, plan = self.session_state, self.plan
        if state is None or plan is None or self.stage != "guessing":
            return None
        return rotation.away_command(state, self.config.group_size(plan), self._child_name)

    async def _away(self) -> bool:
        """The child whose turn it is out of the rotation, or the one skipped just now back:
        the question is asked again, of the child whose turn it now is."""
        record = self._away_record()
        if record is None:
            return False
        await self._cancel_step()
        self._change(record)
        self._emit(GameEvent.ROTATION, change=record.event, child=record.child)
        self._start_step("guessing")
        return True

    async def _on_seat_lost(self, event: KeyfobLost, seat: int) -> None:
        """One seat's keyfob is gone, the others are read: that child's turns are passed
        over until it is back (asked now, the question goes to the next child)."""
        self._record(HalRecord(event=HalEvent.KEYFOB_LOST, reason=event.reason, seat=seat + 1))
        seats = self.turn.seats
        asked = self.turn.asking
        if self.stage == "guessing" and seat < len(seats) and asked == seats[seat].child:
            await self._cancel_step()
            self._start_step("guessing")

    def _on_seat_back(self, event: KeyfobBack, seat: int) -> None:
        self._record(HalRecord(event=HalEvent.KEYFOB_BACK, device=event.device, seat=seat + 1))

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
        self.problems.set(FaultSource.SERVO, None)
        return True

    # -- entering and leaving states -------------------------------------------

    async def _entered(self) -> None:
        stage = self.stage
        if stage != "fault":
            self._said_in_fault = set()  # what was said about the last stop is no news now
        bind_context(step=stage)
        self._emit(GameEvent.STATE, state=stage)
        # Life in every stage but a fault and the end (teaching and pointing say so too).
        self.body.set_alive(stage not in ("fault", *ENDS))
        if stage in ENDS:
            self._end_session(stage)
            return
        state = self.session_state
        if stage in STEPS:
            if state is not None and state.step != stage:
                self._change(StepRecord(to=stage))  # a step not on disk is not entered
            self._start_step(stage)
        elif stage == "idle":
            self._emit(GameEvent.WAITING_FOR_RESEARCHER, step="idle")

    def _end_session(self, stage: str) -> None:
        """The session ends whatever the disk says: a stop must never wait for it."""
        state = self.session_state
        try:
            if state is not None and state.step != stage:
                self._change(StepRecord(to=stage))
            if self.session is not None and state is not None:
                self.session.save_state(state, finished=True)
        except StorageFailed as error:
            self.recorder.refused(error)

    async def _leaving(self) -> None:
        await self._cancel_step()

    def _start_step(self, step: str) -> None:
        task = asyncio.create_task(self._play_step(step), name=f"step {step}")
        self._step_task = task

        def ended(done: asyncio.Task[None]) -> None:
            if not done.cancelled():
                self._inputs.put(StepEnded(step, done.exception()))

        task.add_done_callback(ended)

    async def _play_step(self, step: str) -> None:
        await Steps(self._step_context()).run(step)

    def _step_context(self) -> StepContext:
        """What a step of the open session may use: no trigger, no session to open."""
        opened = OpenedSession(self._require_session(), self._require_plan(), self._require_state())
        config = self.config
        return StepContext(
            settings=self.settings,
            opened=opened,
            script=self.script,
            params=self._require_settings().learner,
            group_size=config.group_size(opened.plan),
            joint_ranges={joint.name: joint.range_deg for joint in config.servos.joints},
            rest_pose={joint.name: joint.rest_deg for joint in config.servos.joints},
            listening_sound=LISTENING_SOUND in config.voice.clips,
            speech=self.speech,
            body=self.body,
            servos=self.hw.servos,
            presses=self.presses,
            recorder=self.recorder,
            emit=self._emit,
            showing=self._showing,
            battery=self._battery,
            turn=self.turn,
            buttons=self.buttons,
            unanswered=self._unanswered,
        )

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
        # A question the researcher's own hold on the keyfob cut off gives the children no
        # grace: the researcher had the keyfob (and may hold it again at once).
        self.presses.close(self._now(), grace=not self._command_on_keyfob)

    async def _on_step_ended(self, event: StepEnded) -> None:
        if event.step != self.stage:
            return
        if event.error is None:
            await self.advance()
        else:
            await self._on_fault(step_fault(event.step, event.error))

    # -- faults -----------------------------------------------------------------

    async def _on_fault(self, fault: HardwareFault) -> None:
        """Record, log, show and say a fault; stop the running step where the kind stops it."""
        stage = self.stage
        self.body.cancel()  # whatever Kaspar's body was doing ends at once, safely
        self._note_fault(fault, stage)
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
        self.speech.announce_soon(fault.line)

    def _note_fault(self, fault: HardwareFault, stage: str) -> None:
        """A problem, a record and a line in the journal."""
        if fault.kind is FaultSource.STORAGE:
            self._storage_fault_queued = False
            if isinstance(fault.error, StorageFailed):
                self.problems.storage_in_event_log = fault.error.in_event_log
        # Known before it is recorded: a record that fails for the same disk is not a new fault.
        self.problems.set(fault.kind, fault.problem, logged=True)
        self._record(
            FaultRecord(fault=fault.kind, detail=fault.detail, joint=fault.joint, state=stage)
        )
        say = log.warning if fault.kind is FaultSource.KEYFOB else log.error
        say("fault", fault=fault.kind.value, detail=fault.detail, joint=fault.joint, state=stage)

    def _storage_refused(self, error: StorageFailed) -> None:
        """A write failed where nothing else stops for it: a storage fault, once per stop."""
        # Once per stop: in the fault stage, or once the session is over, it is said once.
        said = FaultSource.STORAGE in self._said_in_fault and self.stage in ("fault", *ENDS)
        if not (said or self._storage_fault_queued):
            self._storage_fault_queued = True
            self._inputs.put(storage_fault(error))

    def _fault_latched(self, fault: Fault) -> None:
        if fault not in self._seen_faults:
            self._seen_faults.add(fault)
            self._inputs.put(servo_fault(fault))

    async def _on_keyfob_lost(self, event: KeyfobLost) -> None:
        seat = msgspec.UNSET if event.seat is None else event.seat + 1
        self._record(HalRecord(event=HalEvent.KEYFOB_LOST, reason=event.reason, seat=seat))
        if FaultSource.KEYFOB in self.problems and self.stage not in FAULTABLE:
            # Known already (not there at the start, and the reader says so too).
            self.problems.set(FaultSource.KEYFOB, event.reason)
            return
        await self._on_fault(HardwareFault(FaultSource.KEYFOB, event.reason))

    def _on_keyfob_back(self, event: KeyfobBack) -> None:
        seat = msgspec.UNSET if event.seat is None else event.seat + 1
        self._record(HalRecord(event=HalEvent.KEYFOB_BACK, device=event.device, seat=seat))
        self.problems.set(FaultSource.KEYFOB, None)
        self._emit(GameEvent.KEYFOB_BACK)
        self.speech.announce_soon("fault.keyfob_back")

    def _heard_keyfob(self, at: float) -> None:
        """A key of the children's keyfob: it is not silent (a suspicion is over)."""
        self._keyfob_heard_at = max(self._keyfob_heard_at, at)
        if FaultSource.KEYFOB_SILENT in self.problems:
            self._record(HalRecord(event=HalEvent.KEYFOB_HEARD))
            self.problems.set(FaultSource.KEYFOB_SILENT, None)

    def _unanswered(self, since: float) -> None:
        """A whole prompt cycle passed with no answer to what was asked at `since`: if the
        children's keyfob sent nothing at all meanwhile while the researcher's own device
        is there and working, its battery is suspected (recorded, STATUS=, said once)."""
        device = self.hw.researcher
        works = self.router.reads_device and device is not None and device.connected
        if not works or self._keyfob_heard_at >= since:
            return  # the children pressed something, or nothing tells the keyfob apart
        if FaultSource.KEYFOB_SILENT in self.problems:
            return
        silent = self._now() - since
        reason = (
            f"no key from the children's keyfob for {silent:.0f} s of prompts while the "
            "researcher's device works: its battery may be flat"
        )
        self._record(HalRecord(event=HalEvent.KEYFOB_SILENT, reason=reason))
        self.problems.set(FaultSource.KEYFOB_SILENT, reason)
        if not self._said_keyfob_silent:
            self._said_keyfob_silent = True
            self.speech.announce_soon("fault.keyfob_silent")

    def _on_researcher_lost(self, event: KeyfobLost) -> None:
        self._record(HalRecord(event=HalEvent.RESEARCHER_LOST, reason=event.reason))
        first = FaultSource.RESEARCHER not in self.problems
        self.problems.set(FaultSource.RESEARCHER, f"researcher's device: {event.reason}")
        self._set_keyfob_needs()
        if first:
            self.speech.announce_soon("fault.researcher_lost")

    def _on_researcher_back(self, event: KeyfobBack) -> None:
        self._record(HalRecord(event=HalEvent.RESEARCHER_BACK, device=event.device))
        self.problems.set(FaultSource.RESEARCHER, None)
        self._set_keyfob_needs()
        self.speech.announce_soon("fault.researcher_back")

    def _voice_health(self, failing: str | None) -> None:
        self.problems.set(FaultSource.VOICE, failing)

    def note_shutdown(self, reason: str) -> None:
        """The daemon is stopping: the session stays unfinished, to be resumed at the next start."""
        self._record(SessionRecord(event=SessionEvent.SHUTDOWN, reason=reason, state=self.stage))

    # -- recording, telling -------------------------------------------------------

    def _write(self, record: RecordT) -> RecordT | None:
        return self.recorder.write(record)

    def _record(self, record: RecordT) -> RecordT | None:
        return self.recorder.record(record)

    def _record_clock(self) -> None:
        """The wall clock's state, as a session starts or resumes (game.wallclock)."""
        if self._clock is not None:
            self._record(clock_record(self._clock.read()))

    def _record_clock_jump(self) -> None:
        """The wall clock's state again, when it has jumped since the last reading."""
        if self._clock is not None and (reading := self._clock.jumped()) is not None:
            log.warning("the wall clock jumped", step_s=reading.step, source=reading.source.source)
            self._record(clock_record(reading))

    def _change(self, record: RecordT) -> RecordT:
        return self.recorder.change(record, self._require_state(), self.settings)

    def _emit(self, event: GameEvent, **info: Any) -> None:
        for listener in self.listeners:
            try:
                listener(event, info)
            except Exception as error:
                # A listener (the daemon's status, a narrator) must never stop the game.
                log.error("a game listener failed", game_event=event.value, exc_info=error)

    def _now(self) -> float:
        return loop_time()

    def _require_session(self) -> Session:
        if self.session is None:
            raise RuntimeError("no session is open")
        return self.session

    def _require_state(self) -> GameState:
        if self.session_state is None:
            raise RuntimeError("no session is open")
        return self.session_state

    def _require_settings(self) -> SessionSettings:
        if self.session_settings is None:
            raise RuntimeError("no session is open")
        return self.session_settings

    def _require_plan(self) -> SessionPlan:
        if self.plan is None:
            raise RuntimeError("no session is open")
        return self.plan


def _resumed_stage(state: GameState) -> str:
    """The stage a resumed session begins in: its step (paused, if it was), or idle."""
    initial = state.step if state.step in STATES else "idle"
    return "paused" if state.paused and initial in PAUSABLE else initial


def _resume_step(state: GameState | None) -> str:
    """Where a resume (or a reopen) returns to: the session's step, or the one it stopped in."""
    if state is None:
        return "idle"
    if state.step == "stopped" and isinstance(state.stopped_from, str):
        return state.stopped_from
    return state.step
