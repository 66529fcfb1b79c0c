"""The whole game on simulated hardware with a simulated group of children.

Used by `kasparctl demo` and by the end-to-end tests: the game, the sessions
and the servo safety layer are the robot's own; only the servo drivers, the
keyfob (and the researcher's device) and the voice are simulated twins.

A demo's result also measures the interaction: how long from a child's answer
to the end of Kaspar's next question (median), Kaspar's speech per trial, the
researcher's commands a child's press started (there must be none), and the
children's answers the game did not take (none).
"""

from __future__ import annotations

import asyncio
import dataclasses
import errno
import itertools
import random
import statistics
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Generic, Protocol, TextIO, TypeVar

import msgspec
import numpy as np

from hal import Hardware
from hal.clock import LoopClock
from hal.errors import KasparError
from hal.keyfob.sim import SimKeyfob, TerminalKeyfob
from hal.servos.api import ServoApi
from hal.servos.sim import SimServos
from hal.voice.api import VoiceOutput
from hal.voice.sim import SimVoice
from kasparctl.body.api import Body, StillBody
from kasparctl.body.build import make_body
from kasparctl.config import (
    Config,
    GameSettings,
    SessionPlan,
    UncertaintyMode,
    parse_config,
    resolve_session,
)
from kasparctl.game.events import GameEvent, Listener
from kasparctl.game.language import phrasebook_for
from kasparctl.game.machine import Game, Lasting, Setup, Start
from kasparctl.game.opening import OpenedSession, PlanQueue, open_new
from kasparctl.game.phrases import PhrasePicker
from kasparctl.game.records import (
    AnyRecord,
    ButtonCheckRecord,
    CommandRecord,
    FaultSource,
    PoseRecord,
    PressRecord,
    TrialRecord,
)
from kasparctl.game.resume import Abandoned, resume_or_abandon
from kasparctl.game.session import EventLog
from kasparctl.game.stages import ENDS
from kasparctl.game.wallclock import ClockWatch
from kasparctl.sim import simtime
from kasparctl.sim.children import (
    MAX_RESUMES,
    ChildPress,
    Hands,
    Interruptions,
    ResearcherAction,
    SimulatedGroup,
    gesture_downs,
)
from kasparctl.sim.recording import MotionRecord, recorded_voice
from kasparctl.sim.simulate import draw_answer_key
from kasparctl.sim.teacher import DEFAULT_THINK_S, Messiness, Teacher
from kasparctl.vocabulary import Command

# Kaspar's speech per trial is counted at this rate (words a minute), as the speech
# budget was measured before the interaction was reworked.
BUDGET_WPM = 150


# How the demo's pilot locations are said in each language, after "goes" ("gehört", "va").
_DEMO_PLACES: dict[str, dict[str, str]] = {
    "en": {"box": "in the box", "shelf": "on the shelf", "basket": "in the basket"},
    "de": {"box": "in die Kiste", "shelf": "ins Regal", "basket": "in den Korb"},
    "nl": {"box": "in de doos", "shelf": "op de plank", "basket": "in de mand"},
    "it": {"box": "nella scatola", "shelf": "sullo scaffale", "basket": "nel cestino"},
    "fr": {"box": "dans la boîte", "shelf": "sur l'étagère", "basket": "dans le panier"},
}


def with_variant(config: Config, variant: str) -> Config:
    """The demo robot playing the names game or the pilot (three locations it can point at)."""
    if variant == config.game.variant:
        return config
    if variant == "pilot":
        poses = {
            "box": {"right_shoulder_pitch": -40.0, "right_shoulder_roll": 10.0},
            "shelf": {"right_shoulder_pitch": -70.0, "right_shoulder_roll": 40.0},
            "basket": {"right_shoulder_pitch": -30.0, "right_shoulder_roll": 70.0},
        }
        phrases = _DEMO_PLACES.get(config.language, _DEMO_PLACES["en"])
        game = msgspec.structs.replace(
            config.game,
            variant="pilot",
            locations=tuple(poses),
            poses=poses,
            location_phrases=phrases,
        )
    else:
        game = msgspec.structs.replace(
            config.game, variant="names", locations=(), poses={}, location_phrases={}
        )
    return msgspec.structs.replace(config, game=game)


