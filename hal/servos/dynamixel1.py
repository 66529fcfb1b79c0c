"""Dynamixel Protocol 1.0 packets (AX-12A and friends): pure functions, no I/O.

Packet: FF FF ID LEN INST PARAMS CHK, LEN = len(PARAMS) + 2,
CHK = ~(ID + LEN + INST + sum(PARAMS)) & 0xFF (ROBOTIS e-manual, Protocol 1.0).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from hal.errors import CodecError

HEADER = b"\xff\xff"
BROADCAST_ID = 0xFE
MAX_ID = 0xFD
ID_RANGE = (0, MAX_ID)  # the ids a servo can have (BROADCAST_ID is no servo's)
HEAD_SIZE = 4  # FF FF ID LEN: enough to know the whole packet's length


class DynamixelError(CodecError):
    """A Dynamixel (Protocol 1.0 or 2.0) packet that cannot be built or decoded."""


class Instruction(enum.IntEnum):
    """Instruction codes of Protocol 1.0."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    RESET = 0x06
    SYNC_WRITE = 0x83
    BULK_READ = 0x92  # MX series only; the AX-12A does not answer it


class ErrorBits(enum.IntFlag):
    """The status packet's error byte (AX-12A e-manual, Status Packet)."""

    INPUT_VOLTAGE = 0x01
    ANGLE_LIMIT = 0x02
    OVERHEATING = 0x04
    RANGE = 0x08
    CHECKSUM = 0x10
    OVERLOAD = 0x20
    INSTRUCTION = 0x40


class AX12(enum.IntEnum):
    """AX-12A control table addresses (EEPROM below 24, RAM from 24)."""

    MODEL_NUMBER = 0
    FIRMWARE_VERSION = 2
    ID = 3
    BAUD_RATE = 4
    RETURN_DELAY_TIME = 5
    CW_ANGLE_LIMIT = 6
    CCW_ANGLE_LIMIT = 8
    TEMPERATURE_LIMIT = 11
    MIN_VOLTAGE_LIMIT = 12
    MAX_VOLTAGE_LIMIT = 13
    MAX_TORQUE = 14
    STATUS_RETURN_LEVEL = 16
    ALARM_LED = 17
    ALARM_SHUTDOWN = 18
    TORQUE_ENABLE = 24
    LED = 25
    GOAL_POSITION = 30
    MOVING_SPEED = 32
    TORQUE_LIMIT = 34
    PRESENT_POSITION = 36
    PRESENT_SPEED = 38
    PRESENT_LOAD = 40
    PRESENT_VOLTAGE = 42
    PRESENT_TEMPERATURE = 43
    REGISTERED = 44
    MOVING = 46
    LOCK = 47
    PUNCH = 48


AX12_MODEL_NUMBER = 12
AX12_CONTROL_TABLE_SIZE = 50


@dataclass(frozen=True, slots=True)
class Packet:
    """An instruction packet, decoded (the emulators and round-trip tests use it)."""

    servo_id: int
    instruction: int
    params: bytes


@dataclass(frozen=True, slots=True)
class Status:
    """A decoded status packet: who answered, its error bits and the data read."""

    servo_id: int
    error: ErrorBits
    params: bytes


def checksum(body: bytes) -> int:
    """The inverted low byte of the sum of ID, LENGTH, INSTRUCTION and PARAMS."""
    return ~sum(body) & 0xFF


def _check_id(servo_id: int, broadcast: bool = False) -> None:
    highest = BROADCAST_ID if broadcast else MAX_ID
    if not 0 <= servo_id <= highest:
        raise DynamixelError(f"servo id {servo_id} outside 0..{highest}")


def _check_byte(name: str, value: int) -> None:
    if not 0 <= value <= 0xFF:
        raise DynamixelError(f"{name} {value} does not fit in one byte")


