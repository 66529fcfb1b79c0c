"""`kasparctl run --sim` as systemd runs it: notify protocol, watchdog, signals, saved session."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from service_fixtures import NotifyListener, run_command, running_service

from kasparctl.game.session import RECORDS_FILE, STATE_FILE
from kasparctl.service.sdnotify import Notifier, watchdog_interval

WATCHDOG_USEC = 600_000  # pings expected every 0.3 s


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], NotifyListener, Path]]:
    watchdog = {"WATCHDOG_USEC": str(WATCHDOG_USEC), "KASPAR_DEBUG_LOOP_BLOCK_S": "2.0"}
    with running_service(tmp_path, watchdog) as (process, listener):
        yield process, listener, tmp_path / "state"


def test_ready_status_watchdog_and_a_clean_stop(daemon) -> None:
    process, listener, state_dir = daemon
    started = time.monotonic()
    listener.wait_for("READY=1")
    assert time.monotonic() - started < 30

    # The researcher's long green starts a session; STATUS follows the game.
    assert process.stdin is not None
    process.stdin.write("G")
    process.stdin.flush()
    listener.wait_for("STATUS=step 1: placing the bags")

    pings = [at for at, message in listener.collect(2.0) if message == "WATCHDOG=1"]
    assert 4 <= len(pings) <= 10, pings  # every 0.3 s, give or take a busy machine

    # A blocked loop sends nothing: that is what lets systemd restart a hung service.
    os.kill(process.pid, signal.SIGUSR2)
    blocked = listener.collect(1.5)
    assert not [m for _, m in blocked if m == "WATCHDOG=1"], blocked
    listener.wait_for("WATCHDOG=1", seconds=5)

    process.send_signal(signal.SIGTERM)
    listener.wait_for("STOPPING=1")
    assert process.wait(timeout=25) == 0

    # The session is saved, unfinished, to be resumed at the next start.
    (session_dir,) = (state_dir / "sessions").iterdir()
    snapshot = json.loads((session_dir / STATE_FILE).read_text())
    assert snapshot["finished"] is False
    records = [json.loads(line) for line in (session_dir / RECORDS_FILE).read_text().splitlines()]
    assert records[-1]["kind"] == "session" and records[-1]["event"] == "shutdown"
    assert records[-1]["reason"] == "SIGTERM"
    stdout = process.stdout.read() if process.stdout else ""
    for line in filter(None, stdout.splitlines()):
        json.loads(line)  # journald gets one JSON object a line, nothing else on stdout


def test_a_restart_resumes_the_session(tmp_path: Path) -> None:
    state_dir = tmp_path / "state"
    command = run_command(state_dir)
    first = subprocess.Popen(
        command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert first.stdin is not None
    time.sleep(3)
    first.stdin.write("G")
    first.stdin.flush()
    time.sleep(3)
    first.send_signal(signal.SIGINT)
    assert first.wait(timeout=25) == 0
    second = subprocess.Popen(
        command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    time.sleep(4)
    second.send_signal(signal.SIGTERM)
    _, err = second.communicate(timeout=25)
    assert second.returncode == 0, err
    (session_dir,) = (state_dir / "sessions").iterdir()
    records = [json.loads(line) for line in (session_dir / RECORDS_FILE).read_text().splitlines()]
    events = [r.get("event") for r in records if r["kind"] == "session"]
    assert events == ["start", "shutdown", "resumed", "shutdown"]
    assert any(w in err for w in ("nap", "awake", "sleep"))  # Kaspar says it resumed


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
