"""Day one on a real robot, with the real daemon process: what used to leave it idle, deaf
and silent, and what must never happen to a state directory.

- the keyfob not there at boot (a Bluetooth keyfob pairs late, a USB one is plugged in
  late): the service says so in STATUS= and the journal, and a keyfob that comes later
  starts the session with no restart (the simulated keyfob's fifo appearing, and the
  real evdev reader finding nothing at start);
- no sound card (the player fails at once): the session is written, the fault is
  recorded with aplay's telling line, and stop works without sound;
- the sessions directory unusable: a storage fault the researcher resumes from;
- two writers on one state directory: the second exits at once, naming the holder;
- `kasparctl reload` (systemd's ExecReload=) fails when the daemon refuses;
- journald priorities: on the journal's stream every line carries its "<N>".
"""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from fault_rig import ALSA_NO_CARD
from service_fixtures import (
    DEMO_CONFIG,
    PHRASES,
    OutputLines,
    read_session_records,
    run_command,
    running_service,
    spoken,
    status_is,
)

from kasparctl.game.jsonl import read_records
from kasparctl.game.session import EVENTS_FILE
from kasparctl.service.reload import Outcome, request_reload

# Idle names the group "next" starts (the demo's plan: group demo), or reopens.
IDLE = "waiting: 'next' "
PLACING = "step 1: placing the bags"
pytestmark = pytest.mark.slow  # the service in real time


def config_with(tmp_path: Path, extra: str) -> Path:
    """The demo robot's configuration with more tables (voice, keyfob) appended."""
    path = tmp_path / "kaspar.toml"
    path.write_text(DEMO_CONFIG.read_text(encoding="utf-8") + "\n" + extra, encoding="utf-8")
    return path


def quick_speaker(tmp_path: Path) -> Path:
    """The demo robot, its simulated voice at the fastest rate: the tests wait for its lines."""
    return config_with(tmp_path, "[voice]\nrate = 450\n")


