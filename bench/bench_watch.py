"""`kasparctl watch` following a live demo: its CPU, and the delay from a record's fsync to
the screen.

Run on demand: .venv/bin/python bench/bench_watch.py [--live-seconds 90] [--demo-speed 8]
[--idle-seconds 30] [--probes 300]

The view runs full screen (rich) on a pseudo-terminal this script reads, as it
would on a researcher's ssh session, following a state directory:

1. live: beside `kasparctl demo --speed 8` (the names game: its five steps, then a
   question and its answer every few seconds). CPU of the view over the window, and for
   each question the delay from the record's time (stamped just before its write and
   fsync) to the first screen showing it.
2. between records: the demo killed, nothing written; the view still redraws once a
   second while "last record 12 s ago" ages. CPU over the window.
3. probes: this script writes question records itself into a new session of the same
   state directory, with the game's own Session.record (write, fsync), at random
   intervals, each naming a child "probe N"; the delay from the return of the fsync
   to the first screen bytes that show "probe N".
"""

from __future__ import annotations

import argparse
import datetime as dt
import fcntl
import os
import random
import re
import select
import signal
import statistics
import struct
import subprocess
import sys
import tempfile
import termios
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from view_records import question  # the records the view's tests write

from kasparctl.game.jsonl import read_records
from kasparctl.game.records import QuestionRecord, SessionEvent, SessionRecord, StepRecord
from kasparctl.game.session import RECORDS_FILE, Session, session_dirs

CPU_TARGET = 1.0  # percent of one core, between records
DELAY_TARGET_MS = 100.0  # p99, fsync to screen
TICKS = os.sysconf("SC_CLK_TCK")
ANSI = re.compile(rb"\x1b\[[0-9;?]*[A-Za-z]|\x1b[()][A-Z0-9]|\x1b[=>78]")
KASPARCTL = [sys.executable, "-m", "kasparctl"]


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime + stime


