"""The keyfob through evdev: key map, gestures, unplug and return.

Reading happens on the event loop: the device's non-blocking fd is registered
with loop.add_reader and each wake-up reads one batch with evdev's own
InputDevice.read(). evdev's async_read_loop() is not used because it adds and
removes the reader for every batch, turns a spurious wake-up (EAGAIN) into an
exception that ends the iteration, and cannot express end-of-file; here a
single reader stays registered until the device is lost, then is removed
exactly once.

Times: the kernel stamps events with the wall clock unless told otherwise, so
the device is told to stamp with CLOCK_MONOTONIC (EVIOCSCLOCKID) when it is
opened: a wall-clock step (NTP at boot, a researcher setting the date) between
a press and its release must not make a quick green a long one. The game runs
on an injected clock, so each batch is anchored to clock.now() at the read,
keeping the kernel's spacing between the events of the batch (which is what
tells a bounce from a press when the loop was busy). A kernel that refuses the
ioctl is said in the log once per opening.

Keys: each mapped key's code gives its button or command (the device's profile,
hal.keyfob.profiles); a button that alternates keys (F5, then Esc) is held while
any of its keys is, so it is one button. A researcher's device whose profile
gives holds has its gestures turned into commands here (gesture_commands), so
the game only ever sees commands from it.

Opening: by path (a udev rule's stable name); when that path is missing, by the
profile's USB ids and interface, found in sysfs; or by name, among the nodes
that can send the mapped keys (a receiver's other node with the same name
cannot). Never the first of several nodes in string order (event10 sorts before
event9).

Unplug: read() raises OSError(ENODEV) (a pipe in tests gives end-of-file);
either way the reader is removed, held keys are forgotten, KeyfobLost is
queued, and /dev/input is watched with inotify (netlink is not allowed to the
hardened service) until the device can be opened again. udev applies the
group and mode a moment after it creates the node, so a PermissionError is
retried for `reopen_grace` seconds (and an IN_ATTRIB event retries at once).
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import ctypes.util
import errno
import fcntl
import os
import struct
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Protocol

import structlog

from hal.clock import Clock
from hal.errors import KeyfobError
from hal.keyfob.api import InputEvent, KeyfobBack, KeyfobLost
from hal.keyfob.devices import InputNode, input_nodes
from hal.keyfob.gestures import (
    Gesture,
    GestureKind,
    GestureNeeds,
    GestureRecognizer,
    GestureTimings,
)
from hal.keyfob.settings import InputDeviceSettings

log = structlog.get_logger("kaspar.keyfob")

EV_SYN, EV_KEY = 0x00, 0x01
SYN_REPORT, SYN_DROPPED = 0, 3
KEY_UP, KEY_DOWN, KEY_REPEAT = 0, 1, 2
# _IOW('E', 0xa0, int): which clock stamps this descriptor's events.
EVIOCSCLOCKID = 0x400445A0


class EvdevEvent(Protocol):
    """The part of evdev.InputEvent the keyfob reads: one input_event record."""

    @property
    def type(self) -> int:
        """EV_KEY for a key change, EV_SYN for the end of a report (or a dropped one)."""
        ...

    @property
    def code(self) -> int:
        """The key's evdev code (KEY_PAGEDOWN), or the SYN_ kind."""
        ...

    @property
    def value(self) -> int:
        """For a key: 0 up, 1 down, 2 autorepeat."""
        ...

    def timestamp(self) -> float:
        """The kernel's time of the event in seconds (wall clock unless told otherwise)."""
        ...


class EvdevDevice(Protocol):
    """The part of evdev.InputDevice the keyfob uses; tests give a pipe-backed one."""

    @property
    def path(self) -> str | bytes:
        """The device node it was opened by."""
        ...

    @property
    def name(self) -> str:
        """The name the device reports, as `evtest` lists it."""
        ...

    def fileno(self) -> int:
        """The non-blocking descriptor to watch with loop.add_reader."""
        ...

    def read(self) -> Iterable[EvdevEvent]:
        """Every event waiting; BlockingIOError when none, OSError(ENODEV) once unplugged."""
        ...

    def grab(self) -> None:
        """Take the device for ourselves (EVIOCGRAB); OSError if another holds it."""
        ...

    def close(self) -> None:
        """Release the device; the descriptor is closed."""
        ...


