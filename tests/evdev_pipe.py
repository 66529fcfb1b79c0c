"""A keyfob made of a pipe: struct-packed input_event records read by evdev's own code.

There is no /dev/uinput in CI, so the device under test is evdev's EventIO
(the base of evdev.InputDevice) over the read end of an os.pipe(); its read()
is evdev's C reader, parsing the same 24-byte records the kernel writes.
Unplugging makes the next read raise ENODEV, as the kernel does.
"""

from __future__ import annotations

import asyncio
import errno
import os
import stat
import struct
from collections.abc import Iterator
from pathlib import Path

from evdev import ecodes
from evdev.eventio_async import EventIO
from evdev.events import InputEvent

# struct input_event on 64-bit Linux: struct timeval (two longs), __u16 type, __u16 code, __s32 value.
INPUT_EVENT = struct.Struct("llHHi")


def pack(sec: float, type_: int, code: int, value: int) -> bytes:
    whole = int(sec)
    return INPUT_EVENT.pack(whole, round((sec - whole) * 1_000_000), type_, code, value)


class PipeInputDevice(EventIO):
    """Looks like evdev.InputDevice to the keyfob: fd, path, name, read, grab, close."""

    def __init__(self, path: str, name: str = "Kaspar keyfob") -> None:
        self.path = path
        self.name = name
        read_end, self._write_end = os.pipe()
        os.set_blocking(read_end, False)
        self.fd = read_end
        self.grabbed = False
        self.closed = False
        self._unplugged = False
        self.kernel_time = 1_000.0  # the "kernel" stamps events with its own clock

    # -- what the keyfob calls ----------------------------------------------

    def read(self) -> Iterator[InputEvent]:
        events = list(super().read())
        if not events and self._unplugged:
            raise OSError(errno.ENODEV, os.strerror(errno.ENODEV))
        return iter(events)

    def grab(self) -> None:
        self.grabbed = True

    def close(self) -> None:
        if self.fd > -1:
            super().close()
            os.close(self.fd)
            self.fd = -1
            self.closed = True

    # -- what the test calls ------------------------------------------------

    def write_raw(self, data: bytes) -> None:
        os.write(self._write_end, data)

    def events(self, *changes: tuple[int, int, float]) -> None:
        """Write key changes (code, value, seconds after the previous one) in one go."""
        data = b""
        for code, value, gap in changes:
            self.kernel_time += gap
            data += pack(self.kernel_time, ecodes.EV_MSC, ecodes.MSC_SCAN, 0x70000 + code)
            data += pack(self.kernel_time, ecodes.EV_KEY, code, value)
            data += pack(self.kernel_time, ecodes.EV_SYN, ecodes.SYN_REPORT, 0)
        self.write_raw(data)

    def down(self, code: int, gap: float = 0.0) -> None:
        self.events((code, 1, gap))

    def up(self, code: int, gap: float = 0.0) -> None:
        self.events((code, 0, gap))

    def unplug(self) -> None:
        """The kernel's view of a pulled plug: pending events, then ENODEV."""
        self._unplugged = True
        os.close(self._write_end)
        self._write_end = -1

    def end_of_file(self) -> None:
        """A plain end of file, without ENODEV."""
        os.close(self._write_end)
        self._write_end = -1

    def dispose(self) -> None:
        if self._write_end > -1:
            os.close(self._write_end)
            self._write_end = -1
        self.close()


class PipeBank:
    """Device nodes in a temporary /dev/input: a file per node, a pipe device behind each.

    The keyfob watches the directory with real inotify, so plugging in is
    creating the file and unplugging is removing it. A node without group
    read permission refuses to open, like one udev has not finished with.
    """

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.devices: dict[str, PipeInputDevice] = {}
        self.opened: list[str] = []

    def plug(self, node: str, name: str = "Kaspar keyfob", mode: int = 0o660) -> PipeInputDevice:
        path = str(self.directory / node)
        device = PipeInputDevice(path, name)
        self.devices[path] = device
        fd = os.open(path, os.O_CREAT | os.O_WRONLY, mode)
        os.close(fd)
        os.chmod(path, mode)
        return device

    def unplug(self, node: str) -> None:
        path = str(self.directory / node)
        self.devices.pop(path).unplug()
        os.unlink(path)

    def open(self, path: str) -> PipeInputDevice:
        mode = os.stat(path).st_mode  # FileNotFoundError when unplugged
        if not mode & stat.S_IRGRP:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), path)
        device = self.devices[path]
        if device.closed:
            raise OSError(errno.ENODEV, os.strerror(errno.ENODEV), path)  # a stale node
        self.opened.append(path)
        return device

    def dispose(self) -> None:
        for device in self.devices.values():
            device.dispose()


class ManualClock:
    """A clock the test moves: now() only changes in advance()."""

    def __init__(self, start: float = 100.0) -> None:
        self._now = start
        self._moved = asyncio.Condition()

    def now(self) -> float:
        return self._now

    async def sleep(self, seconds: float) -> None:
        until = self._now + max(0.0, seconds)
        async with self._moved:
            await self._moved.wait_for(lambda: self._now >= until)

    async def advance(self, seconds: float) -> None:
        async with self._moved:
            self._now += seconds
            self._moved.notify_all()
        for _ in range(5):  # let the woken sleepers run
            await asyncio.sleep(0)
