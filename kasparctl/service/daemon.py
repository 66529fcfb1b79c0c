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
session it is refused and logged.
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
from kasparctl.config import Config, SessionPlan, load_config
from kasparctl.game.events import GameEvent
from kasparctl.game.machine import Game
from kasparctl.game.phrases import PhrasePicker, load_phrasebook
from kasparctl.game.session import PLAN_FILE, Session, find_unfinished, is_finished, session_dirs
from kasparctl.game.state import GameState, restore
from kasparctl.log import configure_logging
from kasparctl.service.sdnotify import Notifier, watchdog_interval

log = structlog.get_logger("kasparctl.service.daemon")

STATUS_WORDS = {
    "idle": "waiting: long green starts the session",
    "placing": "step 1: placing the bags",
    "teaching": "step 2: teaching Kaspar to point",
    "revealing": "step 3: revealing the toys",
    "guessing": "step 4: Kaspar guesses the names",
    "farewell": "step 5: farewell",
    "finished": "session finished",
    "paused": "paused: long red resumes",
    "fault": "fault: see the journal; long red resumes once cleared",
    "stopped": "session stopped",
}
# The loop may blindly trust this much lateness of its own timer before it
# counts as unresponsive (a busy but healthy loop on a small board).
LOOP_LAG_LIMIT_S = 1.0
REST_TIMEOUT_S = 15.0
DEBUG_BLOCK_ENV = "KASPAR_DEBUG_LOOP_BLOCK_S"


@dataclass
class DaemonOptions:
    """How the service was started: its configuration, simulated hardware, another state dir."""

    config_path: str
    sim: bool = False
    state_dir: str | None = None


