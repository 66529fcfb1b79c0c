"""The service on the robot: build the hardware, run sessions, talk to systemd, stop safely.

One asyncio loop owns everything. systemd learns READY=1 once the servos,
keyfob and voice are open (or their faults recorded), STATUS= follows the
game in words, and WATCHDOG=1 is sent by a task on the loop after checking
that every serial-port owner thread is alive: a hung loop or a dead bus thread
stops the pings and systemd restarts the service, which resumes the session.

SIGTERM/SIGINT: STOPPING=1, Kaspar stops mid-word, the session is left
unfinished on disk (it resumes at the next start), Kaspar goes to rest within
every joint's speed limit, then holds or goes limp as configured; exit 0.
SIGHUP between sessions reloads the configuration (phrases, plan); during a
session it is refused and logged, and `kasparctl reload` (systemd's
ExecReload=) is told so and fails (kasparctl.service.reload).

One writer per state directory: the daemon holds its StateDirLock for its
whole life, and a second writer is refused at once. While no session is open,
what happens is recorded in the event log (<state_dir>/events.jsonl). Nothing
that goes wrong stops the daemon or leaves it idle, deaf and silent: a part
that did not start, sessions that cannot be read, a game that ended by an
error all begin the next game in its fault stage, shown in STATUS= and said,
for the researcher to resume once it is fixed.
"""

from __future__ import annotations

import asyncio
import contextlib
import faulthandler
import os
import secrets
import signal
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import structlog

from hal import Hardware
from hal.build import build
from hal.clock import LoopClock
from hal.errors import HalError
from hal.scheduling import log_scheduling
from kasparctl.body.api import Body, StillBody
from kasparctl.body.behaviours import BehaviourError
from kasparctl.body.build import make_body
from kasparctl.config import Config, ConfigError, SessionPlan, load_config, servo_backend_given
from kasparctl.game.events import GameEvent, Listener
from kasparctl.game.faults import HardwareFault
from kasparctl.game.jsonl import read_records
from kasparctl.game.language import phrasebook_for
from kasparctl.game.lock import StateDirBusy, StateDirLock
from kasparctl.game.machine import Game, Lasting, Setup, Start
from kasparctl.game.opening import OpenedSession, PlanQueue, is_absence, open_new
from kasparctl.game.phrases import PhraseBook, PhrasePicker
from kasparctl.game.records import FaultSource, SessionEvent, SessionRecord, StepRecord
from kasparctl.game.resume import (
    Abandoned,
    CannotResume,
    Resumable,
    abandoned_reason,
    reopen,
    resume_or_abandon,
)
from kasparctl.game.session import RECORDS_FILE, EventLog, is_finished, session_dirs
from kasparctl.game.stages import ENDS
from kasparctl.game.storage import StorageFailed
from kasparctl.game.wallclock import ClockWatch
from kasparctl.log import configure_logging
from kasparctl.service.applying import restart_only
from kasparctl.service.batteries import low_batteries
from kasparctl.service.reload import Outcome, ReloadDesk, runtime_directory
from kasparctl.service.sdnotify import Notifier, watchdog_interval
from kasparctl.service.status import STATUS_WORDS, battery_words, recovery_words, status_line

log = structlog.get_logger("kasparctl.service.daemon")

# The loop may blindly trust this much lateness of its own timer before it
# counts as unresponsive (a busy but healthy loop on a small board).
LOOP_LAG_LIMIT_S = 1.0
REST_TIMEOUT_S = 15.0
# How long a game being ended may take to end before it is cancelled again.
GAME_CANCEL_GRACE_S = 1.0
DEBUG_BLOCK_ENV = "KASPAR_DEBUG_LOOP_BLOCK_S"
# The game events after which STATUS= is written again: the stage, the problems, a new
# session, and Kaspar confused until a name is re-opened or the target learned.
_STATUS_EVENTS = (
    GameEvent.STATE,
    GameEvent.PROBLEMS,
    GameEvent.SESSION,
    GameEvent.CONFUSED,
    GameEvent.REOPENED,
    GameEvent.ANSWERED,
    GameEvent.CHOSEN,
    GameEvent.WAITING_FOR_RESEARCHER,
)


@dataclass
class DaemonOptions:
    """How the service was started: its configuration, simulated hardware, another state dir."""

    config_path: str
    sim: bool = False
    state_dir: str | None = None
    # With sim: the keys (the children's and the researcher's) from this fifo, which may
    # appear later (FifoKeyfob).
    keys: str | None = None


