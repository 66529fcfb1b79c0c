"""The emulator skeleton: a thread serving one pty, packet framing, and fault injection."""

from __future__ import annotations

import heapq
import os
import queue
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from emulators.pty_port import PtyPort


@dataclass
class Faults:
    """What the emulated servos get wrong; tests flip these while the emulator runs."""

    silent: set[int] = field(default_factory=set)  # ids that never reply
    all_silent: bool = False
    bad_checksum: set[int] = field(default_factory=set)  # ids whose replies are corrupted
    wrong_id: dict[int, int] = field(default_factory=dict)  # id -> the id its replies carry
    error_bits: dict[int, int] = field(default_factory=dict)  # id -> protocol error flags
    drop_next: int = 0  # the next N replies are not sent (then the servo answers again)
    corrupt_next: int = 0  # the next N replies are corrupted


@dataclass
class Axis:
    """One servo's shaft: moves toward its goal while torque is on.

    At `speed` units per second when a command set one (a HerkuleX play time),
    else at `rate`, the servo's own speed.
    """

    present: float
    goal: float
    rate: float
    torque: bool = False
    stamp: float | None = None  # the emulator clock's time of the last update
    speed: float | None = None

    def update(self, now: float) -> int:
        if self.torque and self.stamp is not None:
            step = (self.rate if self.speed is None else self.speed) * (now - self.stamp)
            delta = self.goal - self.present
            self.present = self.goal if abs(delta) <= step else self.present + step * (
                1 if delta > 0 else -1
            )
        self.stamp = now
        return round(self.present)


class Emulator:
    """Serves one pty from its own thread until stop(); subclasses decode and answer packets."""

    def __init__(self, path: Path, clock: Callable[[], float] = time.monotonic) -> None:
        # The shafts move on this clock: the wall clock, or a simulated game's loop
        # time (read from this thread; a float read needs no lock).
        self.clock = clock
        self.port = PtyPort(path)
        self.faults = Faults()
        self.received: list[bytes] = []  # every well-framed request, for assertions
        self.replies = 0
        # Seconds between a request and its reply, as a servo's return delay and the wire
        # make it: a reply the driver did not wait for then lands in its next exchange.
        self.reply_delay = 0.0
        self._due: list[tuple[float, int, bytes]] = []  # (monotonic time, order, reply)
        self._buffer = b""
        self._wake_r, self._wake_w = os.pipe()
        self._commands: queue.Queue[tuple[Callable[[], None], threading.Event]] = queue.Queue()
        self._running = True
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._serve, name=f"emulator {path}", daemon=True)
        self._thread.start()

    @property
    def path(self) -> Path:
        return self.port.path

    # --- to be provided by each protocol -------------------------------------------------

    def split(self, buffer: bytes) -> tuple[bytes | None, bytes]:
        """(one complete packet or None, what is left); drop garbage from the front."""
        raise NotImplementedError

    def handle(self, packet: bytes) -> list[tuple[int, bytes]]:
        """Replies to one packet as (servo id, bytes) pairs, before faults are applied."""
        raise NotImplementedError

    def corrupt(self, reply: bytes) -> bytes:
        return reply[:-1] + bytes(((reply[-1] ^ 0x5A) or 1,))

    # --- control from the test thread ---------------------------------------------------

    def _run_in_thread(self, action: Callable[[], None]) -> None:
        done = threading.Event()
        self._commands.put((action, done))
        os.write(self._wake_w, b"x")
        if not done.wait(5):
            raise TimeoutError("emulator thread did not answer")

    def unplug(self) -> None:
        """The adapter is pulled: the driver's port fails with EIO."""
        self._run_in_thread(self.port.unplug)

    def plug(self) -> None:
        """The adapter is back, as a new tty behind the same path."""

        def plug() -> None:
            self._buffer = b""
            self.port.plug()

        self._run_in_thread(plug)

    def stop(self) -> None:
        self._running = False
        os.write(self._wake_w, b"x")
        self._thread.join(5)
        self.port.close()
        os.close(self._wake_r)
        os.close(self._wake_w)

    def __enter__(self) -> Emulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- the serving thread -------------------------------------------------------------

    def _serve(self) -> None:
        while self._running:
            watched = [self._wake_r] + ([self.port.master] if self.port.master is not None else [])
            wait = None
            if self._due:
                wait = max(0.0, self._due[0][0] - time.monotonic())
            ready, _, _ = select.select(watched, [], [], wait)
            while self._due and self._due[0][0] <= time.monotonic():
                self.port.write(heapq.heappop(self._due)[2])
            if self._wake_r in ready:
                os.read(self._wake_r, 64)
                while not self._commands.empty():
                    action, done = self._commands.get()
                    action()
                    done.set()
                continue
            data = self.port.read_available(0)
            if not data:
                continue
            self._buffer += data
            while True:
                packet, self._buffer = self.split(self._buffer)
                if packet is None:
                    break
                self.received.append(packet)
                with self._lock:
                    replies = self.handle(packet)
                for servo_id, reply in replies:
                    self._send(servo_id, reply)

    def _send(self, servo_id: int, reply: bytes) -> None:
        faults = self.faults
        if faults.all_silent or servo_id in faults.silent:
            return
        if faults.drop_next > 0:
            faults.drop_next -= 1
            return
        if servo_id in faults.bad_checksum or faults.corrupt_next > 0:
            faults.corrupt_next = max(0, faults.corrupt_next - 1)
            reply = self.corrupt(reply)
        self.replies += 1
        if self.reply_delay > 0:
            due = time.monotonic() + self.reply_delay
            heapq.heappush(self._due, (due, self.replies, reply))
        else:
            self.port.write(reply)


def split_with(
    head_size: int, header: bytes, length_of: Callable[[bytes], int], buffer: bytes
) -> tuple[bytes | None, bytes]:
    """Frame one packet from `buffer` with a protocol's header and length rule."""
    while True:
        while buffer and not buffer.startswith(header[: len(buffer)]):
            buffer = buffer[1:]
        if len(buffer) < head_size:
            return None, buffer
        try:
            length = length_of(buffer[:head_size])
        except Exception:
            buffer = buffer[1:]  # a false header: resynchronise on the next byte
            continue
        if len(buffer) < length:
            return None, buffer
        return buffer[:length], buffer[length:]
