"""HerkuleX (DRS-0101/0201) packets and register values: pure functions, no I/O.

Packet: FF FF SIZE ID CMD CS1 CS2 DATA..., SIZE counts every byte,
CS1 = (SIZE ^ ID ^ CMD ^ each DATA byte) & 0xFE, CS2 = ~CS1 & 0xFE
(HerkuleX manual v1.1, section 4-1). A reply (ACK) has CMD | 0x40 and ends
with the status error and status detail bytes.

What real servos send beyond the packet layout, and how it is read here:
- a position register's high byte carries flag bits above bit 1 (a public
  capture of a DRS-0101 shows 0x62 for position 0x21F); positions are 10 bits,
  as Dongbu's own libraries read them (`& 0x03` on the high byte);
- the model is EEP 0 (Model No1: 0x01 DRS-0101, 0x02 DRS-0201) and EEP 1
  (Model No2: 0x01); read as one little-endian register like every other;
- voltage is 0.074 V per unit (manual: 0x5B = 6.714 V, 0x89 = 10 V);
- temperature is a raw ADC value: see TEMPERATURE_CENTI_C.
"""

from __future__ import annotations

import bisect
import enum
from collections.abc import Sequence
from dataclasses import dataclass

from hal.errors import CodecError

HEADER = b"\xff\xff"
BROADCAST_ID = 0xFE
MAX_ID = 0xFD
ID_RANGE = (0, MAX_ID)  # the ids a servo can have; a new one answers at FACTORY_ID
FACTORY_ID = 0xFD  # manual: every servo leaves the factory as 253
HEAD_SIZE = 3  # FF FF SIZE
MIN_SIZE = 7
MAX_SIZE = 223
ACK_FLAG = 0x40
PLAYTIME_SECONDS = 0.0112  # one play-time unit (DRS-0101)
MAX_PLAYTIME = 0xFF  # 2.856 s
POSITION_BITS = 0x03FF  # a position is 10 bits; the high byte's upper bits are flags
VOLTS_PER_UNIT = 0.074
# Model numbers: EEP 0-1 read as one little-endian register (Model No1 | Model No2 << 8).
MODEL_DRS_0101 = 0x0101
MODEL_DRS_0201 = 0x0102
# EEP registers a servo answers (manual, non-volatile register map: addresses 0 to 53).
EEP_SIZE = 54