def demo_config() -> Config:
    """The demo's built-in robot: Kaspar 3's head, face and pointing arm, simulated."""
    text = resources.files("kasparctl.sim").joinpath("demo.toml").read_text(encoding="utf-8")
    return parse_config(text, "kasparctl/sim/demo.toml")


class Transcript:
    """The demo's printed lines; a reader that went away (`kasparctl demo | head`) ends the
    demo quietly rather than fault every line Kaspar says into a closed pipe."""

    def __init__(self, stream: TextIO) -> None:
        """Print into `stream` until its reader goes away."""
        self.stream = stream
        self.gone = False
        self.on_gone: Callable[[], None] | None = None

    def write(self, text: str) -> int:
        """Print `text`; once the reader is gone, nothing (and the demo is ended)."""
        if not self.gone:
            try:
                self.stream.write(text)
                self.stream.flush()
            except BrokenPipeError:
                self._went()
        return len(text)

    def flush(self) -> None:
        """Nothing to flush: every write is flushed (a demo is read as it plays)."""

    def _went(self) -> None:
        self.gone = True
        if self.on_gone is not None:
            self.on_gone()


@dataclass
class DemoOptions:
    """Where a demo keeps its records, its seed, its children, and where it prints."""

    state_dir: Path
    seed: int = 0
    teacher: Teacher = field(default_factory=Teacher)
    # How long the simulated children think before pressing: uniform in this range (s).
    think_s: tuple[float, float] = DEFAULT_THINK_S
    messiness: Messiness = field(default_factory=Messiness)
    interactive: bool = False
    # How Kaspar shows how sure it is, for a new session (None: as its plan says).
    uncertainty: UncertaintyMode | None = None
    # Printed lines: the dialogue and what the children and the robot do (the
    # stdout of the moment the demo runs, not of the moment this was imported).
    out: TextIO = field(default_factory=lambda: sys.stdout)
    # Every goal each joint received goes to this CSV (kasparctl.sim.recording).
    motion: Path | None = None
    # A real engine that says every line too, into WAV files the mouth follows.
    voice: str | None = None
    # The researcher's pauses, undos and stops at any moment, open questions included.
    interruptions: Interruptions = field(default_factory=Interruptions)
    # The wall clock watched, its state recorded as the service records it (None: not
    # watched, as the demo's clock is simulated; a test injects one).
    clock: ClockWatch | None = None
    # Step 2: the chance the presser presses green before anyone moved the arm.
    p_unmoved_arm: float = 0.0


@dataclass
class DemoResult:
    """How a demo session ended."""

    session: str
    finished: bool
    trials: int
    learned: int
    resumed: bool
    final_state: str
    state_dir: str
    # Median seconds from a child's answer to the end of Kaspar's next question.
    answer_to_next_question_s: float | None = None
    # Seconds of Kaspar's speech per trial in step 4 (words at BUDGET_WPM).
    speech_s_per_trial: float | None = None
    # Researcher commands (applied or not) that a simulated child's press started.
    accidental_commands: int = 0
    # The researcher's gestures the game took as the children's answer (a trial or a pose).
    commands_taken_as_answers: int = 0
    # Answers the simulated children gave that the game did not take as they meant.
    answers_lost: int = 0
    # Step 2: greens Kaspar refused because nobody had moved the arm (PressRecord.unmoved).
    unmoved_arm_refused: int = 0

    def summary(self) -> dict[str, Any]:
        """The result as plain data (the demo's --json line)."""
        return dataclasses.asdict(self)


class RigServos(ServoApi, Hands, Protocol):
    """Servos the simulated children can move by hand: SimServos, or real drivers on emulators."""


ServosT = TypeVar("ServosT", bound=RigServos)