class Terminal:
    """The view on a pseudo-terminal of 80x24; every byte it draws, with when it came."""

    def __init__(self, state_dir: Path) -> None:
        self.master, slave = os.openpty()
        os.set_blocking(self.master, False)
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
        env = os.environ | {"TERM": "xterm-256color", "LANG": "C.UTF-8"}
        env.pop("NO_COLOR", None)
        self.process = subprocess.Popen(
            [*KASPARCTL, "watch", "--state-dir", str(state_dir)],
            stdin=slave,
            stdout=slave,
            stderr=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
        os.close(slave)
        self.text = b""  # the screen's text, escapes stripped, since the last mark
        self.arrivals: list[tuple[float, int]] = []  # (time.time() of a read, end offset)

    def pump(self, timeout: float) -> None:
        """Read what the view drew within `timeout` seconds."""
        readable, _, _ = select.select([self.master], [], [], timeout)
        if not readable:
            return
        try:
            data = os.read(self.master, 1 << 16)
        except BlockingIOError:
            return
        self.text += ANSI.sub(b"", data)
        self.arrivals.append((time.time(), len(self.text)))

    def drain(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.pump(left)

    def first_showing(self, needle: bytes) -> float | None:
        """When the screen first showed `needle` (wall clock), if it did."""
        at = self.text.find(needle)
        if at < 0:
            return None
        return next(t for t, end in self.arrivals if end >= at + len(needle))

    def wait_for(self, needle: bytes, since: int, seconds: float = 5.0) -> float:
        """The monotonic time at which `needle` appeared after offset `since`."""
        end = time.monotonic() + seconds
        while self.text.find(needle, since) < 0:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"{needle!r} not drawn within {seconds} s")
            self.pump(left)
        return time.monotonic()

    def close(self) -> None:
        os.killpg(self.process.pid, signal.SIGTERM)
        self.process.wait(timeout=10)
        os.close(self.master)


def percentile(values: list[float], fraction: float) -> float:
    ordered = sorted(values)
    return ordered[min(int(fraction * len(ordered)), len(ordered) - 1)]


def live(
    terminal: Terminal, state_dir: Path, seconds: float, speed: float
) -> tuple[float, list[float], int]:
    command = ["demo", "--speed", str(speed), "--seed", "11", "--p-wrong-red", "0.1"]
    demo = subprocess.Popen(
        [*KASPARCTL, *command, "--state-dir", str(state_dir)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        terminal.drain(3.0)  # the view takes up the new session
        cpu0, wall0 = cpu_seconds(terminal.process.pid), time.monotonic()
        (directory,) = session_dirs(state_dir)
        count0 = len(read_records(directory / RECORDS_FILE).records)
        terminal.drain(seconds)
        cpu = cpu_seconds(terminal.process.pid) - cpu0
        wall = time.monotonic() - wall0
    finally:
        demo.send_signal(signal.SIGKILL)
        demo.wait()
    written = read_records(directory / RECORDS_FILE).records
    delays = []
    for record in written:
        if isinstance(record, QuestionRecord):
            shown = terminal.first_showing(f"trial {record.trial} · {record.child}".encode())
            if shown is not None:
                stamped = _epoch(record.time)
                delays.append((shown - stamped) * 1000)
    return 100 * cpu / wall, delays, len(written) - count0


def _epoch(iso: str) -> float:
    return dt.datetime.fromisoformat(iso).timestamp()


def idle(terminal: Terminal, seconds: float) -> float:
    terminal.drain(1.0)
    cpu0, wall0 = cpu_seconds(terminal.process.pid), time.monotonic()
    terminal.drain(seconds)
    return 100 * (cpu_seconds(terminal.process.pid) - cpu0) / (time.monotonic() - wall0)


def probes(terminal: Terminal, state_dir: Path, count: int) -> list[float]:
    rng = random.Random(1)
    session = Session.create(
        state_dir,
        {"group": "probe", "condition": "paper/spoken", "variant": "names", "seed": 0, "plan": {}},
    )
    session.record(SessionRecord(event=SessionEvent.START, plan=session.plan), 0.0)
    session.record(StepRecord(to="guessing"), 0.0)
    terminal.drain(1.0)
    delays = []
    try:
        for n in range(1, count + 1):
            terminal.drain(rng.uniform(0.02, 0.25))
            mark = len(terminal.text)
            session.record(question(n, child=f"probe {n:04d}"), float(n))  # returns after fsync
            written = time.monotonic()
            shown = terminal.wait_for(f"probe {n:04d}".encode(), mark)
            delays.append((shown - written) * 1000)
    finally:
        session.close()
    return delays


def report(name: str, delays: list[float]) -> float:
    p99 = percentile(delays, 0.99)
    print(
        f"{name}: n={len(delays)}  p50 {statistics.median(delays):.1f} ms  "
        f"p99 {p99:.1f} ms  max {max(delays):.1f} ms"
    )
    return p99


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--live-seconds", type=float, default=90.0)
    parser.add_argument("--demo-speed", type=float, default=8.0)
    parser.add_argument("--idle-seconds", type=float, default=30.0)
    parser.add_argument("--probes", type=int, default=300)
    arguments = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        state_dir = Path(scratch) / "state"
        terminal = Terminal(state_dir)
        try:
            terminal.drain(2.0)
            live_cpu, live_delays, records = live(
                terminal, state_dir, arguments.live_seconds, arguments.demo_speed
            )
            idle_cpu = idle(terminal, arguments.idle_seconds)
            probe_delays = probes(terminal, state_dir, arguments.probes)
        finally:
            terminal.close()
    print(
        f"following a live demo (--speed {arguments.demo_speed:g}, {records} records in "
        f"{arguments.live_seconds:g} s): {live_cpu:.2f} % of a core"
    )
    print(
        f"between records ({arguments.idle_seconds:g} s, redrawn each second as ages change): "
        f"{idle_cpu:.2f} % of a core (target < {CPU_TARGET:g} %) "
        f"{'PASS' if idle_cpu < CPU_TARGET else 'FAIL'}"
    )
    report("demo question records, stamped before write+fsync -> on screen", live_delays)
    p99 = report("probe records, fsync returned -> on screen", probe_delays)
    print(
        f"fsync to screen p99: {p99:.1f} ms (target < {DELAY_TARGET_MS:g} ms) "
        f"{'PASS' if p99 < DELAY_TARGET_MS else 'FAIL'}"
    )


if __name__ == "__main__":
    main()