# Raw temperature (RAM 55, and RAM 5 / EEP 11, the servo's own limit) to 1/100 degC: the
# manual's thermistor table, one entry per raw value 0x00-0xFE (0xFF is not in it: no
# servo reads it). As printed in sweetie-bot-project/sweetie_bot_herkulex
# (herkulex_servo_drs101.cpp) and, up to 0xD2, robotActionController's herkulex.py
# (T_ADC). The first prints 0xCD (205) as 68.61, out of sequence between 65.78 and
# 67.46; the second prints 66.61, which is in sequence: 66.61 is used. Points the issue
# checks: 0x42 = 0.05, 0x80 = 25.2, 0xA0 = 39.13, 0xC8 = 62.63, 0xDE = 84.11,
# 0xDF = 85.42, 0xF0 = 119.49 (tests/test_herkulex.py).
TEMPERATURE_CENTI_C: tuple[int, ...] = (
    -7947, -7178, -6320, -5781, -5380, -5058, -4786, -4549, -4340, -4151, -3979, -3820,  # 0x00-0x0B
    -3673, -3535, -3406, -3283, -3167, -3057, -2951, -2850, -2753, -2659, -2569, -2482,  # 0x0C-0x17
    -2397, -2315, -2236, -2159, -2083, -2010, -1938, -1868, -1800, -1733, -1667, -1603,  # 0x18-0x23
    -1539, -1477, -1417, -1357, -1298, -1240, -1183, -1126, -1071, -1016, -962, -909,  # 0x24-0x2F
    -856, -804, -753, -702, -652, -602, -553, -504, -456, -408, -361, -314,  # 0x30-0x3B
    -267, -221, -175, -129, -84, -39, 5, 49, 93, 137, 181, 224,  # 0x3C-0x47
    267, 310, 352, 394, 437, 478, 520, 562, 603, 644, 686, 727,  # 0x48-0x53
    767, 808, 849, 889, 929, 970, 1010, 1050, 1090, 1130, 1170, 1209,  # 0x54-0x5F
    1249, 1289, 1328, 1368, 1407, 1447, 1486, 1526, 1565, 1605, 1644, 1684,  # 0x60-0x6B
    1723, 1762, 1802, 1841, 1881, 1920, 1960, 1999, 2039, 2079, 2119, 2158,  # 0x6C-0x77
    2198, 2238, 2278, 2318, 2359, 2399, 2439, 2480, 2520, 2561, 2602, 2643,  # 0x78-0x83
    2684, 2725, 2766, 2808, 2850, 2891, 2933, 2976, 3018, 3060, 3103, 3146,  # 0x84-0x8F
    3189, 3232, 3276, 3320, 3364, 3408, 3453, 3497, 3542, 3588, 3633, 3679,  # 0x90-0x9B
    3725, 3772, 3818, 3866, 3913, 3961, 4009, 4057, 4106, 4156, 4205, 4256,  # 0x9C-0xA7
    4306, 4357, 4409, 4461, 4513, 4566, 4619, 4673, 4728, 4783, 4839, 4895,  # 0xA8-0xB3
    4952, 5009, 5068, 5127, 5186, 5247, 5308, 5370, 5433, 5496, 5561, 5626,  # 0xB4-0xBF
    5693, 5760, 5828, 5898, 5968, 6040, 6113, 6187, 6263, 6339, 6417, 6497,  # 0xC0-0xCB
    6578, 6661, 6746, 6832, 6920, 7010, 7102, 7196, 7292, 7391, 7492, 7596,  # 0xCC-0xD7
    7703, 7812, 7925, 8041, 8160, 8284, 8411, 8542, 8679, 8820, 8966, 9118,  # 0xD8-0xE3
    9276, 9441, 9613, 9793, 9982, 10181, 10390, 10611, 10845, 11093, 11359, 11643,  # 0xE4-0xEF
    11949, 12280, 12641, 13036, 13472, 13959, 14509, 15139, 15873, 16750, 17829, 19218,  # 0xF0-0xFB
    21132, 24101, 30091,  # 0xFC-0xFE
)
LAST_TEMPERATURE_RAW = 0xFE


class HerkulexError(CodecError):
    """A HerkuleX packet that cannot be built or decoded."""


class Command(enum.IntEnum):
    """Command codes; a reply carries the command | ACK_FLAG."""

    EEP_WRITE = 0x01
    EEP_READ = 0x02
    RAM_WRITE = 0x03
    RAM_READ = 0x04
    I_JOG = 0x05
    S_JOG = 0x06
    STAT = 0x07
    ROLLBACK = 0x08
    REBOOT = 0x09


class Ram(enum.IntEnum):
    """Volatile register map addresses (DRS-0101)."""

    ID = 0
    ACK_POLICY = 1
    ALARM_LED_POLICY = 2
    TORQUE_POLICY = 3
    MAX_TEMPERATURE = 5
    MIN_VOLTAGE = 6
    MAX_VOLTAGE = 7
    MIN_POSITION = 20
    MAX_POSITION = 22
    STATUS_ERROR = 48
    STATUS_DETAIL = 49
    TORQUE_CONTROL = 52
    LED_CONTROL = 53
    VOLTAGE = 54
    TEMPERATURE = 55
    CURRENT_CONTROL_MODE = 56
    TICK = 57
    CALIBRATED_POSITION = 58
    ABSOLUTE_POSITION = 60
    DIFFERENTIAL_POSITION = 62
    PWM = 64
    ABSOLUTE_GOAL_POSITION = 68
    ABSOLUTE_DESIRED_TRAJECTORY = 70
    DESIRED_VELOCITY = 72
    RAM_SIZE = 74


class Eep(enum.IntEnum):
    """Non-volatile register map addresses (DRS-0101), the few the HAL reads."""

    MODEL_NO_1 = 0
    MODEL_NO_2 = 1
    VERSION_1 = 2
    VERSION_2 = 3
    BAUD_RATE = 4
    ID = 6
    ACK_POLICY = 7
    ALARM_LED_POLICY = 8
    TORQUE_POLICY = 9
    MAX_TEMPERATURE = 11
    MIN_VOLTAGE = 12
    MAX_VOLTAGE = 13
    MIN_POSITION = 26
    MAX_POSITION = 28