@dataclass
class DemoRig(Generic[ServosT]):
    """The simulated robot, the game on it, and the simulated group: built, not yet running."""

    game: Game
    servos: ServosT
    keyfob: SimKeyfob
    voice: VoiceOutput
    children: SimulatedGroup | None
    resumed: bool
    state_dir: Path
    # The printed lines, when they may lose their reader (the command's stdout).
    transcript: Transcript | None = None
    # Sessions found unfinished that could not be resumed, closed as abandoned.
    abandoned: list[Abandoned] = field(default_factory=list)
    # Why the records could not be saved, once they could not: the demo ends there.
    storage_failed: str | None = None
    # The researcher's own simulated device, when their commands come from one.
    researcher: SimKeyfob | None = None
    # Kaspar's body language (the game's too): started and closed with the robot.
    body: Body = field(default_factory=StillBody)
    # The record of every goal written (--motion), closed with the robot.
    motion: MotionRecord | None = None
    # Every command the researcher gave (the group's and a test's), with its key times.
    researcher_actions: list[ResearcherAction] = field(default_factory=list)

    async def command(self, name: str) -> None:
        """The researcher's command `name` (next, pause, undo, stop), as they give it:
        a key of their device, or the hold on the children's keyfob that means it."""
        await researcher_command(
            self.game.config, self.keyfob, self.researcher, name, self.researcher_actions
        )

    async def run(self) -> DemoResult:
        """Start the simulated hardware, play (or resume) the session, close everything.

        DemoStorageFailed when the records cannot be saved: nobody is there to free the
        disk, so the demo ends (what was written stays; it resumes from there next time).
        """
        await self.servos.start()
        for group in self.servos.groups:
            # Powered on limp; torque on holds each joint where it is (no jump).
            await self.servos.set_compliant(group, False)
        await self.keyfob.start()
        await self.body.start()
        storage = asyncio.Event()

        def on_storage_fault(event: GameEvent, info: dict[str, Any]) -> None:
            if event is GameEvent.FAULT and info.get("kind") is FaultSource.STORAGE:
                self.storage_failed = str(info.get("detail"))
                storage.set()

        self.game.listeners.insert(0, on_storage_fault)
        reader_gone = asyncio.Event()
        if self.transcript is not None:
            self.transcript.on_gone = reader_gone.set
        if self.researcher is not None:
            await self.researcher.start()
        try:
            final = await _play_until(self.game, storage, reader_gone)
        finally:
            if self.children is not None:
                await self.children.close()
            if self.researcher is not None:
                await self.researcher.close()
            await self.keyfob.close()
            await self.body.close()
            await self.voice.close()
            await self.servos.close()
            if self.motion is not None:
                self.motion.close()
            recorder = self.game.recorder
            recorder.flush()
            if recorder.event_log is not None:
                recorder.event_log.close()
            if self.game.session is not None:
                self.game.session.close()
        if reader_gone.is_set():
            # Nobody reads the demo any more: as a closed pipe ends any command (exit 0);
            # its session, if one opened, resumes at the next demo on this directory.
            raise BrokenPipeError(errno.EPIPE, "the demo's reader went away")
        state, session = self.game.session_state, self.game.session
        if self.storage_failed is not None or state is None or session is None:
            raise DemoStorageFailed(
                f"the records cannot be saved: {self.storage_failed or 'no session was opened'}; "
                f"what was written is kept in {self.state_dir}, and the session resumes from "
                "there once the disk takes records again"
            )
        session.close()
        records = session.records()
        if self.game.recorder.event_log is not None:
            records += self.game.recorder.event_log.records().records
        trials = [r for r in records if isinstance(r, TrialRecord)]
        presses = self.children.presses if self.children is not None else []
        return DemoResult(
            session=session.id,
            finished=final == "finished",
            trials=state.trials,
            learned=sum(p.learned is not None for p in state.progress),
            resumed=self.resumed,
            final_state=final,
            state_dir=str(self.state_dir),
            answer_to_next_question_s=answer_to_next_question(trials),
            speech_s_per_trial=speech_per_trial(self.voice, trials),
            accidental_commands=accidental_commands(records, presses, self.researcher_actions),
            commands_taken_as_answers=commands_taken_as_answers(records, self.researcher_actions),
            answers_lost=len(lost_answers(records, presses, held_s(self.game.config))),
            unmoved_arm_refused=sum(
                isinstance(r, PressRecord) and isinstance(r.unmoved, str) for r in records
            ),
        )


def build(
    config: Config,
    options: DemoOptions,
    children_answers: list[int] | None = None,
    *,
    body: Body | None = None,
) -> DemoRig[SimServos]:
    """Assemble the simulated robot and (or resume) a session in options.state_dir.

    `children_answers` makes the simulated children believe other answers than
    the plan's answer key (to show the learner does not see the key); `body` is
    Kaspar's body language (None: the configuration's, make_body).
    """
    clock = LoopClock()
    servos = SimServos(config.servos, clock)
    also = recorded_voice(config, options.voice, options.state_dir)
    voice = SimVoice(
        options.out,
        clock,
        clips=config.voice.clips,
        also=also,
        prefix=config.robot_settings.name,
    )
    return assemble(config, options, servos, voice, children_answers, body=body)