def log_lines(text: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def events_log(state_dir: Path) -> list[dict[str, Any]]:
    read = read_records(state_dir / EVENTS_FILE)
    assert not read.warnings, read.warnings
    return [json.loads(line) for line in (state_dir / EVENTS_FILE).read_text().splitlines()]


# -- the keyfob not there at boot ---------------------------------------------------------


def test_keyfob_absent_at_boot_is_shown_and_one_plugged_in_later_starts_the_session(
    tmp_path: Path,
) -> None:
    keys = tmp_path / "input" / "keyfob"
    keys.parent.mkdir()

    config = quick_speaker(tmp_path)

    def command(state_dir: Path) -> list[str]:
        return run_command(state_dir, config=config, extra=("--keys", str(keys)))

    with running_service(tmp_path, command=command) as service:
        service.notify.wait_for("READY=1")
        absent = service.notify.wait_for_status(lambda text: "keyfob not connected" in text)
        assert absent.startswith(IDLE) and "not available at start" in absent, absent
        warning = service.stdout.wait_for(lambda line: "keyfob not connected" in line)
        assert json.loads(warning)["level"] == "warning"
        # Kaspar says so, out loud, with nobody pressing anything.
        service.stderr.wait_for(lambda line: spoken(line, PHRASES["fault"]["keyfob_lost"]))

        mark = service.notify.mark()
        os.mkfifo(keys, 0o600)  # plugged in
        service.notify.wait_for_status(lambda text: text.startswith(IDLE), since=mark)
        fd = os.open(keys, os.O_WRONLY | os.O_NONBLOCK)
        try:
            os.write(fd, b"G")  # long green: no restart, no second gesture
        finally:
            os.close(fd)
        service.notify.wait_for_status(status_is(PLACING), since=service.notify.mark())
        assert service.stop() == 0
    events = [r.get("event") for r in events_log(service.state_dir) if r["kind"] == "hal"]
    assert events[:1] == ["keyfob_lost"] and "keyfob_back" in events
    kinds = [r["kind"] for r in read_session_records(service.state_dir)]
    assert kinds[:3] == ["session", "clock", "step"]  # the clock's state as it started


def test_the_real_keyfob_reader_finding_nothing_at_boot_is_shown(tmp_path: Path) -> None:
    (tmp_path / "input").mkdir()
    device = tmp_path / "input" / "kaspar-keyfob"
    config = config_with(tmp_path, f'[keyfob]\ndevice = "{device}"\n\n[voice]\nbackend = "sim"\n')

    def command(state_dir: Path) -> list[str]:
        return run_command(state_dir, config=config, sim=False)

    with running_service(tmp_path, command=command) as service:
        service.notify.wait_for("READY=1")
        status = service.notify.wait_for_status(lambda text: "keyfob not connected" in text)
        assert status.startswith(IDLE) and "ENOENT" in status, status
        line = service.stdout.wait_for(lambda text: "watching for it" in text)
        assert json.loads(line)["level"] == "warning"
        assert service.process.poll() is None
        assert service.stop() == 0
    lost = [r for r in events_log(service.state_dir) if r.get("event") == "keyfob_lost"]
    assert lost and "ENOENT" in lost[0]["reason"]


# -- no sound card ----------------------------------------------------------------------


def fake_aplay(tmp_path: Path) -> Path:
    """A player that fails as aplay does on a machine without a sound card."""
    script = tmp_path / "aplay"
    (tmp_path / "alsa.txt").write_text(ALSA_NO_CARD)
    script.write_text(f"#!/bin/sh\ncat {tmp_path / 'alsa.txt'} >&2\nexit 1\n")
    script.chmod(0o755)
    return script


def test_no_sound_card_the_session_is_written_the_fault_named_and_stop_needs_no_sound(
    tmp_path: Path,
) -> None:
    player = fake_aplay(tmp_path)
    config = config_with(
        tmp_path, f'[keyfob]\nbackend = "sim"\n\n[voice]\nplayer = ["{player}", "-q"]\n'
    )

    def command(state_dir: Path) -> list[str]:
        return run_command(state_dir, config=config, sim=False)

    with running_service(tmp_path, command=command) as service:
        service.notify.wait_for("READY=1")
        service.press("G")
        status = service.notify.wait_for_status(
            lambda text: text.startswith("fault") and "voice failing" in text
        )
        assert "cannot find card '0'" in status, status
        line = service.stdout.wait_for(
            lambda text: '"fault": "voice"' in text and '"event": "fault"' in text
        )
        assert json.loads(line)["level"] == "error"
        assert "cannot find card '0'" in json.loads(line)["detail"]
        # Stop without sound: applied at once, no line waited for.
        pressed = time.monotonic()
        service.press("b")
        service.notify.wait_for_status(lambda text: text.startswith("session stopped"))
        stop_took = time.monotonic() - pressed
        service.notify.wait_for_status(lambda text: text.startswith(IDLE))
        assert service.process.poll() is None  # the service goes on, waiting for the next
        assert service.stop() == 0
    records = read_session_records(service.state_dir)
    unheard = [r for r in records if r["kind"] == "hal" and r["event"] == "voice"]
    assert unheard and unheard[0]["status"] == "failed"
    # The telling line (the first) and the last, not just the end of stderr.
    assert "cannot find card '0'" in unheard[0]["error"]
    assert "audio open error" in unheard[0]["error"]
    faults = [r for r in records if r["kind"] == "fault"]
    assert faults and faults[0]["fault"] == "voice" and faults[0]["state"] == "placing"
    assert [r["to"] for r in records if r["kind"] == "step"] == ["placing", "stopped"]
    assert stop_took < 5.0, stop_took  # the long press itself, and no voice timeout (20 s)


# -- the state directory -----------------------------------------------------------------


def test_an_unusable_sessions_directory_is_a_storage_fault_the_researcher_resumes_from(
    tmp_path: Path,
) -> None:
    state_dir = tmp_path / "state"
    state_dir.mkdir()
    (state_dir / "sessions").write_text("")  # in the way: not a directory, even for root
    config = quick_speaker(tmp_path)

    def command(state_dir: Path) -> list[str]:
        return run_command(state_dir, config=config)

    with running_service(tmp_path, state_dir=state_dir, command=command) as service:
        service.notify.wait_for("READY=1")
        mark = service.notify.mark()
        service.press("G")
        status = service.notify.wait_for_status(
            lambda t: t.startswith("fault") and "CANNOT SAVE the records" in t, since=mark
        )
        assert "sessions: cannot create the state directory" in status, status
        service.stderr.wait_for(lambda line: spoken(line, PHRASES["fault"]["storage"]))
        assert service.process.poll() is None
        (state_dir / "sessions").unlink()  # the researcher clears the way
        mark = service.notify.mark()
        service.press("R")  # long red: resume
        # Until a session's record is written, the status still says records may fail.
        service.notify.wait_for_status(lambda t: t.startswith(IDLE), since=mark)
        service.press("G")
        service.notify.wait_for_status(status_is(PLACING), since=service.notify.mark())  # written: all well again
        assert service.stop() == 0
    faults = [r for r in events_log(state_dir) if r["kind"] == "fault"]
    assert faults[0]["fault"] == "storage" and faults[0]["state"] == "idle"
    assert len(list((state_dir / "sessions").iterdir())) == 1


def test_a_second_service_on_the_same_state_directory_exits_at_once(tmp_path: Path) -> None:
    with running_service(tmp_path) as first:
        first.notify.wait_for("READY=1")
        started = time.monotonic()
        second = subprocess.run(
            run_command(first.state_dir), capture_output=True, text=True, timeout=30,
            stdin=subprocess.DEVNULL,
        )  # fmt: skip
        took = time.monotonic() - started
        assert first.stop() == 0
    assert second.returncode == 1
    lines = second.stderr.strip().splitlines()
    assert len(lines) == 1, lines
    assert str(first.state_dir) in lines[0] and f"process {first.process.pid}" in lines[0]
    assert took < 10, took  # at once: no waiting for the lock


def demo(state_dir: Path, *arguments: str) -> list[str]:
    return [sys.executable, "-m", "kasparctl", "demo", "--state-dir", str(state_dir), *arguments]


def test_two_demos_on_one_state_directory_the_second_refuses_the_first_is_whole(
    tmp_path: Path,
) -> None:
    state_dir = tmp_path / "state"
    environment = os.environ | {"PYTHONUNBUFFERED": "1"}
    first = subprocess.Popen(
        demo(state_dir, "--speed", "40", "--seed", "3", "--variant", "pilot"),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=environment,
    )  # fmt: skip
    assert first.stdout is not None
    output = OutputLines(first.stdout)
    try:
        output.wait_for(lambda line: "Kaspar:" in line)  # the first is playing
        second = subprocess.run(
            demo(state_dir, "--fast", "--seed", "4"), capture_output=True, text=True, timeout=30
        )
        assert first.poll() is None, "the first demo ended before the second was refused"
    finally:
        code = first.wait(timeout=120)
    assert second.returncode == 1, second.stdout + second.stderr
    assert second.stderr.strip().count("\n") == 0
    assert str(state_dir) in second.stderr and f"process {first.pid}" in second.stderr
    assert code == 0, output.text()
    (_one_session,) = (state_dir / "sessions").iterdir()
    trials = [r["trial"] for r in read_session_records(state_dir) if r["kind"] == "trial"]
    assert trials == list(range(1, len(trials) + 1)) and trials
    seqs = [r["seq"] for r in read_session_records(state_dir)]
    assert seqs == list(range(1, len(seqs) + 1))


# -- reload --------------------------------------------------------------------------------


def reload(pid: int, runtime: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "kasparctl", "reload", "--pid", str(pid), "--timeout", "20"],
        capture_output=True, text=True, timeout=60, env=os.environ | {"RUNTIME_DIRECTORY": str(runtime)},
    )  # fmt: skip