class TorqueControl(enum.IntEnum):
    """Values of the TORQUE_CONTROL register: free (limp), brake, or on."""

    FREE = 0x00
    BRAKE = 0x40
    ON = 0x60


class AckPolicy(enum.IntEnum):
    """Which requests a servo answers (RAM 1, copied from EEP 7 at power-up).

    STAT is answered whatever the policy; a broadcast (id 0xFE) never is, STAT
    excepted. The driver writes READS_ONLY to every servo at start and after a
    reconnect, because a previous program may have left any value.
    """

    NEVER = 0  # STAT only
    READS_ONLY = 1  # the factory default: RAM/EEP_READ and STAT
    ALWAYS = 2  # writes and jogs too


# Factory torque policy (manual, EEP 9 = 0x35): these errors release the torque.
DEFAULT_TORQUE_POLICY = 0x35


class StatusError(enum.IntFlag):
    """The status error byte of every reply; the servo latches it until written to zero."""

    EXCEED_INPUT_VOLTAGE = 0x01
    EXCEED_POT_LIMIT = 0x02
    EXCEED_TEMPERATURE = 0x04
    INVALID_PACKET = 0x08
    OVERLOAD = 0x10
    DRIVER_FAULT = 0x20
    EEP_DISTORTED = 0x40


# Errors that are about one packet or the servo's own position limits, not its health:
# written back to zero as soon as they are seen (and logged), so that its LED stops
# blinking and a later real error is not hidden behind them.
TRANSIENT_ERRORS = StatusError.INVALID_PACKET | StatusError.EXCEED_POT_LIMIT


class StatusDetail(enum.IntFlag):
    """The status detail byte of every reply."""

    MOVING = 0x01
    INPOSITION = 0x02
    CHECKSUM_ERROR = 0x04
    UNKNOWN_COMMAND = 0x08
    EXCEED_REG_RANGE = 0x10
    GARBAGE = 0x20
    MOTOR_ON = 0x40


class JogSet(enum.IntFlag):
    """The SET byte of a JOG entry: position mode unless CONTINUOUS."""

    STOP = 0x01
    CONTINUOUS = 0x02
    GREEN = 0x04
    BLUE = 0x08
    RED = 0x10
    INVALID = 0x20


@dataclass(frozen=True, slots=True)
class Packet:
    """A packet with its checksums verified, any command (the emulator reads requests so)."""

    servo_id: int
    command: int
    data: bytes


@dataclass(frozen=True, slots=True)
class Ack:
    """A servo's reply, decoded: the command answered, its data and the two status bytes."""

    servo_id: int
    command: Command
    data: bytes  # between the checksums and the two status bytes
    status_error: StatusError
    status_detail: StatusDetail

    def read_value(self) -> tuple[int, bytes]:
        """(address, bytes) of a RAM_READ or EEP_READ reply."""
        if len(self.data) < 2 or len(self.data) != 2 + self.data[1]:
            raise HerkulexError(f"read reply with malformed data {self.data.hex(' ')}")
        return self.data[0], self.data[2:]


def checksums(size: int, servo_id: int, command: int, data: bytes) -> tuple[int, int]:
    """(CS1, CS2): the XOR of SIZE, ID, CMD and DATA with bit 0 cleared, and its complement."""
    cs1 = size ^ servo_id ^ command
    for byte in data:
        cs1 ^= byte
    cs1 &= 0xFE
    return cs1, ~cs1 & 0xFE


def _check(name: str, value: int, highest: int) -> None:
    if not 0 <= value <= highest:
        raise HerkulexError(f"{name} {value} outside 0..{highest}")


def packet(servo_id: int, command: int, data: bytes = b"") -> bytes:
    """A whole packet with its size and checksums; HerkulexError if a field does not fit."""
    _check("servo id", servo_id, BROADCAST_ID)
    _check("command", command, 0xFF)
    size = MIN_SIZE + len(data)
    if size > MAX_SIZE:
        raise HerkulexError(f"packet of {size} bytes exceeds the {MAX_SIZE}-byte maximum")
    cs1, cs2 = checksums(size, servo_id, command, data)
    return HEADER + bytes((size, servo_id, command, cs1, cs2)) + data


def _read(command: Command, servo_id: int, address: int, length: int) -> bytes:
    _check("address", address, 0xFF)
    _check("length", length, 0xFF)
    return packet(servo_id, command, bytes((address, length)))


