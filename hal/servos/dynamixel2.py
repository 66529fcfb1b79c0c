"""Dynamixel Protocol 2.0 packets (X series): pure functions, no I/O.

Packet: FF FF FD 00 ID LEN_L LEN_H INST PARAMS CRC_L CRC_H. LEN counts INST,
the (stuffed) PARAMS and the CRC; the CRC-16 (polynomial 0x8005, initial 0,
not reflected) covers everything before it. Inside INST+PARAMS every
FF FF FD is followed by an extra FD so that a header never appears there.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

# The same error class for both protocol versions, re-exported for dx2.DynamixelError.
from hal.servos.dynamixel1 import DynamixelError as DynamixelError

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 0xFC  # 0xFD is reserved so that it cannot complete a header
ID_RANGE = (0, MAX_ID)  # the ids a servo can have
HEAD_SIZE = 7  # FF FF FD 00 ID LEN_L LEN_H
STATUS = 0x55


class Instruction(enum.IntEnum):
    """Instruction codes of Protocol 2.0."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    BULK_READ = 0x92
    BULK_WRITE = 0x93


class ErrorNumber(enum.IntEnum):
    """Bits 0-6 of a status packet's error byte."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


ALERT = 0x80  # error byte bit 7: read Hardware Error Status for the cause


class HardwareError(enum.IntFlag):
    """X series Hardware Error Status (address 70)."""

    INPUT_VOLTAGE = 0x01
    OVERHEATING = 0x04
    MOTOR_ENCODER = 0x08
    ELECTRICAL_SHOCK = 0x10
    OVERLOAD = 0x20


class XSeries(enum.IntEnum):
    """X series (XL430/XM430) control table addresses."""

    MODEL_NUMBER = 0
    FIRMWARE_VERSION = 6
    ID = 7
    BAUD_RATE = 8
    RETURN_DELAY_TIME = 9
    OPERATING_MODE = 11
    TEMPERATURE_LIMIT = 31
    TORQUE_ENABLE = 64
    LED = 65
    STATUS_RETURN_LEVEL = 68
    HARDWARE_ERROR_STATUS = 70
    PROFILE_ACCELERATION = 108
    PROFILE_VELOCITY = 112
    GOAL_POSITION = 116
    MOVING = 122
    PRESENT_LOAD = 126
    PRESENT_VELOCITY = 128
    PRESENT_POSITION = 132
    PRESENT_INPUT_VOLTAGE = 144
    PRESENT_TEMPERATURE = 146


XL430_MODEL_NUMBER = 1060
X_CONTROL_TABLE_SIZE = 147


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes) -> int:
    """CRC-16 of `data` (polynomial 0x8005, initial 0, not reflected), as ROBOTIS specifies."""
    crc = 0
    for byte in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(payload: bytes) -> bytes:
    """Add an FD after every FF FF FD in INST+PARAMS, so no header appears inside a packet."""
    out = bytearray()
    for byte in payload:
        out.append(byte)
        if out[-3:] == b"\xff\xff\xfd":
            out.append(0xFD)
    return bytes(out)


def unstuff(payload: bytes) -> bytes:
    """Remove the FD that stuff() added after each FF FF FD."""
    out = bytearray()
    index = 0
    while index < len(payload):
        out.append(payload[index])
        if out[-3:] == b"\xff\xff\xfd" and payload[index + 1 : index + 2] == b"\xfd":
            index += 1  # drop the stuffing byte
        index += 1
    return bytes(out)


@dataclass(frozen=True, slots=True)
class Packet:
    """An instruction packet, decoded and unstuffed (the emulators and round-trip tests use it)."""

    servo_id: int
    instruction: int
    params: bytes


@dataclass(frozen=True, slots=True)
class Status:
    """A decoded status packet: who answered, its error number, the alert bit, the data read."""

    servo_id: int
    error: ErrorNumber
    alert: bool
    params: bytes


def _check(name: str, value: int, highest: int) -> None:
    if not 0 <= value <= highest:
        raise DynamixelError(f"{name} {value} outside 0..{highest}")


def le16(value: int) -> bytes:
    """Two little-endian bytes; DynamixelError outside 0..65535."""
    _check("value", value, 0xFFFF)
    return value.to_bytes(2, "little")


def le32(value: int) -> bytes:
    """Four bytes, two's complement for negative values (positions and velocities are signed)."""
    if not -(2**31) <= value < 2**32:
        raise DynamixelError(f"{value} does not fit in four bytes")
    return (value & 0xFFFFFFFF).to_bytes(4, "little")


def u16(data: bytes, offset: int = 0) -> int:
    """The little-endian unsigned 16-bit value at `offset`."""
    return int.from_bytes(data[offset : offset + 2], "little")


def s32(data: bytes, offset: int = 0) -> int:
    """The little-endian signed 32-bit value at `offset` (positions, velocities)."""
    return int.from_bytes(data[offset : offset + 4], "little", signed=True)