def test_reload_answers_reloaded_between_sessions_and_fails_when_refused(tmp_path: Path) -> None:
    runtime = tmp_path / "run"
    runtime.mkdir(mode=0o700)
    config = quick_speaker(tmp_path)

    def command(state_dir: Path) -> list[str]:
        return run_command(state_dir, config=config)

    with running_service(tmp_path, {"RUNTIME_DIRECTORY": str(runtime)}, command=command) as service:
        service.notify.wait_for("READY=1")
        idle = reload(service.process.pid, runtime)
        assert idle.returncode == 0, idle.stderr
        assert idle.stderr.strip() == "kasparctl reload: reloaded"
        service.press("G")
        service.notify.wait_for_status(status_is(PLACING), since=service.notify.mark())
        refused = reload(service.process.pid, runtime)
        assert refused.returncode == 1
        assert refused.stderr.startswith("kasparctl reload: reload refused: a session is running")
        assert service.process.poll() is None
        assert service.stop() == 0


def test_reload_fails_when_nobody_answers(tmp_path: Path) -> None:
    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)  # a process that never answers
    try:
        verdict = request_reload(os.getpid(), tmp_path, timeout=0.2)
    finally:
        signal.signal(signal.SIGHUP, previous)
    assert verdict.outcome is Outcome.NO_ANSWER and not verdict.ok
    assert f"process {os.getpid()} did not answer" in verdict.detail


# -- journald priorities ---------------------------------------------------------------------


def test_on_the_journal_stream_each_line_carries_its_priority(tmp_path: Path) -> None:
    """As systemd runs it: JOURNAL_STREAM names the stdout's pipe, and journald would read
    "<N>" as each line's priority (SyslogLevelPrefix=)."""
    read_end, write_end = os.pipe()
    status = os.fstat(write_end)
    assert stat.S_ISFIFO(status.st_mode)
    keys = tmp_path / "absent-keyfob"
    config = tmp_path / "kaspar.toml"
    config.write_text(DEMO_CONFIG.read_text().replace('level = "warning"', 'level = "info"'))
    environment = os.environ | {"JOURNAL_STREAM": f"{status.st_dev}:{status.st_ino}"}
    environment.pop("NOTIFY_SOCKET", None)
    process = subprocess.Popen(
        run_command(tmp_path / "state", config=config, extra=("--keys", str(keys))),
        stdin=subprocess.DEVNULL, stdout=write_end, stderr=subprocess.DEVNULL, env=environment,
    )  # fmt: skip
    os.close(write_end)
    lines = OutputLines(os.fdopen(read_end))
    try:
        warning = lines.wait_for(lambda line: "keyfob not connected" in line)
        ready = lines.wait_for(lambda line: '"event": "ready"' in line)
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=30) == 0
    assert warning.startswith("<4>{") and json.loads(warning[3:])["level"] == "warning"
    assert ready.startswith("<6>{")
    assert all(line.startswith("<") for line in lines.text().splitlines())