class Daemon:
    """The service: the hardware, one session after another, systemd's notifications, stopping."""

    def __init__(
        self,
        options: DaemonOptions,
        notifier: Notifier | None = None,
        *,
        hardware: Hardware | None = None,
        listeners: Sequence[Listener] = (),
    ) -> None:
        """Load the configuration; nothing is opened until run().

        `hardware` replaces what the configuration builds (a test's rig); `listeners`
        follow every game the daemon plays, as the daemon's own status does.
        """
        self.options = options
        self.config = self._load()
        # Fixed for the daemon's life: its lock is on this directory.
        self._state_dir = Path(self.config.state_dir)
        self.notifier = notifier or Notifier()
        self.hw: Hardware | None = hardware
        # Kaspar's body language: built with the hardware, one for every game.
        self.body: Body = StillBody()
        self.game: Game | None = None
        self.listeners = list(listeners)
        self.events = EventLog(self._state_dir)
        # What outlives each game: the records the disk refused, and what is not working.
        # The planned sessions, and the researcher's choice among them in idle.
        self.queue = PlanQueue(self._state_dir, lambda: self.config)
        self.lasting = Lasting.new(
            self.events, self._open_session, self.queue, ClockWatch()
        )
        self.lock = StateDirLock(self._state_dir)
        self._stopping = asyncio.Event()
        self._stop_reason = ""
        self._reload = False
        self._reload_tokens: list[str | None] = []
        self._reload_desk = ReloadDesk(runtime_directory())
        # Faults for the next game to begin with (servos that did not start, a game
        # that ended by an error), and whether it must read the sessions again.
        self._pending_faults: list[HardwareFault] = []
        self._read_again = False
        self._playing: asyncio.Task[str] | None = None
        self._book: PhraseBook | None = None
        self._ending: asyncio.Task[None] | None = None
        self._resumable: Resumable | None = None
        # A session abandoned at the last read: shown in STATUS= until the next one opens.
        self._notice: str | None = None
        self._say_abandoned = False
        # A remote's battery below its warning level at the start: STATUS=, said once.
        self._batteries: str | None = None
        self._say_batteries = False

    def _load(self) -> Config:
        """The configuration, as a robot the game is played on; ConfigError otherwise.

        On the robot (without --sim) it must say which servos it drives: without a
        [servos] table they would be simulated without a word.
        """
        path = self.options.config_path
        config = load_config(path, playable=True)
        if not self.options.sim and not servo_backend_given(path):
            raise ConfigError(
                path,
                "servos.backend",
                "no [servos] table with its backend: on the robot the servos would be "
                "simulated without a word; say backend = 'real' with the robot's buses and "
                "joints (systemd/kaspar-3.toml), or backend = 'sim', or run `kasparctl run --sim`",
            )
        if self.options.state_dir is not None:
            config = msgspec.structs.replace(config, state_dir=self.options.state_dir)
        return config

    @property
    def state_dir(self) -> Path:
        """Where sessions are kept (the configuration's, or the one given at the start)."""
        return self._state_dir

    # -- the service ---------------------------------------------------------------

    async def run(self) -> int:
        """Run until SIGTERM or SIGINT; returns the exit status (0).

        StateDirBusy at once, before anything is opened, when another process writes
        to the state directory.
        """
        self._take_lock(at_start=True)
        try:
            return await self._run()
        finally:
            self.events.close()
            self.lock.release()

    def _take_lock(self, at_start: bool = False) -> bool:
        """Hold the state directory's lock; False (and a fault for the next game) if it cannot.

        At the start another writer is fatal (StateDirBusy): the service must not run
        beside a demo on its records. A directory that cannot be made or opened is a
        storage fault the researcher sees; it is tried again before each game.
        """
        if self.lock.held:
            return True
        try:
            self.lock.acquire()
        except StateDirBusy as busy:
            if at_start:
                raise
            self._pending_faults.append(HardwareFault(FaultSource.STORAGE, str(busy)))
            return False
        except OSError as error:
            detail = f"{self.state_dir}: cannot use the state directory: {error.strerror or error}"
            log.error("state directory unusable", state_dir=str(self.state_dir), error=detail)
            self._pending_faults.append(HardwareFault(FaultSource.STORAGE, detail))
            return False
        return True

    async def _run(self) -> int:
        faulthandler.enable()  # a watchdog abort leaves every thread's stack in the journal
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(signum, self.request_stop, signal.Signals(signum).name)
        loop.add_signal_handler(signal.SIGHUP, self._request_reload)
        if os.environ.get(DEBUG_BLOCK_ENV):
            # For an engineer to prove the watchdog restarts a hung service.
            loop.add_signal_handler(signal.SIGUSR2, self._block_loop)
        # Read once (a broken file stops the start, before READY), and again at a reload.
        self._book = phrasebook_for(self.config)
        if self.hw is None:
            self.hw = self._build_hardware()
        await self._open_hardware()
        watchdog = asyncio.create_task(self._watchdog(), name="watchdog")
        self.notifier.ready(STATUS_WORDS["idle"])
        log.info("ready", sim=self.options.sim, state_dir=str(self.state_dir))
        try:
            while not self._stopping.is_set():
                await self._one_session()
        finally:
            watchdog.cancel()
            await asyncio.gather(watchdog, return_exceptions=True)
            await self._stop_hardware()
            self.notifier.close()
        return 0

    def request_stop(self, reason: str) -> None:
        """Stop the service: the session is left to resume, Kaspar goes to rest."""
        if not self._stopping.is_set():
            self._stop_reason = reason
            self.notifier.stopping(f"stopping ({reason})")
            log.info("stopping", reason=reason)
            self._stopping.set()

    def _build_hardware(self) -> Hardware:
        clock = LoopClock()
        return build(
            self.config.servos,
            self.config.keyfob,
            self.config.voice,
            clock,
            researcher=self.config.researcher,
            sim=self.options.sim,
            sim_keys_fifo=self.options.keys,
        )

    async def _open_hardware(self) -> None:
        assert self.hw is not None
        servos = self.hw.servos
        try:
            await servos.start()
            for group in servos.groups:
                # Goal := present position, then torque on: a restart never jerks.
                await servos.set_compliant(group, False)
        except HalError as error:
            # Recorded and spoken, not fatal: the researcher sees the fault and acts.
            log.error("servos not ready", error=str(error))
            detail = f"servos not ready: {error}"
            self._pending_faults.append(HardwareFault(FaultSource.SERVO, detail))
        await self.hw.keyfob.start()
        if self.hw.researcher is not None:
            await self.hw.researcher.start()
        if not self.options.sim:
            self._batteries = low_batteries(self.config)
            if self._batteries:
                log.warning("battery low", batteries=self._batteries)
                self._say_batteries = True
        await self._open_body()

    async def _open_body(self) -> None:
        """The body the configuration asks for; a bad behaviour file leaves Kaspar still,
        said once in the journal, and the game goes on (the body is no part of the study's
        records)."""
        assert self.hw is not None
        try:
            self.body = make_body(self.config, self.hw.servos, self.hw.voice)
        except BehaviourError as error:
            log.error("body language off: a behaviour file is wrong", error=str(error))
            self.body = StillBody()
        await self.body.start()

    async def _one_session(self) -> None:
        resumed, stopped = self._read_sessions()
        faults, self._pending_faults = self._pending_faults, []
        game = self._new_game(resumed, stopped, faults)
        await self._play(game)
        self._robot_wide()
        # What the disk still refuses is written by the next game (or before the next read).
        self.lasting.recorder.flush()
        self.lasting.problems.game_ended()
        if game.session is not None:
            game.session.close()
        if game.stopped_waiting is not None:
            game.stopped_waiting.session.close()  # neither reopened nor closed in this game
        if self._reload:
            self._apply_reload()

    def _robot_wide(self) -> None:
        """The voice and the joints' speed as the robot has them, a session's own ended
        (the next game's session takes its own)."""
        if self.hw is None:
            return
        try:
            self.hw.voice.configure(self.config.voice)
            self.hw.servos.scale_speeds(self.config.game.speed_scale)
        except Exception as error:  # never the end of the robot: logged, the next game goes on
            log.error("the robot-wide voice or speed could not be restored", error=str(error))

    def _read_sessions(self) -> tuple[OpenedSession | None, OpenedSession | None]:
        """The session to resume, or else the stopped one waiting for the researcher.

        What keeps them from being read (the directory not locked, the disk, a bug) is a
        fault for the next game to begin with.
        """
        resumed = stopped = None
        self._resumable = None
        self._read_again = False
        unread = True
        if self._take_lock():
            self.lasting.recorder.flush()  # what an earlier game kept, before the sessions are read
            try:
                resumed = self._resume()
                stopped = None if resumed is not None else self._stopped_waiting()
                unread = False
            except StorageFailed as error:
                detail = f"cannot read the sessions in {self.state_dir}: {error}"
                log.error("sessions unreadable", state_dir=str(self.state_dir), error=str(error))
                self._pending_faults.append(HardwareFault(FaultSource.STORAGE, detail, error=error))
            except Exception as error:  # a bug reading them must not stop the robot either
                log.error("sessions could not be read", exc_info=error)
                detail = f"cannot read the sessions in {self.state_dir}: {error!r}"
                self._pending_faults.append(HardwareFault(FaultSource.SOFTWARE, detail))
        # Until the sessions are read (and the directory locked) no session may start:
        # a resume from the fault ends this game, and the next one reads them again.
        self._read_again = unread or any(
            fault.kind is FaultSource.STORAGE for fault in self._pending_faults
        )
        return resumed, stopped

    def _new_game(
        self,
        resumed: OpenedSession | None,
        stopped: OpenedSession | None,
        faults: Sequence[HardwareFault],
    ) -> Game:
        """The next game, followed by the daemon's status and listeners."""
        assert self.hw is not None and self._book is not None  # opened and read in _run
        picker = PhrasePicker(self._book, np.random.default_rng())
        game = Game(
            Setup(self._config_of(resumed or stopped), self.hw, picker, self.body),
            self.lasting,
            Start(resumed, stopped, faults),
        )
        game.listeners.append(self._on_game_event)
        game.listeners.extend(self.listeners)
        self.game = game
        self.notifier.status(self._status(game))
        if self._say_abandoned:
            self._say_abandoned = False
            game.speech.announce_soon("session.abandoned")
        if self._say_batteries:
            self._say_batteries = False
            game.speech.announce_soon("fault.remote_battery_low")
        return game

    async def _play(self, game: Game) -> None:
        """Play `game` until it ends, or the service stops (its session left to resume)."""
        playing = asyncio.create_task(game.run(), name="game")
        self._playing = playing
        stopping = asyncio.create_task(self._stopping.wait())
        await asyncio.wait({playing, stopping}, return_when=asyncio.FIRST_COMPLETED)
        stopping.cancel()
        if not playing.done():
            if game.session is not None:
                game.note_shutdown(self._stop_reason)
            playing.cancel()
            await asyncio.gather(playing, return_exceptions=True)
        elif not playing.cancelled() and (failure := playing.exception()) is not None:
            # The game catches what it can; this is a bug it could not. The next game
            # begins in its fault stage rather than loop: the researcher decides.
            log.error("game ended by an error", exc_info=failure)
            detail = f"the game ended by an error: {failure!r}"
            self._pending_faults.append(HardwareFault(FaultSource.SOFTWARE, detail))
        if self._ending is not None:
            await asyncio.gather(self._ending, return_exceptions=True)
            self._ending = None
        self._playing = None

    def _status(self, game: Game) -> str:
        """STATUS=: the stage, Kaspar confused (and what reopen would do), the problems."""
        confused = recovery_words(game.session_state, game.settings)
        waiting = None
        stopped = game.stopped_waiting
        if game.stage == "idle" and game.session is None and stopped is not None:
            waiting = (
                f"waiting: 'next' reopens group {stopped.plan.group}, session "
                f"{stopped.plan.number} (stopped), 'stop' closes it"
            )
        elif game.stage == "idle" and game.session is None:
            with contextlib.suppress(Exception):  # the words must never stop the robot
                waiting = self.queue.words()
        notices = " | ".join(n for n in (self._notice, self._batteries) if n) or None
        battery = battery_words(self.hw.servos.battery() if self.hw is not None else None)
        clock = self.lasting.clock.last if self.lasting.clock is not None else None
        unsynchronised = clock is not None and not clock.source.synchronised
        return status_line(
            game.stage, game.problems, notices, confused, battery, waiting, unsynchronised
        )

    def _on_game_event(self, event: GameEvent, info: dict[str, Any]) -> None:
        game = self.game
        if game is None or event not in _STATUS_EVENTS:
            return
        if event is GameEvent.SESSION:
            self._notice = None  # the next session has begun: the abandoned one is old news
        self.notifier.status(self._status(game))
        if event is GameEvent.STATE and info["state"] == "idle" and self._read_again:
            # Resumed from the storage fault: read the sessions again before any starts.
            self._read_again = False
            self._end_game()

    def _end_game(self) -> None:
        playing = self._playing
        if playing is None or playing.done() or self._ending is not None:
            return
        self._ending = asyncio.get_running_loop().create_task(self._cancel_until_done(playing))

    @staticmethod
    async def _cancel_until_done(playing: asyncio.Task[str]) -> None:
        # transitions takes a cancellation that lands inside a trigger for a newer
        # trigger's and swallows it (the game would play on, its sessions unread):
        # cancelled again until it has ended.
        while not playing.done():
            playing.cancel()
            await asyncio.wait({playing}, timeout=GAME_CANCEL_GRACE_S)

    # -- sessions --------------------------------------------------------------------

    def _config_of(self, resumed: OpenedSession | None) -> Config:
        """The configuration a game plays: a resumed (or reopened) session keeps the learner
        it began with."""
        return self._resumable.config(self.config) if resumed and self._resumable else self.config

    def _resume(self) -> OpenedSession | None:
        """The unfinished session to carry on; each that cannot be is abandoned on the way.

        StorageFailed when the sessions cannot be read or an abandon cannot be written.
        """
        clock = asyncio.get_running_loop().time()
        outcome = resume_or_abandon(self.state_dir, self.config.game, self.config.profile, clock)
        for abandoned in outcome.abandoned:
            self._note_abandoned(abandoned, clock)
        resumable = self._resumable = outcome.resumable
        if resumable is None:
            return None
        session, state = resumable.session, resumable.state
        log.info("resuming session", session=session.id, step=state.step, trials=state.trials)
        if session.repairs:
            # A crash tore the last record (never fsynced, so never reacted to): said.
            self._notice = f"session {session.id} resumed after a crash: " + "; ".join(
                session.repairs
            )
        return OpenedSession(session, resumable.plan, state, resumable.settings(self.config))

    def _note_abandoned(self, abandoned: Abandoned, clock: float) -> None:
        """Shown in STATUS=, said when the game begins, and in the event log."""
        what = f"session {abandoned.session_id} abandoned (cannot be resumed): {abandoned.reason}"
        self._notice = what
        self._say_abandoned = True
        record = SessionRecord(
            event=SessionEvent.ABANDONED,
            reason=f"{abandoned.session_id}: {abandoned.reason}",
            state="idle",
        )
        self.events.record(record, clock)  # StorageFailed: a storage fault, as any

    def _open_session(self) -> OpenedSession:
        plan = self._next_plan()
        seed = (
            self.config.game.seed if self.config.game.seed is not None else secrets.randbelow(2**31)
        )
        opened = open_new(self.state_dir, self.config, plan, seed)
        log.info(
            "session opened", session=opened.session.id, group=plan.group, condition=plan.condition
        )
        return opened

    def _next_plan(self) -> SessionPlan:
        """The researcher's choice, else the first planned session (group and number) not
        yet ended and not absent; then the last again (kasparctl.game.opening.PlanQueue).

        A session ends finished, or stopped (the researcher then reopens it with "next",
        or closes it with "stop": a stopped session waits for that choice, see
        _stopped_waiting).
        """
        return self.queue.take(lambda: asyncio.get_running_loop().time())

    def _stopped_waiting(self) -> OpenedSession | None:
        """The latest session, if the researcher stopped it and has not closed it yet.

        StorageFailed when it cannot be read; a stopped session that cannot be reopened
        (its records damaged since, its learner gone) stays closed, with a warning.
        """
        # A group marked absent was never opened: it is no session waiting.
        directories = [d for d in session_dirs(self.state_dir) if not is_absence(d)]
        if not directories:
            return None
        latest = directories[-1]
        if not is_finished(latest) or abandoned_reason(latest) is not None:
            return None
        records = read_records(latest / RECORDS_FILE).records
        ends = [r.to for r in records if isinstance(r, StepRecord) and r.to in ENDS]
        closed = any(
            isinstance(r, SessionRecord) and r.event is SessionEvent.CLOSED for r in records
        )
        if not ends or ends[-1] != "stopped" or closed:
            return None
        try:
            resumable = reopen(latest, self.config.game, self.config.profile)
        except CannotResume as error:
            log.warning(
                "a stopped session cannot be reopened; it stays closed",
                session=latest.name,
                reason=error.reason,
            )
            return None
        self._resumable = resumable
        log.info("a stopped session waits: next reopens it, stop closes it", session=latest.name)
        settings = resumable.settings(self.config)
        return OpenedSession(resumable.session, resumable.plan, resumable.state, settings)

    # -- signals, reload, watchdog ------------------------------------------------------

    def _request_reload(self) -> None:
        token = self._reload_desk.token()
        game = self.game
        if game is not None and game.session is not None:
            log.warning(
                "reload refused: a session is running; send SIGHUP again once it has ended",
                session=game.session.id,
            )
            self._reload_desk.answer(
                token, Outcome.REFUSED, f"a session is running ({game.session.id}); reload after it"
            )
            return
        self._reload = True
        self._reload_tokens.append(token)
        # Ending the idle game lets the session loop reload before the next one.
        self._end_game()

    def _apply_reload(self) -> None:
        self._reload = False
        tokens, self._reload_tokens = self._reload_tokens, []
        try:
            config = self._load()
            book = phrasebook_for(config)
            config, kept = restart_only(self.config, config, self.state_dir)
            if self.hw is not None:
                # The voice takes the new engine, voice, rate, volume and pitch now; each
                # session then speaks with its own (kasparctl.config.session_settings).
                self.hw.voice.configure(config.voice)
        except Exception as error:  # a bad file must not stop the robot
            log.error("reload failed; keeping the running configuration", error=str(error))
            for token in tokens:
                self._reload_desk.answer(token, Outcome.FAILED, str(error))
            return
        for key in kept:
            log.warning(
                "reload: takes effect at the next restart; the running value is kept", key=key
            )
        self.config, self._book = config, book
        log.info("configuration reloaded", sessions=len(self.config.sessions), restart_only=kept)
        for token in tokens:
            self._reload_desk.answer(token, Outcome.RELOADED)

    def _block_loop(self) -> None:
        seconds = float(os.environ.get(DEBUG_BLOCK_ENV, "0") or 0)
        log.warning("blocking the event loop on purpose", seconds=seconds)
        time.sleep(seconds)

    async def _watchdog(self) -> None:
        interval = watchdog_interval()
        if interval is None:
            return
        expected = asyncio.get_running_loop().time() + interval
        while True:
            await asyncio.sleep(interval)
            now = asyncio.get_running_loop().time()
            late, expected = now - expected, now + interval
            dead = self._dead_threads()
            if dead:
                log.error("watchdog withheld: hardware threads died", threads=dead)
                continue
            if late > LOOP_LAG_LIMIT_S:
                log.warning("event loop was unresponsive", late_s=round(late, 3))
            self.notifier.watchdog()

    def _dead_threads(self) -> list[str]:
        if self.options.sim or self.config.servos.backend != "real":
            return []
        alive = {thread.name for thread in threading.enumerate() if thread.is_alive()}
        return [
            f"bus {bus.name}" for bus in self.config.servos.buses if f"bus {bus.name}" not in alive
        ]

    async def _stop_hardware(self) -> None:
        hw = self.hw
        if hw is None:
            return
        hw.voice.cancel()
        # Before the rest: nothing of a behaviour may move a joint once Kaspar goes there.
        await self.body.close()
        try:
            async with asyncio.timeout(REST_TIMEOUT_S):
                await hw.servos.rest()
            if self.config.daemon.stop_action == "torque_off":
                for group in hw.servos.groups:
                    await hw.servos.set_compliant(group, True)
        except (HalError, TimeoutError) as error:
            log.error("could not bring Kaspar to rest", error=str(error) or "timed out")
        await hw.keyfob.close()
        if hw.researcher is not None:
            await hw.researcher.close()
        await hw.voice.close()
        await hw.servos.close()
        log.info("stopped", reason=self._stop_reason)


def run_daemon(options: DaemonOptions) -> int:
    """`kasparctl run`: the service in the foreground, logging as configured.

    StateDirBusy, before anything is opened, when another process writes there.
    """
    daemon = Daemon(options)
    configure_logging(daemon.config.logging.level, daemon.config.logging.format)
    # What the unit gave the thread that runs the event loop (and so the body loop).
    log_scheduling()
    return asyncio.run(daemon.run())
