"""One owner per serial port: a thread that holds the port, bounded I/O, reconnect.

The event loop never touches the port. It submits a transaction (bytes out,
how many reply packets to read and how to frame and decode them) and awaits a
future; the bus thread does the blocking I/O. Reads wait in select() with the
transaction's deadline, never spinning. A timeout, a framing error or a reply
that fails its decoder is retried a bounded number of times. If the adapter
vanishes (EIO, SerialException) every pending and new transaction fails with
PortUnavailable while the thread reopens the port with exponential backoff;
when it is back the bus carries on, no restart needed.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import errno
import os
import queue
import select
import termios
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar, overload

import serial  # pyserial ships no types: the bus sees a port through SerialPort
import structlog

from hal.clock import thread_work
from hal.errors import (
    BusClosed,
    BusTimeout,
    CodecError,
    InvalidArgument,
    PortUnavailable,
    RepeatFilter,
)

log = structlog.get_logger("hal.servos.bus")

T = TypeVar("T")

BITS_PER_BYTE = 10  # start + 8 data + stop

# pyserial's failure of a port that cannot be opened, or has gone.
SerialException: type[Exception] = serial.SerialException


class SerialPort(Protocol):
    """The part of serial.Serial the bus thread uses; only that thread touches it."""

    def fileno(self) -> int:
        """The descriptor the thread waits on with select() and reads with os.read()."""
        ...

    def write(self, data: bytes, /) -> int | None:
        """Send `data`; SerialException (or OSError) when the adapter has gone."""
        ...

    def reset_input_buffer(self) -> None:
        """Drop bytes received but not read (a late reply to an earlier attempt)."""
        ...

    def set_low_latency_mode(self, low_latency_settings: bool, /) -> None:
        """ASYNC_LOW_LATENCY; OSError, ValueError or AttributeError where unsupported."""
        ...

    def close(self) -> None:
        """Release the port."""
        ...


def open_port(path: str, baud: int) -> SerialPort:
    """Open `path` exclusively, non-blocking reads, a 1 s write timeout.

    Raises SerialException, OSError or ValueError when it cannot be opened.
    """
    port: SerialPort = serial.Serial(path, baud, timeout=0, write_timeout=1.0, exclusive=True)
    return port


# What an adapter that cannot be opened most often means, in a person's words.
_OPEN_FAILURES = {
    errno.ENOENT: "no such device (the adapter unplugged, or its udev rule not installed)",
    errno.ENODEV: "no such device (the adapter unplugged)",
    errno.ENXIO: "no such device (the adapter unplugged)",
    errno.EACCES: "permission denied (the service's user is not in the dialout group)",
    errno.EBUSY: "in use by another process",
}


def open_failure(error: BaseException) -> str:
    """Why a port could not be opened, in words; the system's own where it is unusual."""
    number = getattr(error, "errno", None)
    if isinstance(number, int) and number in _OPEN_FAILURES:
        return _OPEN_FAILURES[number]
    if isinstance(number, int):
        return os.strerror(number)
    return str(error)


def wire_time(n_bytes: int, baud: int) -> float:
    """Seconds that `n_bytes` take on the wire at `baud`."""
    return n_bytes * BITS_PER_BYTE / baud


@dataclass(frozen=True, slots=True)
class Framing:
    """How to cut a protocol's replies out of the byte stream."""

    head_size: int  # bytes needed before the total length is known
    length: Callable[[bytes], int]  # total packet length from its head; raises a CodecError


class BusState(enum.Enum):
    """Whether the owner thread holds the port; changes are reported on the event loop."""

    CONNECTED = "connected"
    DISCONNECTED = "disconnected"
    CLOSED = "closed"


@dataclass
class BusStats:
    """Counters of one bus since it was made; written by its owner thread only."""

    transactions: int = 0
    bytes_out: int = 0
    bytes_in: int = 0
    retries: int = 0
    # Replies that came but were not the one asked for (corrupt, another id, a stale
    # answer): a protocol problem, unlike a late reply on a loaded machine.
    bad_replies: int = 0
    timeouts: int = 0
    disconnects: int = 0
    reconnects: int = 0


@dataclass(frozen=True, slots=True)
class Exchange:
    """One request and the replies it expects, for SerialBus.exchange_all."""

    request: bytes
    replies: int = 0
    framing: Framing | None = None
    decode: Callable[[list[bytes]], Any] | None = None
    expect: int = 0  # reply bytes expected in all, for the deadline


