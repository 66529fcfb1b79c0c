"""Pololu Maestro serial commands (compact protocol, and its Pololu form): pure functions.

Data bytes carry 7 bits each, so a 14-bit value goes low 7 bits first
(Maestro user's guide, section 5.e). Targets are in quarter-microseconds.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

from hal.errors import CodecError

POLOLU_START = 0xAA
DEFAULT_DEVICE = 12
MAX_CHANNELS = 24
ID_RANGE = (0, MAX_CHANNELS - 1)  # channels, the Maestro's "ids" (a Mini Maestro 24's)
MAX_VALUE = 0x3FFF


class MaestroError(CodecError):
    """A Maestro command that cannot be built or a reply that cannot be decoded."""


class Command(enum.IntEnum):
    """Command bytes of the compact protocol."""

    SET_TARGET = 0x84
    SET_SPEED = 0x87
    SET_ACCELERATION = 0x89
    GET_POSITION = 0x90
    GET_MOVING_STATE = 0x93
    SET_MULTIPLE_TARGETS = 0x9F  # Mini Maestro 12/18/24 only
    GET_ERRORS = 0xA1
    GO_HOME = 0xA2


class Errors(enum.IntFlag):
    """The Maestro's error register (Get Errors): its serial link and script, not a servo."""

    SERIAL_SIGNAL = 1 << 0
    SERIAL_OVERRUN = 1 << 1
    SERIAL_RX_BUFFER_FULL = 1 << 2
    SERIAL_CRC = 1 << 3
    SERIAL_PROTOCOL = 1 << 4
    SERIAL_TIMEOUT = 1 << 5
    SCRIPT_STACK = 1 << 6
    SCRIPT_CALL_STACK = 1 << 7
    SCRIPT_PROGRAM_COUNTER = 1 << 8


# Bytes each command carries after its command byte; SET_MULTIPLE_TARGETS is variable.
_DATA_BYTES = {
    Command.SET_TARGET: 3,
    Command.SET_SPEED: 3,
    Command.SET_ACCELERATION: 3,
    Command.GET_POSITION: 1,
    Command.GET_MOVING_STATE: 0,
    Command.GET_ERRORS: 0,
    Command.GO_HOME: 0,
}
REPLY_LENGTH = {Command.GET_POSITION: 2, Command.GET_MOVING_STATE: 1, Command.GET_ERRORS: 2}


def _channel(channel: int) -> int:
    if not 0 <= channel < MAX_CHANNELS:
        raise MaestroError(f"channel {channel} outside 0..{MAX_CHANNELS - 1}")
    return channel


def _value14(value: int) -> bytes:
    if not 0 <= value <= MAX_VALUE:
        raise MaestroError(f"value {value} outside 0..{MAX_VALUE}")
    return bytes((value & 0x7F, value >> 7))


def set_target(channel: int, target: int) -> bytes:
    """Target in quarter-microseconds; 0 stops the pulses (the servo goes limp)."""
    return bytes((Command.SET_TARGET, _channel(channel))) + _value14(target)


def set_speed(channel: int, speed: int) -> bytes:
    """Speed limit in 0.25 us per 10 ms; 0 is unlimited."""
    return bytes((Command.SET_SPEED, _channel(channel))) + _value14(speed)


def set_acceleration(channel: int, acceleration: int) -> bytes:
    """Acceleration limit 0 to 255 (0 is unlimited); MaestroError outside it."""
    if not 0 <= acceleration <= 255:
        raise MaestroError(f"acceleration {acceleration} outside 0..255")
    return bytes((Command.SET_ACCELERATION, _channel(channel))) + _value14(acceleration)


def set_multiple_targets(first_channel: int, targets: Sequence[int]) -> bytes:
    """Targets for consecutive channels from `first_channel`, in one command."""
    if not targets or first_channel + len(targets) > MAX_CHANNELS:
        raise MaestroError(f"{len(targets)} targets from channel {first_channel} do not fit")
    out = bytearray((Command.SET_MULTIPLE_TARGETS, len(targets), _channel(first_channel)))
    for target in targets:
        out += _value14(target)
    return bytes(out)


def get_position(channel: int) -> bytes:
    """Get Position: the reply is the channel's present pulse width (or input), 2 bytes."""
    return bytes((Command.GET_POSITION, _channel(channel)))


def get_moving_state() -> bytes:
    """Get Moving State: the reply is 1 byte, 1 while any servo is still moving."""
    return bytes((Command.GET_MOVING_STATE,))


def get_errors() -> bytes:
    """Get Errors: the reply is the error register, 2 bytes; reading it clears it."""
    return bytes((Command.GET_ERRORS,))


def go_home() -> bytes:
    """Go Home: every channel to its configured home position (or limp)."""
    return bytes((Command.GO_HOME,))


def pololu(device: int, compact: bytes) -> bytes:
    """The same command in the Pololu protocol form, addressed to one device on a daisy chain."""
    if not 0 <= device <= 0x7F:
        raise MaestroError(f"device number {device} outside 0..127")
    if not compact or compact[0] < 0x80:
        raise MaestroError("a compact command starts with a byte >= 0x80")
    return bytes((POLOLU_START, device, compact[0] & 0x7F)) + compact[1:]


def command_length(head: bytes) -> int:
    """Total length of the compact command starting `head` (2 bytes suffice for any)."""
    if not head:
        raise MaestroError("empty command")
    try:
        command = Command(head[0])
    except ValueError:
        raise MaestroError(f"unknown command byte {head[0]:#04x}") from None
    if command is Command.SET_MULTIPLE_TARGETS:
        if len(head) < 2:
            raise MaestroError("SET_MULTIPLE_TARGETS without its count")
        return 3 + 2 * head[1]
    return 1 + _DATA_BYTES[command]


def decode_command(raw: bytes) -> tuple[Command, tuple[int, ...]]:
    """(command, arguments) of one compact command; values are rebuilt from 7-bit pairs."""
    if len(raw) != command_length(raw[:2]):
        raise MaestroError(f"command of {len(raw)} bytes has the wrong length")
    if any(byte & 0x80 for byte in raw[1:]):
        raise MaestroError(f"data byte with its top bit set in {raw.hex(' ')}")
    command = Command(raw[0])
    if command is Command.SET_MULTIPLE_TARGETS:
        values = tuple(raw[i] | raw[i + 1] << 7 for i in range(3, len(raw), 2))
        return command, (raw[2], *values)
    if len(raw) == 4:
        return command, (raw[1], raw[2] | raw[3] << 7)
    return command, tuple(raw[1:])


def decode_position(reply: bytes) -> int:
    """Get Position reply: quarter-microseconds, or the analog reading of an input channel."""
    if len(reply) != 2:
        raise MaestroError(f"position reply of {len(reply)} bytes, expected 2")
    return reply[0] | reply[1] << 8


def decode_errors(reply: bytes) -> Errors:
    """The Get Errors reply; MaestroError for a wrong length or undefined bits."""
    if len(reply) != 2:
        raise MaestroError(f"errors reply of {len(reply)} bytes, expected 2")
    value = reply[0] | reply[1] << 8
    if value >> 9:
        raise MaestroError(f"errors value {value:#06x} has undefined bits set")
    return Errors(value)


def decode_moving_state(reply: bytes) -> bool:
    """The Get Moving State reply; MaestroError unless it is 00 or 01."""
    if len(reply) != 1 or reply[0] > 1:
        raise MaestroError(f"moving-state reply {reply.hex(' ')} is not 00 or 01")
    return reply[0] == 1
