"""A Pololu Mini Maestro on a pty: compact protocol, targets, speed limits, errors.

As the Maestro user's guide describes it: channels start off (no pulses, the
default start-up setting) and Get Position of a channel without pulses reads 0;
a target of 0 stops the pulses; pulses resume at the new target at once (there
is no position to ramp from); a hobby servo has no feedback, so a position is
the pulse width being sent, never where a hand put the horn.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path

from emulators.base import Axis, Emulator
from hal.servos import maestro as mo


class MaestroEmulator(Emulator):
    def __init__(
        self, path: Path, channels: int = 12, rate: float = 40000.0,
        clock: Callable[[], float] = time.monotonic,
        inputs: Mapping[int, int] | None = None,
    ) -> None:
        # Channels configured as inputs: Get Position reads the input (0-1023; a digital
        # input, channels 12 and up of a Mini Maestro 18, reads 0 or 1023).
        self.inputs = dict(inputs or {})
        self.channels = channels
        self.axes = [Axis(0, 0, rate) for _ in range(channels)]
        self.targets = [0] * channels
        self.errors = 0
        super().__init__(path, clock)

    def split(self, buffer: bytes) -> tuple[bytes | None, bytes]:
        while buffer and buffer[0] < 0x80:
            buffer = buffer[1:]
        if not buffer:
            return None, buffer
        try:
            length = mo.command_length(buffer[:2])
        except mo.MaestroError:
            if len(buffer) < 2 and buffer[0] == mo.Command.SET_MULTIPLE_TARGETS:
                return None, buffer
            self.errors |= mo.Errors.SERIAL_PROTOCOL
            return self.split(buffer[1:])
        if len(buffer) < length:
            return None, buffer
        return buffer[:length], buffer[length:]

    def _set(self, channel: int, target: int) -> None:
        if channel >= self.channels:
            self.errors |= mo.Errors.SERIAL_PROTOCOL
            return
        axis = self.axes[channel]
        axis.update(self.clock())
        was_off = self.targets[channel] == 0
        self.targets[channel] = target
        axis.torque = target != 0  # target 0 stops the pulses: the servo goes limp
        axis.goal = target
        if was_off or not target:
            axis.present = target  # pulses stop at once, and start again at the target

    def handle(self, packet: bytes) -> list[tuple[int, bytes]]:
        try:
            command, args = mo.decode_command(packet)
        except mo.MaestroError:
            self.errors |= mo.Errors.SERIAL_PROTOCOL
            return []
        if command is mo.Command.SET_TARGET:
            self._set(*args)
        elif command is mo.Command.SET_MULTIPLE_TARGETS:
            for offset, target in enumerate(args[1:]):
                self._set(args[0] + offset, target)
        elif command is mo.Command.GET_POSITION:
            channel = args[0]
            if channel in self.inputs:
                value = self.inputs[channel]
                return [(channel, bytes((value & 0xFF, value >> 8)))]
            position = round(self.axes[channel].update(self.clock())) if channel < self.channels else 0
            return [(channel, bytes((position & 0xFF, position >> 8)))]
        elif command is mo.Command.GET_ERRORS:
            errors = self.errors | self.faults.error_bits.get(0, 0)
            self.errors = 0
            return [(0, bytes((errors & 0xFF, errors >> 8)))]
        elif command is mo.Command.GET_MOVING_STATE:
            now = self.clock()
            moving = any(a.update(now) != round(a.goal) for a in self.axes if a.torque)
            return [(0, bytes((int(moving),)))]
        return []