def _write(command: Command, servo_id: int, address: int, data: bytes) -> bytes:
    _check("address", address, 0xFF)
    _check("data length", len(data), MAX_SIZE - MIN_SIZE - 2)
    return packet(servo_id, command, bytes((address, len(data))) + data)


def ram_read(servo_id: int, address: int, length: int) -> bytes:
    """RAM_READ `length` bytes from `address` of the volatile registers."""
    return _read(Command.RAM_READ, servo_id, address, length)


def ram_write(servo_id: int, address: int, data: bytes) -> bytes:
    """RAM_WRITE `data` at `address` of the volatile registers (unanswered by default)."""
    return _write(Command.RAM_WRITE, servo_id, address, data)


def eep_read(servo_id: int, address: int, length: int) -> bytes:
    """EEP_READ `length` bytes from `address` of the non-volatile registers."""
    return _read(Command.EEP_READ, servo_id, address, length)


def eep_write(servo_id: int, address: int, data: bytes) -> bytes:
    """EEP_WRITE `data` at `address` of the non-volatile registers.

    Sent only by bring-up commands the engineer runs on purpose (set-id, set-voltage --eep).
    """
    return _write(Command.EEP_WRITE, servo_id, address, data)


def stat(servo_id: int) -> bytes:
    """STAT: the reply is only the two status bytes."""
    return packet(servo_id, Command.STAT)


def reboot(servo_id: int) -> bytes:
    """REBOOT the servo."""
    return packet(servo_id, Command.REBOOT)


def rollback(servo_id: int, keep_id: bool = True, keep_baud: bool = True) -> bytes:
    """ROLLBACK to factory settings (keeping id and baud by default): never sent by the HAL."""
    return packet(servo_id, Command.ROLLBACK, bytes((int(keep_id), int(keep_baud))))


def _jog(position: int, flags: int) -> bytes:
    _check("position", position, 0x7FFF)
    _check("set", flags, 0xFF)
    return bytes((position & 0xFF, position >> 8, flags))


def s_jog(playtime: int, moves: Sequence[tuple[int, int, int]]) -> bytes:
    """S_JOG: every (id, position, set) move shares one play time (units of 11.2 ms)."""
    _check("play time", playtime, 0xFF)
    data = bytearray((playtime,))
    for servo_id, position, flags in moves:
        _check("servo id", servo_id, MAX_ID)
        data += _jog(position, flags) + bytes((servo_id,))
    return packet(BROADCAST_ID, Command.S_JOG, bytes(data))


def i_jog(moves: Sequence[tuple[int, int, int, int]]) -> bytes:
    """I_JOG: each (id, position, set, play time) move has its own play time."""
    data = bytearray()
    for servo_id, position, flags, playtime in moves:
        _check("servo id", servo_id, MAX_ID)
        _check("play time", playtime, 0xFF)
        data += _jog(position, flags) + bytes((servo_id, playtime))
    return packet(BROADCAST_ID, Command.I_JOG, bytes(data))


def ack(servo_id: int, command: int, data: bytes, status_error: int, status_detail: int) -> bytes:
    """A reply as a servo sends it (for emulators and round-trip tests)."""
    _check("status error", status_error, 0xFF)
    _check("status detail", status_detail, 0xFF)
    return packet(servo_id, command | ACK_FLAG, data + bytes((status_error, status_detail)))


def packet_length(head: bytes) -> int:
    """Total length of the packet whose first HEAD_SIZE bytes are `head`; HerkulexError if bad."""
    if len(head) < HEAD_SIZE or head[:2] != HEADER:
        raise HerkulexError(f"not a HerkuleX header: {head[:HEAD_SIZE].hex(' ')}")
    if not MIN_SIZE <= head[2] <= MAX_SIZE:
        raise HerkulexError(f"packet size {head[2]} outside {MIN_SIZE}..{MAX_SIZE}")
    return head[2]


def decode_packet(raw: bytes) -> Packet:
    """Any packet, its size and checksums verified; HerkulexError otherwise."""
    size = packet_length(raw)
    if len(raw) != size:
        raise HerkulexError(f"packet of {len(raw)} bytes, its size byte says {size}")
    servo_id, command, cs1, cs2 = raw[3], raw[4], raw[5], raw[6]
    data = raw[7:]
    if (cs1, cs2) != checksums(size, servo_id, command, data):
        raise HerkulexError(f"bad checksums in {raw.hex(' ')}")
    if servo_id > BROADCAST_ID:
        raise HerkulexError(f"servo id {servo_id} is not valid")
    return Packet(servo_id, command, data)