class Daemon:
    """The service: the hardware, one session after another, systemd's notifications, stopping."""

    def __init__(self, options: DaemonOptions, notifier: Notifier | None = None) -> None:
        """Load the configuration; nothing is opened until run()."""
        self.options = options
        self.config = self._load()
        self.notifier = notifier or Notifier()
        self.hw: Hardware | None = None
        self.game: Game | None = None
        self._stopping = asyncio.Event()
        self._stop_reason = ""
        self._reload = False

    def _load(self) -> Config:
        config = load_config(self.options.config_path)
        if self.options.state_dir is not None:
            config = msgspec.structs.replace(config, state_dir=self.options.state_dir)
        return config

    @property
    def state_dir(self) -> Path:
        """Where sessions are kept (the configuration's, or the one given at the start)."""
        return Path(self.config.state_dir)

    # -- the service ---------------------------------------------------------------

    async def run(self) -> int:
        """Run until SIGTERM or SIGINT; returns the exit status (0)."""
        faulthandler.enable()  # a watchdog abort leaves every thread's stack in the journal
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(signum, self.request_stop, signal.Signals(signum).name)
        loop.add_signal_handler(signal.SIGHUP, self._request_reload)
        if os.environ.get(DEBUG_BLOCK_ENV):
            # For an engineer to prove the watchdog restarts a hung service.
            loop.add_signal_handler(signal.SIGUSR2, self._block_loop)
        clock = LoopClock()
        self.hw = build(
            self.config.servos,
            self.config.keyfob,
            self.config.voice,
            clock,
            sim=self.options.sim,
        )
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
        await self.hw.keyfob.start()

    async def _one_session(self) -> None:
        assert self.hw is not None
        resumed = self._resume()
        book = load_phrasebook(self.config.language, self.config.phrases_dir)
        picker = PhrasePicker(book, np.random.default_rng())
        game = Game(self.config, self.hw, picker, self._open_session, resumed)
        game.listeners.append(self._on_game_event)
        self.game = game
        self.notifier.status(STATUS_WORDS.get(game.stage, game.stage))
        playing = asyncio.create_task(game.run(), name="game")
        stopping = asyncio.create_task(self._stopping.wait())
        await asyncio.wait({playing, stopping}, return_when=asyncio.FIRST_COMPLETED)
        stopping.cancel()
        if not playing.done():
            if game.session is not None:
                game.note_shutdown(self._stop_reason)
            playing.cancel()
            await asyncio.gather(playing, return_exceptions=True)
        elif not playing.cancelled() and playing.exception() is not None:
            log.error("game ended by an error", error=repr(playing.exception()))
        if game.session is not None:
            game.session.close()
        if self._reload:
            self._apply_reload()

    def _on_game_event(self, event: GameEvent, info: dict[str, Any]) -> None:
        if event is GameEvent.STATE:
            self.notifier.status(STATUS_WORDS.get(info["state"], info["state"]))

    # -- sessions --------------------------------------------------------------------

    def _resume(self) -> tuple[Session, SessionPlan, GameState] | None:
        directory = find_unfinished(self.state_dir)
        if directory is None:
            return None
        session, warnings = Session.open(directory)
        for warning in warnings:
            log.warning("session repaired", detail=warning)
        plan = msgspec.convert(session.plan["plan"], type=SessionPlan)
        snapshot, later = session.load_state()
        params = self.config.profile(plan.profile)
        state = restore(snapshot, later, self.config.game, params, session.plan.get("seed"))
        log.info("resuming session", session=session.id, step=state.step, trials=state.trials)
        return session, plan, state

    def _open_session(self) -> tuple[Session, SessionPlan, GameState]:
        plan = self._next_plan()
        seed = (
            self.config.game.seed if self.config.game.seed is not None else secrets.randbelow(2**31)
        )
        session = Session.create(
            self.state_dir,
            {
                "group": plan.group,
                "condition": plan.condition,
                "variant": self.config.game.variant,
                "seed": seed,
                "plan": msgspec.to_builtins(plan),
            },
            robot=self.config.robot(),
        )
        state = GameState.new(self.config.game, self.config.profile(plan.profile), seed)
        log.info("session opened", session=session.id, group=plan.group, condition=plan.condition)
        return session, plan, state

    def _next_plan(self) -> SessionPlan:
        """The first planned group without a finished session; then the last one again."""
        plans = self.config.sessions
        if not plans:
            return SessionPlan(group="unplanned")
        done = set()
        for directory in session_dirs(self.state_dir):
            if is_finished(directory):
                with contextlib.suppress(OSError, msgspec.DecodeError, KeyError, TypeError):
                    done.add(msgspec.json.decode((directory / PLAN_FILE).read_bytes())["group"])
        return next((plan for plan in plans if plan.group not in done), plans[-1])

    # -- signals, reload, watchdog ------------------------------------------------------

    def _request_reload(self) -> None:
        game = self.game
        if game is not None and game.session is not None:
            log.warning(
                "reload refused: a session is running; send SIGHUP again once it has ended",
                session=game.session.id,
            )
            return
        self._reload = True
        # Ending the idle game lets the session loop reload before the next one.
        for task in asyncio.all_tasks():
            if task.get_name() == "game":
                task.cancel()

    def _apply_reload(self) -> None:
        self._reload = False
        try:
            self.config = self._load()
            load_phrasebook(self.config.language, self.config.phrases_dir)
        except Exception as error:  # a bad file must not stop the robot
            log.error("reload failed; keeping the running configuration", error=str(error))
            return
        log.info("configuration reloaded", sessions=len(self.config.sessions))

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
        try:
            async with asyncio.timeout(REST_TIMEOUT_S):
                await hw.servos.rest()
            if self.config.daemon.stop_action == "torque_off":
                for group in hw.servos.groups:
                    await hw.servos.set_compliant(group, True)
        except (HalError, TimeoutError) as error:
            log.error("could not bring Kaspar to rest", error=str(error) or "timed out")
        await hw.keyfob.close()
        await hw.voice.close()
        await hw.servos.close()
        log.info("stopped", reason=self._stop_reason)


def run_daemon(options: DaemonOptions) -> int:
    """`kasparctl run`: the service in the foreground, logging as configured."""
    daemon = Daemon(options)
    configure_logging(daemon.config.logging.level, daemon.config.logging.format)
    return asyncio.run(daemon.run())