def assemble(
    config: Config,
    options: DemoOptions,
    servos: ServosT,
    voice: VoiceOutput,
    children_answers: list[int] | None = None,
    *,
    patience: int = MAX_RESUMES,
    body: Body | None = None,
) -> DemoRig[ServosT]:
    """build() with the servos and the voice given, e.g. real drivers on pty emulators;
    `body` is Kaspar's body language (None: the configuration's, make_body)."""
    clock = LoopClock()
    out = options.out

    early: list[str] = []

    def narrate(text: str) -> None:
        try:
            now = clock.now()
        except RuntimeError:  # built before its loop runs: told when the game begins
            early.append(text)
            return
        while early:
            out.write(f"[{now:10.3f}]   ({early.pop(0)})\n")
        out.write(f"[{now:10.3f}]   ({text})\n")

    def tell_early(event: GameEvent, info: dict[str, Any]) -> None:
        if early:
            narrate(early.pop())

    researcher = None
    if config.researcher.source == "device":
        # The simulated researcher holds a device with a key for every command (the
        # configured presenter may lack choose, absent and away: a keypad has them).
        researcher = SimKeyfob(clock, commands=sorted(Command))
    # A keypad's command keys are keys of the children's keypad.
    keypad = (
        sorted(set(config.keyfob.commands.values()))
        if config.researcher.source == "keypad"
        else []
    )
    if options.interactive:
        keyfob: SimKeyfob = TerminalKeyfob(clock, researcher=researcher, commands=keypad)
    else:
        keyfob = SimKeyfob(clock, commands=keypad)
    book = phrasebook_for(config)
    picker = PhrasePicker(book, np.random.default_rng([options.seed, 2]))
    plan = _demo_plan(config, PlanQueue(options.state_dir, lambda: config), clock, narrate)
    if options.uncertainty is not None:
        mode = options.uncertainty
        plan = msgspec.structs.replace(plan, uncertainty=mode, speak_uncertainty=None)
    outcome = resume_or_abandon(options.state_dir, config.game, config.profile)
    for abandoned in outcome.abandoned:
        why = abandoned.reason
        narrate(f"session {abandoned.session_id} abandoned, it cannot be resumed: {why}")
    resumed = None
    if outcome.resumable is not None:
        resumable = outcome.resumable
        settings = resumable.settings(config)
        resumed = OpenedSession(resumable.session, resumable.plan, resumable.state, settings)
        plan = resumed.plan
        narrate(f"resuming group {plan.group}, session {plan.number}")
        config = outcome.resumable.config(config)
    else:
        settings = resolve_session(config, plan)
    game_settings = settings.game
    answers = _answers(game_settings, plan, options.seed)

    def open_session() -> OpenedSession:
        with_key = msgspec.structs.replace(
            plan, answer_key=tuple(game_settings.toys[a] for a in answers)
        )
        return open_new(options.state_dir, config, with_key, options.seed)

    actions: list[ResearcherAction] = []

    async def give(name: str) -> None:
        await researcher_command(config, keyfob, researcher, name, actions)

    hardware = Hardware(servos, keyfob, voice, researcher)
    # Before the session opens and after it ends, what happens goes where the service puts it.
    events = EventLog(options.state_dir)
    if body is None:
        # Seeded like everything else in the demo: blinks at the same moments, the same game.
        body = make_body(config, servos, voice, rng=random.Random(options.seed))
    game = Game(
        Setup(config, hardware, picker, body),
        Lasting.new(events, open_session, clock=options.clock),
        Start(resumed),
    )
    children = None
    if not options.interactive:
        # A resumed game gets fresh but reproducible children: seeded by where it resumed.
        progress = 0 if resumed is None else resumed.state.trials + 1
        children = SimulatedGroup(
            keyfob,
            servos,
            options.teacher,
            children_answers if children_answers is not None else answers,
            np.random.default_rng([options.seed, 1, progress]),
            pointing_group=config.game.pointing_group,
            think_s=options.think_s,
            command=give,
            messiness=options.messiness,
            interruptions=options.interruptions,
            shares_keyfob=lambda: researcher is None or not researcher.connected,
            researcher_rng=np.random.default_rng([options.seed, 5, progress]),
            p_unmoved_arm=options.p_unmoved_arm,
            unmoved_rng=np.random.default_rng([options.seed, 6, progress]),
            # The bags stay where they were put, whatever was interrupted.
            room=np.random.default_rng([options.seed, 4]),
            narrate=narrate,
            patience=patience,
        )
        game.listeners.append(children)
    game.listeners.insert(0, tell_early)
    game.listeners.append(_narrator(narrate))
    transcript = out if isinstance(out, Transcript) else None
    motion = MotionRecord(servos, options.motion) if options.motion is not None else None
    return DemoRig(
        game, servos, keyfob, voice, children, resumed is not None, options.state_dir,
        transcript=transcript, abandoned=outcome.abandoned, researcher=researcher, body=body,
        motion=motion, researcher_actions=actions,
    )