def instruction(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A whole packet, stuffed and with its CRC; DynamixelError if a field does not fit."""
    _check("servo id", servo_id, BROADCAST_ID)
    _check("instruction", instruction, 0xFF)
    body = stuff(bytes((instruction,)) + params)
    length = len(body) + 2
    _check("packet length", length, 0xFFFF)
    packet = HEADER + bytes((servo_id,)) + le16(length) + body
    return packet + le16(crc16(packet))


def ping(servo_id: int) -> bytes:
    """PING: the reply carries the model number and firmware version."""
    return instruction(servo_id, Instruction.PING)


def read(servo_id: int, address: int, length: int) -> bytes:
    """READ `length` bytes of the control table from `address`."""
    return instruction(servo_id, Instruction.READ, le16(address) + le16(length))


def write(servo_id: int, address: int, data: bytes) -> bytes:
    """WRITE `data` into the control table at `address`."""
    return instruction(servo_id, Instruction.WRITE, le16(address) + data)


def reboot(servo_id: int) -> bytes:
    """REBOOT: clears Hardware Error Status; the servo comes back with torque off."""
    return instruction(servo_id, Instruction.REBOOT)


def sync_read(address: int, length: int, servo_ids: Iterable[int]) -> bytes:
    """SYNC_READ: each servo answers in turn with `length` bytes from `address`."""
    ids = bytes(servo_ids)
    for servo_id in ids:
        _check("servo id", servo_id, MAX_ID)
    return instruction(BROADCAST_ID, Instruction.SYNC_READ, le16(address) + le16(length) + ids)


def sync_write(address: int, length: int, data: Mapping[int, bytes]) -> bytes:
    """One packet that writes `length` bytes at `address` on every servo in `data`."""
    params = bytearray(le16(address) + le16(length))
    for servo_id, values in data.items():
        _check("servo id", servo_id, MAX_ID)
        if len(values) != length:
            raise DynamixelError(f"servo {servo_id}: {len(values)} bytes for a {length}-byte write")
        params.append(servo_id)
        params += values
    return instruction(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def bulk_read(items: Sequence[tuple[int, int, int]]) -> bytes:
    """BULK_READ of (id, address, length) items, each servo its own range."""
    params = bytearray()
    for servo_id, address, length in items:
        _check("servo id", servo_id, MAX_ID)
        params += bytes((servo_id,)) + le16(address) + le16(length)
    return instruction(BROADCAST_ID, Instruction.BULK_READ, bytes(params))


def bulk_write(items: Sequence[tuple[int, int, bytes]]) -> bytes:
    """BULK_WRITE of (id, address, data) items, each servo its own range."""
    params = bytearray()
    for servo_id, address, data in items:
        _check("servo id", servo_id, MAX_ID)
        params += bytes((servo_id,)) + le16(address) + le16(len(data)) + data
    return instruction(BROADCAST_ID, Instruction.BULK_WRITE, bytes(params))


def status(servo_id: int, error: int = 0, params: bytes = b"") -> bytes:
    """A status packet as a servo sends it (for emulators and round-trip tests)."""
    _check("error", error, 0xFF)
    return instruction(servo_id, STATUS, bytes((error,)) + params)


def packet_length(head: bytes) -> int:
    """Total length of the packet whose first HEAD_SIZE bytes are `head`; DynamixelError if bad."""
    if len(head) < HEAD_SIZE or head[:4] != HEADER:
        raise DynamixelError(f"not a Protocol 2.0 header: {head[:HEAD_SIZE].hex(' ')}")
    length = u16(head, 5)
    if length < 3:
        raise DynamixelError(f"length field {length} is below the minimum of 3")
    return HEAD_SIZE + length


def _unframe(packet: bytes) -> tuple[int, int, bytes]:
    length = packet_length(packet)
    if len(packet) != length:
        raise DynamixelError(f"packet of {len(packet)} bytes, its length field says {length}")
    if crc16(packet[:-2]) != u16(packet, length - 2):
        raise DynamixelError(f"bad CRC in {packet.hex(' ')}")
    if packet[4] > BROADCAST_ID:
        raise DynamixelError(f"servo id {packet[4]} is not valid")
    body = unstuff(packet[7:-2])
    return packet[4], body[0], body[1:]


def decode_status(packet: bytes) -> Status:
    """A servo's status packet; DynamixelError for a bad frame, CRC, id or error number."""
    servo_id, instruction_code, params = _unframe(packet)
    if instruction_code != STATUS:
        raise DynamixelError(f"instruction {instruction_code:#04x} where a status (0x55) was due")
    if not params:
        raise DynamixelError("status packet without its error byte")
    if servo_id > MAX_ID:
        raise DynamixelError(f"status packet from the broadcast id {servo_id}")
    try:
        error = ErrorNumber(params[0] & 0x7F)
    except ValueError:
        raise DynamixelError(f"unknown error number {params[0] & 0x7F}") from None
    return Status(servo_id, error, bool(params[0] & ALERT), params[1:])


def decode_instruction(packet: bytes) -> Packet:
    """An instruction packet as a servo reads it (emulators and round-trip tests)."""
    servo_id, instruction_code, params = _unframe(packet)
    return Packet(servo_id, instruction_code, params)