@dataclass(eq=False)
class _Job:
    exchanges: list[Exchange]
    batch: bool  # resolve with the list of outcomes rather than the single result
    future: asyncio.Future[Any]
    loop: asyncio.AbstractEventLoop

    def resolve(self, result: Any = None, error: BaseException | None = None) -> None:
        def settle() -> None:
            if self.future.done():  # the caller gave up (watchdog) or was cancelled
                return
            if error is not None:
                self.future.set_exception(error)
            else:
                self.future.set_result(result)

        with contextlib.suppress(RuntimeError):  # the loop has closed: nobody is waiting
            self.loop.call_soon_threadsafe(settle)


_STOP = object()


@dataclass
class SerialBus:
    """Owns one serial port. Create, `await start()`, `await transact(...)`, `await close()`.

    Its methods are called from one event loop; the port itself belongs to the
    owner thread. `timeout_margin` and the backoffs are in seconds; `on_state`
    is called on the event loop at each change of state.
    """

    name: str
    port: str
    baud: int
    timeout_margin: float = 0.02
    retries: int = 2
    backoff_initial: float = 0.05
    backoff_max: float = 2.0
    on_state: Callable[[BusState], None] | None = None
    stats: BusStats = field(default_factory=BusStats)
    # Written each time the port opens, before any exchange: what every servo behind it
    # must be told again after a power cycle (HerkuleX: its ACK policy).
    greeting: bytes = b""

    def __post_init__(self) -> None:
        """Prepare the job queue and state; nothing runs until start()."""
        self._jobs: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._serial: SerialPort | None = None
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._state = BusState.DISCONNECTED
        self._state_changed: asyncio.Event | None = None
        self._backoff = self.backoff_initial
        self._next_open = 0.0
        self._repeats = RepeatFilter()
        self._log = log.bind(bus=self.name, port=self.port)
        # Why the port last failed to open, in words (None once it is open): every
        # message about the bus names the adapter and this, once, not each servo behind it.
        self.open_error: str | None = None

    # --- event-loop side ----------------------------------------------------------------

    @property
    def state(self) -> BusState:
        """The state as last reported by the owner thread."""
        return self._state

    @property
    def connected(self) -> bool:
        """True while the port is open."""
        return self._state is BusState.CONNECTED

    def unavailable(self) -> str:
        """Why the bus cannot be used, naming the adapter: "bus body: cannot open
        /dev/kaspar-body: no such device (...)", or that it is not open."""
        if self.open_error is not None:
            return f"bus {self.name}: cannot open {self.port}: {self.open_error}"
        return f"bus {self.name}: {self.port} is not available"

    async def start(self) -> None:
        """Start the owner thread; it opens the port (now, or as soon as it appears)."""
        if self._thread is not None:
            return
        self._loop = asyncio.get_running_loop()
        self._state_changed = asyncio.Event()
        self._thread = threading.Thread(target=self._run, name=f"bus {self.name}", daemon=True)
        self._thread.start()
        # Give the first open a chance so that a plugged-in bus starts connected.
        await self.wait_state(BusState.CONNECTED, timeout=1.0)

    async def wait_state(self, state: BusState, timeout: float) -> bool:
        """Wait until the bus is in `state`; False if `timeout` passed first."""
        assert self._state_changed is not None, "start() the bus first"
        deadline = time.monotonic() + timeout
        while self._state is not state:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            self._state_changed.clear()
            with contextlib.suppress(TimeoutError), thread_work(asyncio.get_running_loop()):
                async with asyncio.timeout(remaining):
                    await self._state_changed.wait()
        return True

    def transaction_timeout(self, request_bytes: int, reply_bytes: int, replies: int) -> float:
        """Deadline for one attempt: wire time both ways, plus the margin per reply."""
        return wire_time(request_bytes + reply_bytes, self.baud) + self.timeout_margin * max(
            1, replies
        )

    @overload
    async def transact(
        self,
        request: bytes,
        replies: int,
        framing: Framing,
        decode: Callable[[list[bytes]], T],
        expect: int = 0,
    ) -> T: ...

    @overload
    async def transact(
        self,
        request: bytes,
        replies: int = 0,
        framing: Framing | None = None,
        decode: None = None,
        expect: int = 0,
    ) -> list[bytes]: ...

    async def transact(
        self,
        request: bytes,
        replies: int = 0,
        framing: Framing | None = None,
        decode: Callable[[list[bytes]], T] | None = None,
        expect: int = 0,
    ) -> object:
        """Send `request`, read `replies` packets (framed by `framing`) and decode them.

        `expect` is the number of reply bytes expected in all (for the deadline);
        `decode` turns the packets into the result and raises a CodecError for a
        reply that must be retried (corrupt, wrong id); without it the result is
        the packets. Raises BusTimeout after the retries, PortUnavailable while
        the adapter is away, BusClosed after close(), InvalidArgument for replies
        without a framing. Runs on the event loop; the I/O is the bus thread's.
        """
        outcome: object = await self._submit(
            [Exchange(request, replies, framing, decode, expect)], False
        )
        return outcome

    async def exchange_all(self, exchanges: Sequence[Exchange]) -> list[Any]:
        """Run `exchanges` back to back on the bus thread, with a single hand-off.

        Reading 17 AX-12s one READ at a time is 17 transactions; handing each to the
        thread separately would cost more than the wire. Each outcome is the decoded
        result or the exception that ended that exchange (BusTimeout, CodecError);
        once the port is lost the rest are PortUnavailable.
        """
        outcomes: list[Any] = await self._submit(list(exchanges), True)
        return outcomes

    async def _submit(self, exchanges: list[Exchange], batch: bool) -> Any:
        if self._state is BusState.CLOSED or self._loop is None:
            raise BusClosed(f"bus {self.name} is not running")
        if any(e.replies and e.framing is None for e in exchanges):
            raise InvalidArgument("replies need a framing")
        loop = asyncio.get_running_loop()
        future: asyncio.Future[Any] = loop.create_future()
        self._jobs.put(_Job(exchanges, batch, future, loop))
        attempts = sum(
            self.transaction_timeout(len(e.request), e.expect, e.replies) + 0.01 for e in exchanges
        )
        # A watchdog far beyond the thread's own deadlines: it only fires if the thread is stuck.
        watchdog = attempts * (self.retries + 1) + 5.0
        try:
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for returns the reply and
            # drops a cancellation that lands in the same loop turn as the reply, and a
            # game step paused at that instant would carry on (found by the soak).
            with thread_work(loop):
                async with asyncio.timeout(watchdog):
                    return await future
        except TimeoutError:
            raise BusTimeout(f"bus {self.name}: the bus thread did not answer") from None

    async def close(self) -> None:
        """Stop the owner thread and release the port; queued transactions fail with BusClosed.

        Waits up to 5 s for the thread (off the event loop); a second close() does nothing.
        """
        if self._thread is None:
            self._state = BusState.CLOSED
            return
        self._jobs.put(_STOP)
        with thread_work(asyncio.get_running_loop()):
            await asyncio.to_thread(self._thread.join, 5.0)
        self._thread = None
        self._set_state(BusState.CLOSED)

    # --- owner-thread side --------------------------------------------------------------

    def _set_state(self, state: BusState) -> None:
        if state is self._state:
            return
        self._state = state

        def notify() -> None:
            if self._state_changed is not None:
                self._state_changed.set()
            if self.on_state is not None:
                self.on_state(state)

        if self._loop is not None:
            with contextlib.suppress(RuntimeError):
                self._loop.call_soon_threadsafe(notify)

    def _run(self) -> None:
        try:
            while True:
                if self._serial is None:
                    self._try_open()
                wait = None
                if self._serial is None:
                    wait = max(0.0, self._next_open - time.monotonic())
                try:
                    job = self._jobs.get(timeout=wait)
                except queue.Empty:
                    continue
                if job is _STOP:
                    break
                if self._serial is None:
                    job.resolve(error=PortUnavailable(self.unavailable()))
                    continue
                self._execute(job)
        finally:
            self._drop_port()
            while True:
                try:
                    job = self._jobs.get_nowait()
                except queue.Empty:
                    break
                if job is not _STOP:
                    job.resolve(error=BusClosed(f"bus {self.name} closed"))

    def _try_open(self) -> None:
        if time.monotonic() < self._next_open:
            return
        try:
            port = open_port(self.port, self.baud)
        except (SerialException, OSError, ValueError) as error:
            self.open_error = open_failure(error)
            if self._repeats.first("open", str(error)):
                self._log.warning("serial port cannot be opened; retrying", error=str(error))
            self._next_open = time.monotonic() + self._backoff
            self._backoff = min(self._backoff * 2, self.backoff_max)
            return
        self._request_low_latency(port)
        self.open_error = None
        repeated = self._repeats.end("open")
        if self.stats.disconnects:
            self.stats.reconnects += 1
        self._log.info(
            "serial port open",
            baud=self.baud,
            failed_attempts=repeated[1] if repeated else 0,
        )
        self._serial = port
        if self.greeting:
            try:
                port.write(self.greeting)
            except (SerialException, OSError, termios.error) as error:
                self._lost(error)
                return
            self.stats.bytes_out += len(self.greeting)
        self._backoff = self.backoff_initial
        self._set_state(BusState.CONNECTED)

    def _request_low_latency(self, port: SerialPort) -> None:
        # ASYNC_LOW_LATENCY makes the kernel push received bytes at once; ftdi_sio
        # also maps it to a 1 ms latency timer. A pty does not support it.
        try:
            port.set_low_latency_mode(True)
        except (OSError, ValueError, AttributeError, SerialException) as error:
            if self._repeats.first("low-latency", str(error)):
                self._log.info("low-latency mode not available on this port", error=str(error))

    def _drop_port(self) -> None:
        if self._serial is not None:
            with contextlib.suppress(Exception):
                self._serial.close()
            self._serial = None

    def _lost(self, error: BaseException) -> None:
        self.stats.disconnects += 1
        self._log.error("serial port lost; reopening with backoff", error=str(error))
        self._drop_port()
        self._next_open = time.monotonic() + self._backoff
        self._set_state(BusState.DISCONNECTED)

    def _execute(self, job: _Job) -> None:
        outcomes: list[Any] = []
        for exchange in job.exchanges:
            if self._serial is None:  # lost during this batch
                outcomes.append(PortUnavailable(self.unavailable()))
                continue
            try:
                outcomes.append(self._attempt(exchange))
            except Exception as error:  # every outcome is reported to the caller, none dropped
                outcomes.append(error)
        if job.batch:
            job.resolve(outcomes)
        elif isinstance(outcomes[0], Exception):
            job.resolve(error=outcomes[0])
        else:
            job.resolve(outcomes[0])

    def _attempt(self, exchange: Exchange) -> Any:
        """One exchange with its retries; raises what ended it."""
        assert self._serial is not None
        self.stats.transactions += 1
        timeout = self.transaction_timeout(len(exchange.request), exchange.expect, exchange.replies)
        last: Exception | None = None
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats.retries += 1
            try:
                self._serial.reset_input_buffer()
                self._serial.write(exchange.request)
                self.stats.bytes_out += len(exchange.request)
                deadline = time.monotonic() + timeout
                packets = self._read_replies(exchange, deadline)
                if exchange.decode is None:
                    return packets
                return exchange.decode(packets)
            except (SerialException, OSError, termios.error) as error:
                self._lost(error)
                raise PortUnavailable(f"bus {self.name}: {error}") from None
            except BusTimeout as error:
                last = error
            except CodecError as error:
                self.stats.bad_replies += 1
                last = error
        if isinstance(last, BusTimeout):
            self.stats.timeouts += 1
            raise BusTimeout(f"bus {self.name}: {last} (after {self.retries} retries)")
        assert last is not None
        raise last

    def _read_replies(self, exchange: Exchange, deadline: float) -> list[bytes]:
        if not exchange.replies:
            return []
        assert exchange.framing is not None, "_submit refuses replies without a framing"
        framing = exchange.framing
        return [self._read_packet(framing, deadline) for _ in range(exchange.replies)]

    def _read_packet(self, framing: Framing, deadline: float) -> bytes:
        head = self._read_exact(framing.head_size, deadline)
        total = framing.length(head)
        return head + self._read_exact(total - framing.head_size, deadline)

    def _read_exact(self, count: int, deadline: float) -> bytes:
        assert self._serial is not None
        fd = self._serial.fileno()
        data = b""
        while len(data) < count:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise BusTimeout(f"{len(data)} of {count} reply bytes before the deadline")
            ready, _, _ = select.select([fd], [], [], remaining)
            if not ready:
                continue
            chunk = os.read(fd, count - len(data))
            if not chunk:  # readable yet empty: the device has gone (pty hang-up, USB unplug)
                raise SerialException("readable but no data: the device has gone")
            data += chunk
            self.stats.bytes_in += len(chunk)
        return data
