"""Event times from CLOCK_MONOTONIC: a wall-clock step inside a press changes nothing.

The kernel stamps a node's events with CLOCK_REALTIME unless EVIOCSCLOCKID asks for
another clock. The pipe device here stands in for the kernel: it stamps with its wall
clock, or with its monotonic clock once the reader's ioctl has asked for it (the request
and argument checked as the kernel would). Press and release are read in one batch, so
the reader spaces them by the stamps.
"""

from __future__ import annotations

import asyncio
import errno
import os
import struct
import time
from pathlib import Path

import pytest
from evdev import ecodes
from evdev_pipe import ManualClock, PipeInputDevice, pack

from hal.keyfob.gestures import GestureKind, held_gestures
from hal.keyfob.reader import EVIOCSCLOCKID, Keyfob, stamp_monotonic
from hal.keyfob.settings import KeyfobSettings

GREEN = ecodes.KEY_PAGEDOWN


class KernelClocks(PipeInputDevice):
    """A node whose stamps follow the clock its descriptor was set to."""

    def __init__(self, path: str) -> None:
        super().__init__(path)
        self.clock_id = time.CLOCK_REALTIME
        self.monotonic_now = 500.0
        self.wall_now = 1_764_000_000.0

    def ioctl(self, fd: int, request: int, argument: bytes) -> None:
        if fd != self.fd or request != EVIOCSCLOCKID:
            raise OSError(errno.ENOTTY, "not an evdev request")
        (clock_id,) = struct.unpack("i", argument)
        if clock_id not in (time.CLOCK_REALTIME, time.CLOCK_MONOTONIC, time.CLOCK_BOOTTIME):
            raise OSError(errno.EINVAL, "no such clock")
        self.clock_id = clock_id

    def key(self, code: int, value: int, after: float, wall_step: float = 0.0) -> bytes:
        self.monotonic_now += after
        self.wall_now += after + wall_step
        stamp = self.monotonic_now if self.clock_id == time.CLOCK_MONOTONIC else self.wall_now
        return pack(stamp, ecodes.EV_KEY, code, value) + pack(stamp, ecodes.EV_SYN, 0, 0)


async def quick_green_across_a_wall_clock_step(tmp_path: Path, ioctl) -> list:
    device = KernelClocks(str(tmp_path / "kaspar-keyfob"))
    clock = ManualClock()
    keyfob = Keyfob(
        KeyfobSettings(device=device.path),
        clock,
        needs=held_gestures(3.0),  # one keyfob: a long green (3 s) is the researcher's next
        opener=lambda path: device,
        input_dir=str(tmp_path),
        ioctl=ioctl or device.ioctl,
    )
    await keyfob.start()
    try:
        # A 0.15 s press; NTP steps the wall clock forward an hour in between.
        device.write_raw(device.key(GREEN, 1, 0.0) + device.key(GREEN, 0, 0.15, wall_step=3600))
        await asyncio.sleep(0.05)
        await clock.advance(0.1)
        out = []
        while True:
            try:
                out.append(await asyncio.wait_for(keyfob.next_event(), 0.2))
            except TimeoutError:
                return [(g.kind, g.button) for g in out]
    finally:
        await keyfob.close()
        device.dispose()


async def test_a_wall_clock_step_inside_a_press_leaves_it_a_press(tmp_path):
    assert await quick_green_across_a_wall_clock_step(tmp_path, None) == [
        (GestureKind.PRESS, "green")
    ]


async def test_without_the_monotonic_clock_the_step_would_make_it_a_hold(tmp_path):
    def refuses(fd: int, request: int, argument: bytes) -> None:
        raise OSError(errno.ENOTTY, "refused")

    # What the reader did before it asked for CLOCK_MONOTONIC: a long green, a command.
    assert await quick_green_across_a_wall_clock_step(tmp_path, refuses) == [
        (GestureKind.LONG, "green")
    ]


def test_the_request_is_the_kernels():
    calls = []
    stamp_monotonic(7, lambda fd, request, argument: calls.append((fd, request, argument)))
    assert calls == [(7, 0x400445A0, struct.pack("i", time.CLOCK_MONOTONIC))]
    read_end, write_end = os.pipe()
    try:
        with pytest.raises(OSError) as refused:  # the real ioctl on what is no input node
            stamp_monotonic(read_end)
        assert refused.value.errno == errno.ENOTTY
    finally:
        os.close(read_end)
        os.close(write_end)
