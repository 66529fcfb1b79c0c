"""The soak's faults: injected one at a time into a running game, each followed until it is
recorded and the game has recovered, and every step written to a ledger that survives SIGKILL.

A fault counts as recorded only when it is on disk where the researchers and the
engineer will look: the session's records (a servo, keyfob or voice fault) or the
daemon's log (bus replies retried, which never reach the game).
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from soak_rig import EmulatedServos, HangingSink, MonitoredHerkulex

from hal.keyfob.sim import SimKeyfob
from hal.servos.bus import BusState
from kasparctl.game.machine import Game
from kasparctl.game.session import RECORDS_FILE

# Each kind is injected in turn as a game's first fault (so a short soak sees them all),
# then at random.
KINDS = (
    "servo_timeout",
    "corrupt_burst",
    "corrupt_retried",
    "adapter_unplug",
    "keyfob_unplug",
    "tts_hang",
    "sigkill",
)
# Simulated seconds between one fault's end and the next.
GAP_S = (5.0, 90.0)
# How long a fault lasts, in poll intervals: at least one, so that it is seen.
DURATION_POLLS = (1.2, 3.0)
# Past this (simulated seconds after the fault ended) a fault not recorded, or a game
# not recovered, is reported as such.
FOLLOW_S = 240.0
CHECK_EVERY_S = 0.25
# A SIGKILL lands at a random moment within this many real seconds of being armed:
# mid-record, mid-motion, mid-speech.
KILL_DELAY_S = (0.0, 0.003)
MAX_KILLS_PER_GAME = 2


class Ledger:
    """Append-only JSON lines, fsynced one by one: what was injected survives a SIGKILL."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()  # the emulator thread reports violations too

    def write(self, **entry: Any) -> None:
        line = (json.dumps(entry, sort_keys=True) + "\n").encode()
        with self._lock:
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o600)
            try:
                os.write(fd, line)
                os.fsync(fd)
            finally:
                os.close(fd)

    def entries(self) -> list[dict[str, Any]]:
        if not self.path.exists():
            return []
        lines = self.path.read_bytes().split(b"\n")
        return [json.loads(line) for line in lines if line.strip()]


class Tail:
    """The whole JSON lines appended to a file since the last look."""

    def __init__(self, path: Callable[[], Path | None]) -> None:
        self._path = path
        self._offset = 0
        self._current: Path | None = None

    def skip_to_end(self) -> None:
        path = self._path()
        self._current = path
        self._offset = path.stat().st_size if path is not None and path.exists() else 0

    def new(self) -> list[dict[str, Any]]:
        path = self._path()
        if path is None or not path.exists():
            return []
        if path != self._current:
            self._current, self._offset = path, 0
        with path.open("rb") as handle:
            handle.seek(self._offset)
            data = handle.read()
        end = data.rfind(b"\n") + 1
        self._offset += end
        found = []
        for line in data[:end].split(b"\n"):
            if line.strip():
                try:
                    found.append(json.loads(line))
                except json.JSONDecodeError:
                    continue
        return found


def is_evidence(kind: str, info: dict[str, Any], entry: dict[str, Any]) -> bool:
    """Whether a record (or, for retried replies, a log line) shows the injected fault."""
    record_kind, detail = entry.get("kind"), str(entry.get("detail", ""))
    if kind == "servo_timeout":
        return record_kind == "fault" and f"servo {info['servo_id']} on bus" in detail
    if kind == "corrupt_burst":
        return record_kind == "fault" and "no valid reply" in detail
    if kind == "adapter_unplug":
        return record_kind == "fault" and ("bus_lost" in detail or "not available" in detail)
    if kind == "keyfob_unplug":
        return record_kind == "hal" and entry.get("event") == "keyfob_lost"
    if kind == "tts_hang":
        return record_kind == "hal" and entry.get("event") == "voice" and (
            entry.get("status") == "timed_out"
        )
    if kind == "corrupt_retried":
        return entry.get("event") == "bus replies retried"
    raise ValueError(f"unknown fault kind {kind!r}")


@dataclass
class StateWatch:
    """A game listener: when the game last left its fault state, and whether it is over."""

    left_fault_at: float = -1.0
    state: str = "idle"
    resumed: list[Callable[[], None]] = field(default_factory=list)

    def __call__(self, event: str, info: dict[str, Any]) -> None:
        if event == "state":
            if self.state == "fault" and info["state"] != "fault":
                self.left_fault_at = asyncio.get_running_loop().time()
            self.state = str(info["state"])
        elif event == "resumed":
            for hook in self.resumed:
                hook()

    @property
    def over(self) -> bool:
        return self.state in ("finished", "stopped")