async def researcher_command(
    config: Config,
    keyfob: SimKeyfob,
    device: SimKeyfob | None,
    name: str,
    actions: list[ResearcherAction] | None = None,
) -> None:
    """Give the researcher's command `name` on `device`, or as the configured hold on the
    children's `keyfob` (one keyfob, or the device away); kept in `actions` with its key
    times (how the demo tells the researcher's keys from the children's)."""
    if device is not None and device.connected:
        where, action = device, f"command {name}"
    elif config.researcher.source == "keypad":
        where, action = keyfob, f"command {name}"  # a command key of the children's keypad
    else:
        gestures = {command: gesture for gesture, command in config.game.commands.items()}
        gesture = gestures.get(name)
        if gesture is None:
            # No gesture means it on the children's keyfob (an undo or a re-open, by
            # default): any other gesture there is the children's (a double red is a red).
            return
        # Held a little past the researcher's hold, as the keyfob's "long" actions are.
        hold = config.researcher.hold_s + 0.3
        where, action = keyfob, gesture
        if gesture == "both":
            action = f"chord green {hold:.3f}"
        elif gesture.startswith("long "):
            action = f"hold {gesture.split()[1]} {hold:.3f}"
    start = await where.perform(action)
    if actions is not None:
        up = asyncio.get_running_loop().time()
        actions.append(ResearcherAction(name, gesture_downs(action, start), up, where is keyfob))


def answer_to_next_question(trials: Sequence[TrialRecord]) -> float | None:
    """Median seconds from each answer to the end of the next question."""
    gaps = [b.question_end - a.feedback_at for a, b in itertools.pairwise(trials)]
    return round(statistics.median(gaps), 3) if gaps else None


def speech_per_trial(voice: VoiceOutput, trials: Sequence[TrialRecord]) -> float | None:
    """Seconds of Kaspar's speech per trial in step 4, its words at BUDGET_WPM.

    From 30 s before the first question's end (its intro and first question) to the
    last answer: what the speech budget has always counted.
    """
    if not trials or not isinstance(voice, SimVoice):
        return None
    start, end = trials[0].question_end - 30.0, trials[-1].feedback_at
    words = sum(len(line.text.split()) for line in voice.lines if start <= line.started <= end)
    return round(words * 60.0 / BUDGET_WPM / len(trials), 3)


def accidental_commands(
    records: Sequence[AnyRecord],
    presses: Sequence[ChildPress],
    researcher: Sequence[ResearcherAction] = (),
) -> int:
    """Researcher commands begun by a child's press: a command whose gesture began while a
    simulated child's keys were down, and not at a key-down of the researcher's own (the
    researcher may press their device while a child holds the keyfob)."""
    theirs = {down for action in researcher for down in action.downs}
    commands = [r for r in records if isinstance(r, CommandRecord) and r.at not in theirs]
    return sum(any(p.downs[0] <= c.at <= p.up for p in presses) for c in commands)


def commands_taken_as_answers(
    records: Sequence[AnyRecord], researcher: Sequence[ResearcherAction]
) -> int:
    """The researcher's gestures the records show as the children's answer: a trial's
    feedback or a shown bag's pose at a key-down of the researcher's (from the records and
    the researcher's key times alone, whatever the game believed)."""
    theirs = {down for action in researcher for down in action.downs}
    answers = [r.feedback_at for r in records if isinstance(r, TrialRecord)]
    answers += [r.at for r in records if isinstance(r, PoseRecord)]
    return sum(at in theirs for at in answers)