def instruction(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A whole packet to `servo_id` (or BROADCAST_ID); DynamixelError if a field does not fit."""
    _check_id(servo_id, broadcast=True)
    _check_byte("instruction", instruction)
    length = len(params) + 2
    if length > 0xFF:
        raise DynamixelError(f"{len(params)} parameter bytes do not fit in one packet")
    body = bytes((servo_id, length, instruction)) + params
    return HEADER + body + bytes((checksum(body),))


def ping(servo_id: int) -> bytes:
    """PING: the servo answers with an empty status packet."""
    return instruction(servo_id, Instruction.PING)


def read(servo_id: int, address: int, length: int) -> bytes:
    """READ `length` bytes of the control table from `address`."""
    _check_byte("address", address)
    _check_byte("length", length)
    return instruction(servo_id, Instruction.READ, bytes((address, length)))


def write(servo_id: int, address: int, data: bytes) -> bytes:
    """WRITE `data` into the control table at `address`, at once."""
    _check_byte("address", address)
    return instruction(servo_id, Instruction.WRITE, bytes((address,)) + data)


def reg_write(servo_id: int, address: int, data: bytes) -> bytes:
    """REG_WRITE: like WRITE, but held until ACTION."""
    _check_byte("address", address)
    return instruction(servo_id, Instruction.REG_WRITE, bytes((address,)) + data)


def action(servo_id: int = BROADCAST_ID) -> bytes:
    """ACTION: carry out the writes held by REG_WRITE (every servo by default)."""
    return instruction(servo_id, Instruction.ACTION)


def reset(servo_id: int) -> bytes:
    """RESET the control table to the factory values (id 1, 1 Mbps): never sent by the HAL."""
    return instruction(servo_id, Instruction.RESET)


def sync_write(address: int, length: int, data: Mapping[int, bytes]) -> bytes:
    """One packet that writes `length` bytes at `address` on every servo in `data`."""
    _check_byte("address", address)
    _check_byte("length", length)
    params = bytearray((address, length))
    for servo_id, values in data.items():
        _check_id(servo_id)
        if len(values) != length:
            raise DynamixelError(f"servo {servo_id}: {len(values)} bytes for a {length}-byte write")
        params.append(servo_id)
        params += values
    return instruction(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def bulk_read(items: Sequence[tuple[int, int, int]]) -> bytes:
    """BULK_READ of (id, address, length) items; MX series only."""
    params = bytearray((0x00,))
    for servo_id, address, length in items:
        _check_id(servo_id)
        _check_byte("address", address)
        _check_byte("length", length)
        params += bytes((length, servo_id, address))
    return instruction(BROADCAST_ID, Instruction.BULK_READ, bytes(params))


def status(servo_id: int, error: int = 0, params: bytes = b"") -> bytes:
    """A status packet as a servo sends it (for emulators and round-trip tests)."""
    _check_byte("error", error)
    return instruction(servo_id, error, params)


def packet_length(head: bytes) -> int:
    """Total length of the packet whose first HEAD_SIZE bytes are `head`."""
    if len(head) < HEAD_SIZE or head[:2] != HEADER:
        raise DynamixelError(f"not a Protocol 1.0 header: {head[:HEAD_SIZE].hex(' ')}")
    if head[3] < 2:
        raise DynamixelError(f"length byte {head[3]} is below the minimum of 2")
    return head[3] + 4


def _unframe(packet: bytes) -> tuple[int, int, bytes]:
    length = packet_length(packet)
    if len(packet) != length:
        raise DynamixelError(f"packet of {len(packet)} bytes, its length byte says {length}")
    if checksum(packet[2:-1]) != packet[-1]:
        raise DynamixelError(f"bad checksum in {packet.hex(' ')}")
    if packet[2] > BROADCAST_ID:
        raise DynamixelError(f"servo id {packet[2]} is not valid")
    return packet[2], packet[4], packet[5:-1]


def decode_status(packet: bytes) -> Status:
    """A servo's status packet; DynamixelError for a bad frame, checksum, id or error byte."""
    servo_id, error, params = _unframe(packet)
    if servo_id > MAX_ID:
        raise DynamixelError(f"status packet from the broadcast id {servo_id}")
    if error & 0x80:
        raise DynamixelError(f"error byte {error:#04x} has its reserved bit set")
    return Status(servo_id, ErrorBits(error), params)


def decode_instruction(packet: bytes) -> Packet:
    """An instruction packet as a servo reads it (emulators and round-trip tests)."""
    servo_id, instruction_code, params = _unframe(packet)
    return Packet(servo_id, instruction_code, params)


def u16(data: bytes, offset: int = 0) -> int:
    """The little-endian unsigned 16-bit value at `offset`."""
    return data[offset] | data[offset + 1] << 8


def le16(value: int) -> bytes:
    """Two little-endian bytes; DynamixelError outside 0..65535."""
    if not 0 <= value <= 0xFFFF:
        raise DynamixelError(f"{value} does not fit in two bytes")
    return bytes((value & 0xFF, value >> 8))
