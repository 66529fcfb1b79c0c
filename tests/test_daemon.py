"""`kasparctl run --sim` as systemd runs it: notify protocol, watchdog, signals, saved session."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import socket
import time
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path

import pytest
from service_fixtures import (
    DEMO_CONFIG,
    PHRASES,
    RunningService,
    log_event,
    read_session_records,
    running_service,
    spoken,
    status_is,
    wait_for_record,
)

from kasparctl.game.session import RECORDS_FILE, STATE_FILE
from kasparctl.service.daemon import DEBUG_BLOCK_ENV, Daemon, DaemonOptions
from kasparctl.service.sdnotify import Notifier, watchdog_interval
from kasparctl.sim.simtime import run

WATCHDOG_USEC = 600_000  # pings expected every 0.3 s
PING_INTERVAL_S = WATCHDOG_USEC / 2_000_000
BLOCK_S = 1.5  # the loop blocked on purpose: over the daemon's 1 s lag limit plus a ping


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[RunningService]:
    watchdog = {"WATCHDOG_USEC": str(WATCHDOG_USEC), DEBUG_BLOCK_ENV: str(BLOCK_S)}
    with running_service(tmp_path, watchdog) as service:
        yield service


def _logged(event: str) -> Callable[[str], bool]:
    return lambda line: log_event(line, event) is not None


@pytest.mark.slow  # the service in real time: a long green, a spoken line, a blocked loop
def test_ready_status_watchdog_and_a_clean_stop(daemon: RunningService) -> None:
    notify = daemon.notify
    notify.wait_for("READY=1")
    notify.wait_for("WATCHDOG=1")  # the running loop pings (its pace: see the simulated test)

    # The researcher's "next" (G) starts a session: Kaspar greets the children first.
    pressed = notify.mark()
    daemon.press("G")
    daemon.stderr.wait_for(lambda line: spoken(line, PHRASES["session"]["greeting"]))

    # A blocked loop sends nothing: that is what lets systemd restart a hung service.
    # (Blocked while Kaspar speaks, the line's timer runs out meanwhile: no time lost.)
    os.kill(daemon.process.pid, signal.SIGUSR2)
    line = daemon.stdout.wait_for(_logged("blocking the event loop on purpose"))
    # The loop logs, then blocks: every ping it sent before is already queued, and
    # none can come until BLOCK_S after the line's own timestamp.
    blocked_at = datetime.fromisoformat(json.loads(line)["timestamp"]).timestamp()
    notify.drain()
    window = blocked_at + BLOCK_S - 0.05 - time.time()
    assert window > PING_INTERVAL_S, f"saw the block too late to watch it ({window:.2f} s left)"
    blocked = notify.collect(window)
    assert not [m for m in blocked if "WATCHDOG=1" in m.split("\n")], blocked
    unblocked = daemon.stdout.wait_for(_logged("event loop was unresponsive"))
    assert json.loads(unblocked)["late_s"] >= BLOCK_S - PING_INTERVAL_S - 0.01
    notify.wait_for("WATCHDOG=1")  # pings again once the loop runs

    # STATUS follows the game (it may have come while the pings were watched).
    notify.wait_for_status(status_is("step 1: placing the bags"), since=pressed)

    daemon.process.send_signal(signal.SIGTERM)
    notify.wait_for("STOPPING=1")
    assert daemon.process.wait(timeout=25) == 0

    # The session is saved, unfinished, to be resumed at the next start.
    (session_dir,) = (daemon.state_dir / "sessions").iterdir()
    snapshot = json.loads((session_dir / STATE_FILE).read_text())
    assert snapshot["finished"] is False
    records = [json.loads(line) for line in (session_dir / RECORDS_FILE).read_text().splitlines()]
    assert records[-1]["kind"] == "session" and records[-1]["event"] == "shutdown"
    assert records[-1]["reason"] == "SIGTERM"
    for line in filter(None, daemon.stdout.text().splitlines()):
        json.loads(line)  # journald gets one JSON object a line, nothing else on stdout


class RecordedNotifier(Notifier):
    """Keeps what would go to systemd, with the loop's (simulated) time of each datagram."""

    def __init__(self) -> None:
        super().__init__("")
        self.sent: list[tuple[float, tuple[str, ...]]] = []

    def notify(self, *fields: str) -> bool:
        """Keeps the datagram instead of sending it."""
        self.sent.append((asyncio.get_running_loop().time(), fields))
        return True