def held_s(config: Config) -> float | None:
    """How long a hold on the children's keyfob is no answer (it reached the researcher's
    hold, kasparctl.game.routing.HeldPress), when their commands are on it; else None."""
    if config.researcher.source != "keyfob":
        return None
    return config.researcher.hold_s


def lost_answers(
    records: Sequence[AnyRecord], presses: Sequence[ChildPress], held: float | None = None
) -> list[str]:
    """The children's answers the game did not take as they meant them.

    A trial's answer must be the children's first press for it made after the question
    ended, or an eager one the game took in the question's last words (the record says
    so; a double tap whose first tap came too early answers with its second), with the
    button meant. In step 2 every press that showed a bag must be the time of a pose
    record (Kaspar read the arm when it came, whatever the press became). With `held`
    (one keyfob), a hold or squeeze of `held` seconds or more is no answer by the rule
    (the children press again when Kaspar asks again), so it is not counted here.
    """
    # A press that went down once Kaspar had paused or stopped had no question to answer.
    presses = [p for p in presses if not p.withdrawn]
    if held is not None:
        presses = [p for p in presses if not _held_for(p.action, held)]
    trials = [r for r in records if isinstance(r, TrialRecord)]
    shown = {r.at for r in records if isinstance(r, PoseRecord)}
    # A press before anyone moved the arm is taken as meant when Kaspar refused it (or,
    # after unmoved_arm_asks refusals, took it).
    refused = {r.at for r in records if isinstance(r, PressRecord) and isinstance(r.unmoved, str)}
    lost = [
        f"bag {p.bag + 1} at {p.downs[0]:.3f}"
        for p in presses
        if p.bag is not None and not (shown | refused if p.unmoved else shown).intersection(p.downs)
    ]
    # Each press for Kaspar's check of the buttons is the press its record names.
    checked = {(r.pressed, r.at) for r in records if isinstance(r, ButtonCheckRecord)}
    lost += [
        f"the check's {p.button} at {p.downs[0]:.3f}"
        for p in presses
        if p.check and (p.button, p.downs[0]) not in checked
    ]
    by_trial: dict[int, list[ChildPress]] = {}
    for press in presses:
        if press.trial is not None:
            by_trial.setdefault(press.trial, []).append(press)
    latest: dict[int, TrialRecord] = {t.trial: t for t in trials}  # an undone trial is asked again
    for number, trial in latest.items():
        mine = by_trial.get(number, [])
        taken = [p for p in mine if trial.feedback_at in p.downs]
        after = [p for p in mine if p.downs[0] >= trial.question_end]
        meant = bool(taken) and taken[0].button == trial.feedback
        skipped = any(p.downs[0] < trial.feedback_at for p in after)
        if not meant or skipped:
            lost.append(f"trial {number}")
    return lost


def _held_for(action: str, held: float) -> bool:
    """Whether a keyfob action ("hold red 4.2", "chord green 3.1") is held `held` s or more."""
    words = action.split()
    return words[0] in ("hold", "chord") and float(words[2]) >= held


async def play(config: Config, options: DemoOptions) -> DemoResult:
    """Play (or resume) one session in options.state_dir on the simulated robot."""
    return await build(config, options).run()