@dataclass
class Injector:
    """Injects a game's faults one after another, following each to its end."""

    game: Game
    servos: EmulatedServos
    emulator: MonitoredHerkulex
    keyfob: SimKeyfob
    sink: HangingSink
    ledger: Ledger
    log_path: Path
    rng: np.random.Generator
    first_kind: str
    faults: int
    may_kill: bool
    watch: StateWatch
    kill_armed: bool = False

    async def run(self) -> None:
        while self.game.session is None:
            await asyncio.sleep(1.0)
        for index in range(self.faults):
            await asyncio.sleep(float(self.rng.uniform(*GAP_S)))
            if self.watch.over:
                return
            kind = self.first_kind if index == 0 else str(self.rng.choice(KINDS))
            if kind == "sigkill":
                if not self.may_kill:
                    continue
                self._kill()
                return
            await self._one(kind)

    def _records_path(self) -> Path | None:
        session = self.game.session
        return None if session is None else session.directory / RECORDS_FILE

    async def _one(self, kind: str) -> None:
        loop = asyncio.get_running_loop()
        records = Tail(self._records_path)
        log = Tail(lambda: self.log_path)
        records.skip_to_end()
        log.skip_to_end()
        poll = self.servos.settings.poll_interval_s
        duration = float(self.rng.uniform(*DURATION_POLLS)) * poll
        info: dict[str, Any] = {"state": self.watch.state}
        injected = loop.time()
        heal = await self._inject(kind, info)
        healed_at: float | None = None
        recorded_at: float | None = None
        recovered_at: float | None = None
        evidence: dict[str, Any] | None = None
        stops_game = kind not in ("corrupt_retried", "tts_hang")
        while True:
            now = loop.time()
            if heal is not None and now >= injected + duration:
                await heal()
                heal, healed_at = None, loop.time()
            if recorded_at is None:
                source = log if kind == "corrupt_retried" else records
                for entry in source.new():
                    if is_evidence(kind, info, entry):
                        recorded_at, evidence = loop.time(), entry
                        break
            if recorded_at is not None and recovered_at is None:
                if not stops_game:
                    recovered_at = recorded_at
                elif self.watch.left_fault_at >= recorded_at:
                    recovered_at = self.watch.left_fault_at
            finished = heal is None and (recovered_at is not None or self.watch.over)
            if finished or now > injected + duration + FOLLOW_S:
                break
            await asyncio.sleep(CHECK_EVERY_S)
        if heal is not None:
            await heal()
        self.ledger.write(
            event="fault",
            kind=kind,
            info=info,
            injected_at=injected,
            healed_after=None if healed_at is None else healed_at - injected,
            recorded_after=None if recorded_at is None else recorded_at - injected,
            recovered_after=None if recovered_at is None else recovered_at - injected,
            game_over=self.watch.over,
            evidence=None if evidence is None else _brief(evidence),
        )

    async def _inject(self, kind: str, info: dict[str, Any]) -> Callable[[], Any] | None:
        """Start the fault; returns what ends it (None when it ends by itself)."""
        emulator = self.emulator
        if kind == "servo_timeout":
            joints = self.servos.settings.joints
            joint = joints[int(self.rng.integers(len(joints)))]
            info.update(joint=joint.name, servo_id=joint.id)
            emulator.faults.silent.add(joint.id)

            async def answer_again() -> None:
                emulator.faults.silent.discard(joint.id)

            return answer_again
        if kind in ("corrupt_burst", "corrupt_retried"):
            retries = self.servos.settings.buses[0].retries
            # Up to `retries` corrupt replies are absorbed by the bus; one more fails the read.
            count = retries + 1
            if kind == "corrupt_retried":
                count = int(self.rng.integers(1, retries + 1))
            info.update(corrupt_replies=count)
            emulator.faults.corrupt_next = count
            return None
        if kind == "adapter_unplug":
            emulator.unplug()

            async def plug_back() -> None:
                emulator.plug()
                # The bus thread reopens it on its own backoff, in real time; the
                # simulated clock is held meanwhile (hal.clock.thread_work).
                started = time.monotonic()
                back = await self.servos.driver.bus.wait_state(BusState.CONNECTED, timeout=10.0)
                info.update(reconnected=back, reconnect_real_s=time.monotonic() - started)

            return plug_back
        if kind == "keyfob_unplug":
            await self.keyfob.perform("lost")

            async def plug_keyfob() -> None:
                await self.keyfob.perform("back")

            return plug_keyfob
        if kind == "tts_hang":
            self.sink.hang_next = True
            return None
        raise ValueError(f"unknown fault kind {kind!r}")

    def _kill(self) -> None:
        session = self.game.session
        records = 0
        if session is not None and (session.directory / RECORDS_FILE).exists():
            records = (session.directory / RECORDS_FILE).read_bytes().count(b"\n")
        delay = float(self.rng.uniform(*KILL_DELAY_S))
        self.ledger.write(
            event="fault",
            kind="sigkill",
            info={"state": self.watch.state, "delay_real_s": delay},
            records_at_kill=records,
            wall=time.time(),
            goals_checked=self.emulator.monitor.goals_checked,
        )
        self.kill_armed = True
        timer = threading.Timer(delay, os.kill, (os.getpid(), signal.SIGKILL))
        timer.daemon = True
        timer.start()


def _brief(entry: dict[str, Any]) -> dict[str, Any]:
    keep = ("kind", "event", "fault", "detail", "status", "seq", "count")
    return {key: entry[key] for key in keep if key in entry}