def test_the_watchdog_pings_every_half_watchdog_usec(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("WATCHDOG_USEC", str(WATCHDOG_USEC))
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    notifier = RecordedNotifier()
    daemon = Daemon(DaemonOptions(str(DEMO_CONFIG), sim=True, state_dir=str(tmp_path)), notifier)

    async def three_seconds_of_pings() -> float:
        start = asyncio.get_running_loop().time()
        watchdog = asyncio.create_task(daemon._watchdog())
        await asyncio.sleep(3 + PING_INTERVAL_S / 2)  # simulated: the span being measured
        watchdog.cancel()
        await asyncio.gather(watchdog, return_exceptions=True)
        return start

    start = run(three_seconds_of_pings(), virtual=True)
    assert {fields for _, fields in notifier.sent} == {("WATCHDOG=1",)}
    offsets = [at - start for at, _ in notifier.sent]
    assert offsets == pytest.approx([PING_INTERVAL_S * n for n in range(1, 11)])


@pytest.mark.slow  # the service in real time, started twice
def test_a_restart_resumes_the_session(tmp_path: Path) -> None:
    state_dir = tmp_path / "state"
    with running_service(tmp_path, state_dir=state_dir) as first:
        first.notify.wait_for("READY=1")
        first.press("G")
        wait_for_record(state_dir, lambda r: r["kind"] == "step" and r.get("to") == "placing")
        assert first.stop(signal.SIGINT) == 0
    with running_service(tmp_path, state_dir=state_dir) as second:
        # Kaspar says it resumed, after the "resumed" record is on disk.
        second.stderr.wait_for(lambda line: spoken(line, PHRASES["session"]["resumed"]))
        assert second.stop(signal.SIGTERM) == 0, second.stderr.lines
    sessions = [r for r in read_session_records(state_dir) if r["kind"] == "session"]
    assert [r["event"] for r in sessions] == ["start", "shutdown", "resumed", "shutdown"]
    assert [r.get("reason") for r in sessions if r["event"] == "shutdown"] == ["SIGINT", "SIGTERM"]
    assert sessions[2]["step"] == "placing"  # where it was stopped
    assert len({path.name for path in (state_dir / "sessions").iterdir()}) == 1


def test_notifier_speaks_the_protocol_to_abstract_and_path_sockets(tmp_path: Path) -> None:
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    name = f"kaspar-test-{os.getpid()}"
    listener.bind("\0" + name)
    listener.settimeout(5)
    notifier = Notifier("@" + name)
    assert notifier.ready("waiting")
    assert listener.recv(100) == b"READY=1\nSTATUS=waiting"
    notifier.close()
    listener.close()
    assert not Notifier("").enabled
    assert not Notifier(str(tmp_path / "nobody-listens")).notify("WATCHDOG=1")


def test_watchdog_interval_is_half_of_watchdog_usec(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WATCHDOG_USEC", "10000000")
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    assert watchdog_interval() == 5.0
    monkeypatch.setenv("WATCHDOG_PID", "1")  # meant for another process
    assert watchdog_interval() is None
    monkeypatch.delenv("WATCHDOG_USEC")
    assert watchdog_interval() is None


def test_next_session_is_the_first_planned_group_not_finished(tmp_path: Path) -> None:
    from kasparctl.config import GameSettings
    from kasparctl.game.session import Session
    from kasparctl.game.state import GameState
    from kasparctl.learning.learner import LearnerParams
    from kasparctl.service.daemon import Daemon, DaemonOptions

    ended = GameState.new(GameSettings(), LearnerParams(), seed=1)
    example = Path(__file__).resolve().parents[1] / "systemd" / "kaspar.toml"  # groups A1, A2
    daemon = Daemon(DaemonOptions(str(example), sim=True, state_dir=str(tmp_path)), Notifier(""))
    assert daemon._next_plan().group == "A1"
    unfinished = Session.create(tmp_path, {"group": "A1"})
    assert daemon._next_plan().group == "A1"  # interrupted, not done
    unfinished.save_state(ended, finished=True)
    assert daemon._next_plan().group == "A2"
    Session.create(tmp_path, {"group": "A2"}).save_state(ended, finished=True)
    assert daemon._next_plan().group == "A2"  # all done: the last group plays again