def decode_ack(raw: bytes) -> Ack:
    """A reply to a known command; HerkulexError for a request, an unknown command or no status."""
    decoded = decode_packet(raw)
    if not decoded.command & ACK_FLAG:
        raise HerkulexError(f"command {decoded.command:#04x} is not a reply")
    try:
        command = Command(decoded.command & ~ACK_FLAG)
    except ValueError:
        raise HerkulexError(f"reply to unknown command {decoded.command:#04x}") from None
    if len(decoded.data) < 2 or decoded.servo_id > MAX_ID:
        raise HerkulexError(f"reply without status bytes or from id {decoded.servo_id}")
    return Ack(
        decoded.servo_id,
        command,
        decoded.data[:-2],
        StatusError(decoded.data[-2] & 0x7F),
        StatusDetail(decoded.data[-1] & 0x7F),
    )


def u16(data: bytes, offset: int = 0) -> int:
    """The little-endian unsigned 16-bit value at `offset`."""
    return data[offset] | data[offset + 1] << 8


def le16(value: int) -> bytes:
    """Two little-endian bytes; HerkulexError outside 0..65535."""
    _check("value", value, 0xFFFF)
    return bytes((value & 0xFF, value >> 8))


def position(value: bytes) -> int:
    """A position register (calibrated or absolute) as the servo means it: its low 10 bits.

    A real DRS-0101 sets flag bits in the high byte (0x60 in a public capture);
    Dongbu's libraries mask them off the same way. HerkulexError for a value
    that is not two bytes.
    """
    if len(value) != 2:
        raise HerkulexError(f"position of {len(value)} bytes, expected 2")
    return u16(value) & POSITION_BITS


def model_number(value: bytes) -> int:
    """EEP 0-1 (Model No1, Model No2) as one little-endian number: 0x0101 is a DRS-0101."""
    if len(value) != 2:
        raise HerkulexError(f"model number of {len(value)} bytes, expected 2")
    return u16(value)


def voltage_v(raw: int) -> float:
    """Volts of a voltage register (RAM 54, 6, 7; EEP 12, 13): 0.074 V per unit."""
    return raw * VOLTS_PER_UNIT


def raw_voltage(volts: float) -> int:
    """The voltage register's count nearest `volts`; HerkulexError beyond what a byte holds."""
    raw = round(volts / VOLTS_PER_UNIT)
    if not 0 <= raw <= 0xFF:
        raise HerkulexError(
            f"{volts} V does not fit a voltage register (0 to {0xFF * VOLTS_PER_UNIT:.2f} V)"
        )
    return raw


def voltage_limits_write(servo_id: int, low_v: float, high_v: float, eep: bool = False) -> bytes:
    """Min and Max Voltage (RAM 6-7, or EEP 12-13) in one write."""
    data = bytes((raw_voltage(low_v), raw_voltage(high_v)))
    if eep:
        return eep_write(servo_id, Eep.MIN_VOLTAGE, data)
    return ram_write(servo_id, Ram.MIN_VOLTAGE, data)


def temperature_c(raw: int) -> float:
    """Degrees Celsius of a raw temperature (RAM 55, RAM 5 or EEP 11), from the manual's table.

    HerkulexError for 0xFF (beyond the table: no servo reads it) or any value not a byte.
    """
    if not 0 <= raw <= LAST_TEMPERATURE_RAW:
        raise HerkulexError(
            f"raw temperature {raw:#04x} is not a reading: the manual's table covers "
            f"0x00 to {LAST_TEMPERATURE_RAW:#04x}"
        )
    return TEMPERATURE_CENTI_C[raw] / 100


def raw_temperature(celsius: float) -> int:
    """The raw reading nearest to `celsius` (for emulators and thresholds), within the table."""
    centi = celsius * 100
    above = bisect.bisect_left(TEMPERATURE_CENTI_C, centi)
    if above == 0:
        return 0
    if above > LAST_TEMPERATURE_RAW:
        return LAST_TEMPERATURE_RAW
    below = above - 1
    nearer_below = centi - TEMPERATURE_CENTI_C[below] <= TEMPERATURE_CENTI_C[above] - centi
    return below if nearer_below else above