def open_evdev(path: str) -> EvdevDevice:
    """Open the evdev device node `path`; OSError (ENOENT, EACCES, ...) when it cannot be.
    (The reader then asks for CLOCK_MONOTONIC stamps: stamp_monotonic.)"""
    import evdev

    return evdev.InputDevice(path)


def stamp_monotonic(fd: int, ioctl: Callable[[int, int, bytes], object] = fcntl.ioctl) -> None:
    """Ask the kernel to stamp `fd`'s events with CLOCK_MONOTONIC; OSError if it refuses."""
    ioctl(fd, EVIOCSCLOCKID, struct.pack("i", time.CLOCK_MONOTONIC))


class Keyfob:
    """The real keyfob (or the researcher's keypad); satisfies hal.keyfob.api.KeyfobInput."""

    def __init__(
        self,
        settings: InputDeviceSettings,
        clock: Clock,
        *,
        role: str = "keyfob",
        needs: GestureNeeds | None = None,
        opener: Callable[[str], EvdevDevice] = open_evdev,
        input_dir: str = "/dev/input",
        sys_root: str = "/sys",
        retry_every: float = 5.0,
        ioctl: Callable[[int, int, bytes], object] = fcntl.ioctl,
    ) -> None:
        """Read the keyfob that `settings` names, stamping gestures with `clock`.

        `role` names the device in the log ("keyfob", "researcher");
        `needs` are the gestures listened for at first (set_needs changes them);
        `opener` opens a device node (evdev's, or a test's pipe device); `input_dir`
        is watched for the keyfob's return, and looked at again every `retry_every`
        seconds in case an inotify event was missed; `sys_root` is where sysfs says which
        node is which; `ioctl` sets the clock of an opened node (a test's stands in for
        the kernel's). Nothing is opened until start().
        """
        self._settings = settings
        self._clock = clock
        self._log = log.bind(input=role)
        self._opener = opener
        self._input_dir = input_dir
        self._sys_root = sys_root
        self._ioctl = ioctl
        # Safety net under inotify: look again now and then, in case an event was missed.
        self._retry_every = retry_every
        self._key_map = settings.key_map()
        self._ignored = settings.ignored_codes() - set(self._key_map)
        self._gesture_commands = settings.gesture_commands()
        # Each button's keys held now: a button that alternates keys is one button.
        self._held: dict[str, set[int]] = {}
        commands = [name for name in self._key_map.values() if name not in ("green", "red")]
        timings = GestureTimings(
            long_press=settings.long_press,
            double_press=settings.double_press,
            bounce=settings.bounce,
            both_window=settings.both_window,
        )
        self._recogniser = GestureRecognizer(timings, needs or GestureNeeds(), commands=commands)
        self._events: asyncio.Queue[InputEvent] = asyncio.Queue()
        self._device: EvdevDevice | None = None
        self._fd = -1
        self._timer: asyncio.Task[None] | None = None
        self._watch: asyncio.Task[None] | None = None
        self._last_time = float("-inf")
        self._dropping = False
        self._unknown_codes: set[int] = set()
        self._closed = False

    # -- KeyfobInput --------------------------------------------------------

    async def start(self) -> None:
        """Open the keyfob on the running loop, or report KeyfobLost and watch for it.

        Never raises for a missing or unreadable keyfob: the game starts without
        it and is told when it comes.
        """
        try:
            self._open()
        except (OSError, KeyfobError) as error:
            # Said once here: a Bluetooth keyfob pairs after the computer starts, a USB
            # one is plugged in late; the watch below finds it when it comes.
            reason = f"not available at start: {_describe(error)}"
            self._log.warning("keyfob not connected; watching for it", reason=reason)
            self._report_lost(reason)

    async def next_event(self) -> InputEvent:
        """The next gesture or lost/back event, in order; waits as long as it takes."""
        return await self._events.get()

    def set_needs(self, needs: GestureNeeds) -> None:
        """Which gestures the game listens for from each button's next key-down."""
        self._recogniser.set_needs(needs)

    @property
    def connected(self) -> bool:
        """True while the device is open and read."""
        return self._device is not None

    async def close(self) -> None:
        """Stop the gesture timer and the reopen watch, and release the device; idempotent."""
        self._closed = True
        for task in (self._timer, self._watch):
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        self._timer = self._watch = None
        self._drop_device()

    def locate(self) -> EvdevDevice:
        """The configured device, opened as the reader would open it (not grabbed, not
        read); the caller closes it. OSError or KeyfobError when it cannot be."""
        return self._open_device()

    def probe(self) -> str:
        """Open the configured keyfob once and close it: "path (name)".

        Raises KeyfobError when it cannot be found or opened (the OSError's
        message, unchanged, or the name that no device has).
        """
        try:
            device = self._open_device()
        except OSError as error:
            raise KeyfobError(str(error)) from error
        try:
            return f"{os.fsdecode(device.path)} ({device.name})"
        finally:
            device.close()

    # -- opening ------------------------------------------------------------

    def _open_device(self) -> EvdevDevice:
        path = self._settings.device_path
        if path is not None:
            try:
                return self._opener(path)
            except FileNotFoundError:
                node = self._by_ids(path)
                if node is None:
                    raise
                return self._opener(f"{self._input_dir}/{node.node}")
        wanted = self._settings.name
        # sysfs says what each node is without opening it; where it names none (a
        # container, a tree of test nodes) each node is opened and asked its name.
        node = self._best([node for node in input_nodes(self._sys_root) if node.name == wanted])
        if node is not None:
            return self._opener(f"{self._input_dir}/{node.node}")
        entries = sorted(Path(self._input_dir).glob("event*"), key=_event_number)
        for entry in entries:
            try:
                device = self._opener(str(entry))
            except OSError:
                continue
            if device.name == wanted:
                return device  # kept open: opening again could race an unplug
            device.close()
        raise KeyfobError(f"no input device named {wanted!r} in {self._input_dir}")

    def _by_ids(self, path: str) -> InputNode | None:
        """The node of the profile's USB ids and interface, for a path no rule made."""
        match = self._settings.match()
        if match.vendor is None:
            return None
        found = [
            node
            for node in input_nodes(self._sys_root)
            if node.vendor == match.vendor
            and (match.product is None or node.product == match.product)
            and (match.interface is None or node.interface == match.interface)
        ]
        node = self._best(found)
        if node is not None:
            self._log.info("keyfob found by its ids", missing=path, node=node.node)
        return node

    def _best(self, nodes: list[InputNode]) -> InputNode | None:
        """Of several nodes, the one that can send the most mapped keys, then the kernel's
        first (event9 before event10)."""
        if not nodes:
            return None
        wanted = set(self._key_map)
        return min(nodes, key=lambda node: (-len(wanted & node.keys), node.number))

    def _open(self) -> None:
        device = self._open_device()
        path = os.fsdecode(device.path)
        try:
            if self._settings.grab:
                try:
                    device.grab()
                except OSError as error:
                    # Still usable, but its keys also reach whoever else holds it.
                    self._log.warning("keyfob not grabbed", device=path, error=_describe(error))
            fd = device.fileno()
            try:
                stamp_monotonic(fd, self._ioctl)
            except OSError as error:
                self._log.warning("keyfob events stamped by the wall clock", error=_describe(error))
            asyncio.get_running_loop().add_reader(fd, self._on_readable)
        except BaseException:
            with contextlib.suppress(OSError):
                device.close()
            raise
        self._device, self._fd = device, fd
        self._log.info("keyfob open", device=path, name=device.name)

    def _drop_device(self) -> None:
        if self._device is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop may already be closed
            asyncio.get_running_loop().remove_reader(self._fd)
        with contextlib.suppress(OSError):
            self._device.close()
        self._device, self._fd = None, -1

    # -- reading ------------------------------------------------------------

    def _on_readable(self) -> None:
        device = self._device
        if device is None:
            return
        try:
            batch = list(device.read())
        except BlockingIOError:
            return  # woken with nothing to read
        except OSError as error:
            self._lose(_describe(error))
            return
        if not batch:
            self._lose("end of file")
            return
        now = self._clock.now()
        newest = batch[-1].timestamp()
        gestures: list[Gesture] = []
        for event in batch:
            at = max(self._last_time, now - max(0.0, newest - event.timestamp()))
            self._last_time = at
            gestures += self._on_event(event, at)
        self._publish(gestures)

    def _on_event(self, event: EvdevEvent, at: float) -> list[Gesture]:
        if event.type == EV_SYN:
            if event.code == SYN_DROPPED:
                # The kernel's buffer overflowed: which keys are down is unknown
                # until the next report, so forget the holds rather than guess.
                self._log.warning("keyfob events dropped by the kernel")
                self._dropping = True
                self._held.clear()
                return self._recogniser.reset()
            if event.code == SYN_REPORT:
                self._dropping = False
            return []
        if event.type != EV_KEY or self._dropping or event.value == KEY_REPEAT:
            return []
        button = self._key_map.get(event.code)
        if button is None:
            if event.code not in self._unknown_codes and event.code not in self._ignored:
                self._unknown_codes.add(event.code)
                self._log.info("keyfob key not mapped", code=event.code)
            return []
        held = self._held.setdefault(button, set())
        was_held = bool(held)
        if event.value == KEY_DOWN:
            held.add(event.code)
        else:
            held.discard(event.code)
        if was_held == bool(held):
            return []  # another key of a button already held, or one never seen down
        return self._recogniser.key(button, bool(held), at)

    def _translate(self, gesture: Gesture) -> Gesture | None:
        """A researcher device's gesture as the command its profile gives it, or None."""
        if not self._gesture_commands or gesture.kind is GestureKind.COMMAND:
            return gesture
        command = self._gesture_commands.get((gesture.kind, gesture.button))
        if command is None:
            return None
        return Gesture(GestureKind.COMMAND, command, gesture.at, gesture.decided)

    def _publish(self, gestures: list[Gesture]) -> None:
        for gesture in gestures:
            translated = self._translate(gesture)
            if translated is not None:
                self._events.put_nowait(translated)
        self._schedule()

    def _schedule(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        deadline = self._recogniser.next_deadline()
        if deadline is not None and not self._closed:
            self._timer = asyncio.get_running_loop().create_task(self._wait_until(deadline))

    async def _wait_until(self, deadline: float) -> None:
        await self._clock.sleep(max(0.0, deadline - self._clock.now()))
        self._timer = None
        self._publish(self._recogniser.advance(self._clock.now()))

    # -- lost and back ------------------------------------------------------

    def _lose(self, reason: str) -> None:
        self._log.warning("keyfob lost", reason=reason)
        self._drop_device()
        self._held.clear()
        self._publish(self._recogniser.reset())
        self._report_lost(reason)

    def _report_lost(self, reason: str) -> None:
        self._events.put_nowait(KeyfobLost(at=self._clock.now(), reason=reason))
        if self._watch is None and not self._closed:
            self._watch = asyncio.get_running_loop().create_task(self._reopen())

    async def _reopen(self) -> None:
        watched = [self._input_dir]
        path = self._settings.device_path
        if path is not None and str(Path(path).parent) != self._input_dir:
            watched.append(str(Path(path).parent))  # /dev/input/by-id comes and goes
        grace_until: float | None = None
        try:
            with DirectoryWatch(watched) as watch:
                while not self._closed:
                    try:
                        self._open()
                    except PermissionError as error:
                        # The node exists but udev has not set its group yet.
                        now = self._clock.now()
                        grace_until = grace_until or now + self._settings.reopen_grace
                        if now < grace_until:
                            await self._clock.sleep(0.1)
                            continue
                        self._log.warning("keyfob not readable", error=_describe(error))
                        grace_until = None
                    except (OSError, KeyfobError) as error:
                        self._log.debug("keyfob still away", error=_describe(error))
                    except Exception as error:
                        # Not expected from a device node, but the watch must outlive it.
                        self._log.error("keyfob reopen failed", error=repr(error))
                    else:
                        assert self._device is not None
                        self._events.put_nowait(
                            KeyfobBack(
                                at=self._clock.now(), device=os.fsdecode(self._device.path)
                            )
                        )
                        return
                    await watch.changed(self._retry_every)
        finally:
            self._watch = None


class DirectoryWatch:
    """inotify on a few directories: `changed()` returns when any of them changes.

    ctypes over libc rather than a dependency; a directory that does not
    exist yet is added when it appears (checked at every change).
    """

    _MASK = 0x00000004 | 0x00000080 | 0x00000100 | 0x00000200  # ATTRIB MOVED_TO CREATE DELETE
    _IN_NONBLOCK, _IN_CLOEXEC = os.O_NONBLOCK, 0o2000000

    def __init__(self, directories: Iterable[str]) -> None:
        """Watch `directories` once entered (on the running loop); missing ones are added later."""
        self._directories = list(directories)
        self._unwatchable: set[str] = set()
        self._libc: Any = None
        self._fd = -1
        self._changed: asyncio.Event | None = None

    def __enter__(self) -> DirectoryWatch:
        """Start inotify and register it with the running loop.

        Without inotify (a sandbox that forbids it) this logs a warning and
        changed() only waits out its timeout.
        """
        self._changed = asyncio.Event()
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        fd = libc.inotify_init1(self._IN_NONBLOCK | self._IN_CLOEXEC)
        if fd < 0:
            # Without inotify the periodic retry still finds the keyfob, only later.
            log.warning("inotify unavailable", error=os.strerror(ctypes.get_errno()))
            return self
        self._libc, self._fd = libc, fd
        self._add_watches()
        asyncio.get_running_loop().add_reader(fd, self._on_readable)
        return self

    def __exit__(self, *exc: object) -> None:
        """Unregister and close the inotify descriptor."""
        if self._fd >= 0:
            asyncio.get_running_loop().remove_reader(self._fd)
            os.close(self._fd)
            self._fd = -1

    def _add_watches(self) -> None:
        for directory in self._directories:
            # Adding an existing watch again is harmless: inotify returns the same one.
            if self._libc.inotify_add_watch(self._fd, os.fsencode(directory), self._MASK) < 0:
                error = ctypes.get_errno()
                if error != errno.ENOENT and directory not in self._unwatchable:
                    # Only the periodic look finds the keyfob there: say why, once.
                    self._unwatchable.add(directory)
                    log.warning("cannot watch for the keyfob", directory=directory,
                                error=os.strerror(error))  # fmt: skip

    def _on_readable(self) -> None:
        try:
            data = os.read(self._fd, 65536)
        except BlockingIOError:
            return
        names = []
        offset = 0
        while offset + 16 <= len(data):
            _wd, _mask, _cookie, length = struct.unpack_from("iIII", data, offset)
            names.append(data[offset + 16 : offset + 16 + length].rstrip(b"\0"))
            offset += 16 + length
        log.debug("input directory changed", names=[n.decode(errors="replace") for n in names])
        self._add_watches()
        assert self._changed is not None
        self._changed.set()

    async def changed(self, timeout: float) -> None:
        """Wait for a change, or `timeout` seconds (the safety net)."""
        assert self._changed is not None
        # asyncio.timeout, not wait_for: on Python 3.11 wait_for can swallow a
        # cancellation that lands as the awaited thing completes.
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout):
                await self._changed.wait()
        self._changed.clear()


def _event_number(path: Path) -> int:
    digits = path.name.removeprefix("event")
    return int(digits) if digits.isdigit() else -1


def _describe(error: BaseException) -> str:
    if isinstance(error, OSError) and error.errno is not None:
        return f"{errno.errorcode.get(error.errno, error.errno)}: {error.strerror}"
    return str(error)