async def _play_until(game: Game, *stops: asyncio.Event) -> str:
    """Play the game to its end, or end it at the first of `stops` (the records cannot be
    saved; nobody reads the transcript any more)."""
    playing = asyncio.create_task(game.run(), name="demo game")
    stopping = {asyncio.create_task(stop.wait()) for stop in stops}
    try:
        await asyncio.wait({playing, *stopping}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in stopping:
            task.cancel()
        # A cancellation inside a transitions trigger is swallowed: again until it ends.
        while not playing.done():
            playing.cancel()
            await asyncio.wait({playing}, timeout=1.0)
    return game.stage if playing.cancelled() else playing.result()


def _answers(game: GameSettings, plan: SessionPlan, seed: int) -> list[int]:
    """The right toy of each target (the session's toys): the plan's answer key, or one
    drawn for the demo."""
    if plan.answer_key:
        return [game.toys.index(toy) for toy in plan.answer_key]
    return list(draw_answer_key(game, np.random.default_rng([seed, 3])))


def _demo_plan(
    config: Config, queue: PlanQueue, clock: LoopClock, narrate: Callable[[str], None]
) -> SessionPlan:
    """The planned session the demo plays, said: the first not yet ended in this state
    directory, as the service's "next" would open it (the last again once all are)."""
    plans = config.sessions
    if not plans:
        return SessionPlan(group="demo")
    offer = queue.chosen()
    plan = queue.take(clock.now)
    place = plans.index(plan) + 1
    if offer is None:
        narrate(
            f"every planned session has been played in this state directory; playing the "
            f"last again: group {plan.group}, session {plan.number}"
        )
    else:
        narrate(
            f"planned session {place} of {len(plans)}: group {plan.group}, "
            f"session {plan.number}"
        )
    return plan


def _narrator(narrate: Callable[[str], None]) -> Listener:
    looked_at: list[str] = [""]  # the last look told: Kaspar turning back is not news

    def listener(event: GameEvent, info: dict[str, Any]) -> None:
        if event is GameEvent.POINT:
            style = info.get("style")
            narrate(f"Kaspar points at {info['target']}" + (f", {style}" if style else ""))
        elif event is GameEvent.BODY:
            note = body_note(info)
            if note is None:
                return
            if info.get("kind") == "look":
                if note == looked_at[0]:
                    return
                looked_at[0] = note
            narrate(note)
        elif event is GameEvent.LISTENING:
            narrate("Kaspar listens")
        elif event is GameEvent.STATE and info["state"] in ("paused", "fault", *ENDS):
            narrate(f"the game is {info['state']}")
        elif event is GameEvent.SESSION:
            narrate(f"session {info['session']} starts")
        elif event is GameEvent.RESUMED:
            narrate(f"session resumed in step {info['step']}")

    return listener


# How the transcript names each behaviour the game asks for.
BEHAVIOUR_NOTES = {
    "thinking": "Kaspar tilts its head, thinking",
    "nod": "Kaspar nods",
    "happy": "Kaspar smiles",
    "sad": "Kaspar looks sad",
    "greeting": "Kaspar waves hello",
    "farewell": "Kaspar waves goodbye",
}


def body_note(info: dict[str, Any]) -> str | None:
    """A GameEvent.BODY in a few words: a behaviour, or where Kaspar looks (None: not shown)."""
    kind = info.get("kind")
    if kind == "perform":
        behaviour = str(info["behaviour"])
        note = BEHAVIOUR_NOTES.get(behaviour, f"Kaspar: {behaviour}")
        if behaviour == "thinking":
            note += _how_hard(float(info["strength"]))
        return note
    if kind == "look" and info.get("gaze") == "child":  # whose turn; the point says the bag
        return f"Kaspar looks at {info['name']}" if info.get("name") else None
    return None  # life on and off is too small a thing to print


def _how_hard(strength: float) -> str:
    """How hard Kaspar thinks, in words, by the thinking behaviour's strength."""
    if strength >= 0.75:
        return " hard"
    if strength >= 0.5:
        return ""
    if strength > 0.25:
        return " a little"
    return " briefly"


# In simulated time a game that waits for ever would spin for ever: past this much
# simulated time it has stalled, and that is an error, not a long game.
STALL_LIMIT_S = 12 * 3600.0


class DemoStalled(KasparError):
    """A simulated game that stopped making progress."""


class DemoStorageFailed(KasparError):
    """The demo's records could not be saved (the disk full, the directory gone): it ended."""


def run_demo(
    config: Config, options: DemoOptions, speed: float | None = None, fast: bool = False
) -> DemoResult:
    """Real time by default; `speed` times faster; or `fast`, in simulated time."""
    if not fast:
        return simtime.run(play(config, options), speed=speed)

    async def bounded() -> DemoResult:
        rig = build(config, options)
        try:
            async with asyncio.timeout(STALL_LIMIT_S):
                return await rig.run()
        except TimeoutError:
            raise DemoStalled(
                f"no end after {STALL_LIMIT_S:.0f} simulated seconds, in state {rig.game.stage}"
            ) from None

    return simtime.run(bounded(), virtual=True)
