"""HerkuleX DRS-0101/0201 servos on a pty, as strict as the real ones.

What a real servo does and a kind emulator would not (HerkuleX manual v1.1,
register maps and section 5; a public capture for the position flags):
- ACK policy (RAM 1): 0 answers STAT only, 1 reads and STAT, 2 everything;
  a broadcast is never answered, except STAT (every servo at once: a collision);
- the high byte of a position reply carries flag bits (0x60 as captured);
- EEP reads cover the documented map (0-53) and RAM reads 0-73; beyond, the
  servo latches INVALID_PACKET with EXCEED_REG_RANGE;
- a request with bad checksums latches INVALID_PACKET with CHECKSUM_ERROR;
- status error bits latch until written back to zero (RAM 48), and those in
  the torque policy (RAM 3, 0x35) release the torque, which cannot be turned
  on again while they are set;
- S_JOG/I_JOG reach the goal in the play time (no faster than the servo's
  maximum speed), the STOP bit halts the servo where it is, and the status
  detail says MOVING, INPOSITION and MOTOR_ON;
- temperature rises while the servo holds a load or moves and falls back
  when it rests; at its limit (RAM 5) it latches EXCEED_TEMPERATURE;
- each servo starts at its own position, voltage and temperature; with `supply_v`
  (a battery) every servo reads that voltage, and one outside its RAM Min/Max
  Voltage (6, 7; copied from EEP 12, 13 at power-up: 0x5B-0x89, 6.7-10.1 V) latches
  EXCEED_INPUT_VOLTAGE, at power-up too, which its torque policy acts on;
- a temperature reading is a raw thermistor value (hx.TEMPERATURE_CENTI_C); a test
  may pin a raw byte, 0xFF included, which no real servo sends;
- EEP_WRITE of the id (EEP 6) takes effect at the next REBOOT, as the manual says.

Tests can also move a limp joint "by hand": push() once, or hand() for a
movement that follows the emulator's clock.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path

from emulators.base import Axis, Emulator, split_with
from hal.servos import herkulex as hx

# What the capture shows above the 10 position bits of a DRS-0101's reply.
CAPTURED_POSITION_FLAGS = 0x60
MAX_SPEED_UNITS = 1100.0  # ~360 deg/s, the DRS-0101's no-load speed
AMBIENT_C = 24.0
INPOSITION_MARGIN = 3  # RAM 44 default, raw units

# Defaults of the non-volatile map (manual, register map page): addresses 0-53.
_EEP_DEFAULTS: dict[int, int] = {
    hx.Eep.MODEL_NO_2: 0x01, hx.Eep.VERSION_1: 0x00, hx.Eep.VERSION_2: 0x90,
    hx.Eep.BAUD_RATE: 0x10, hx.Eep.ACK_POLICY: hx.AckPolicy.READS_ONLY,
    hx.Eep.ALARM_LED_POLICY: 0x7F, hx.Eep.TORQUE_POLICY: hx.DEFAULT_TORQUE_POLICY,
    # Max Temperature: 0xDE in the manual's default column (its text says 0xDF).
    hx.Eep.MAX_TEMPERATURE: 0xDE, hx.Eep.MIN_VOLTAGE: 0x5B, hx.Eep.MAX_VOLTAGE: 0x89,
}
FACTORY_ID = 0xFD  # a new servo's id (manual: 253)
MODEL_NO_1 = {"drs-0101": 0x01, "drs-0201": 0x02}


def default_position(servo_id: int) -> int:
    """Where a servo starts unless told: near the centre, and different for every id."""
    return 512 + (servo_id if servo_id % 2 == 0 else -servo_id)


class Servo:
    """One emulated servo: its EEP and RAM maps, its shaft, its temperature."""

    def __init__(self, servo_id: int, model: str, position: int, rate: float) -> None:
        self.eep = bytearray(hx.EEP_SIZE)
        for address, value in _EEP_DEFAULTS.items():
            self.eep[address] = value
        self.eep[hx.Eep.MODEL_NO_1] = MODEL_NO_1[model]
        self.eep[hx.Eep.ID] = servo_id
        self.eep[hx.Eep.MIN_POSITION : hx.Eep.MIN_POSITION + 2] = hx.le16(21)
        self.eep[hx.Eep.MAX_POSITION : hx.Eep.MAX_POSITION + 2] = hx.le16(1002)
        self.ram = bytearray(hx.Ram.RAM_SIZE)
        # At power-up the EEP registers from ID on are copied to RAM 0 onwards.
        self.ram[0:48] = self.eep[hx.Eep.ID : hx.Eep.ID + 48]
        self.ram[hx.Ram.VOLTAGE] = 100 + servo_id % 5  # about 7.4 V, a little different each
        self.axis = Axis(float(position), float(position), rate)
        self.temperature_c = AMBIENT_C + servo_id % 4
        self.load = 0.0  # fraction of stall torque the servo holds (a test sets it)
        self.hand: Callable[[float], float] | None = None
        self.heat_stamp: float | None = None  # emulator clock time of the last heat update
        self.latched = 0  # status error bits, until written back to zero
        self.detail = 0  # latched invalid-packet detail bits
        self.supply_v: float | None = None  # the battery's voltage, if the test gave one
        self.pinned_temperature: int | None = None  # a raw byte a test put in RAM 55

    @property
    def policy(self) -> int:
        return self.ram[hx.Ram.ACK_POLICY]

    @property
    def torque_policy(self) -> int:
        return self.ram[hx.Ram.TORQUE_POLICY]

    @property
    def torque_on(self) -> bool:
        return self.ram[hx.Ram.TORQUE_CONTROL] == hx.TorqueControl.ON


class HerkulexEmulator(Emulator):
    """A bus of DRS servos; `servos[id]` holds each one's maps and state."""

    def __init__(
        self, path: Path, ids: list[int], rate: float = MAX_SPEED_UNITS,
        clock: Callable[[], float] = time.monotonic,
        positions: Mapping[int, int] | None = None,
        ack_policy: int | Mapping[int, int] = hx.AckPolicy.READS_ONLY,
        models: Mapping[int, str] | None = None,
        position_flags: int = CAPTURED_POSITION_FLAGS,
        heat_c_per_s: float = 2.0,
        cool_c_per_s: float = 0.2,
        supply_v: float | None = None,
    ) -> None:
        self.servos: dict[int, Servo] = {}
        for servo_id in ids:
            position = (positions or {}).get(servo_id, default_position(servo_id))
            servo = Servo(servo_id, (models or {}).get(servo_id, "drs-0101"), position, rate)
            policy = ack_policy if isinstance(ack_policy, int) else ack_policy.get(servo_id, 1)
            servo.eep[hx.Eep.ACK_POLICY] = servo.ram[hx.Ram.ACK_POLICY] = policy
            servo.supply_v = supply_v
            self._power_up(servo)
            self.servos[servo_id] = servo
        self.position_flags = position_flags
        self.heat_c_per_s = heat_c_per_s
        self.cool_c_per_s = cool_c_per_s
        super().__init__(path, clock)

    # The attributes older tests and the soak read.
    @property
    def ram(self) -> dict[int, bytearray]:
        return {i: s.ram for i, s in self.servos.items()}

    @property
    def axes(self) -> dict[int, Axis]:
        return {i: s.axis for i, s in self.servos.items()}

    def split(self, buffer: bytes) -> tuple[bytes | None, bytes]:
        return split_with(hx.HEAD_SIZE, hx.HEADER, hx.packet_length, buffer)

    def corrupt(self, reply: bytes) -> bytes:
        return reply[:5] + bytes((reply[5] ^ 0x02,)) + reply[6:]

    # --- what a test does to the servos ---------------------------------------------------

    def set_present(self, servo_id: int, raw: int) -> None:
        """Put the shaft at `raw` (a robot powered on where its joints hang)."""
        with self._lock:
            self.servos[servo_id].axis.present = float(raw)
            self.servos[servo_id].axis.goal = float(raw)

    def push(self, servo_id: int, raw: float) -> bool:
        """A hand moves the horn; only a limp servo gives way (False if its torque is on)."""
        with self._lock:
            servo = self.servos[servo_id]
            if servo.torque_on:
                return False
            servo.axis.present = float(raw)
            return True

    def hand(self, servo_id: int, path: Callable[[float], float] | None) -> None:
        """From now on a limp servo's shaft follows `path(now)` (emulator clock); None lets go."""
        with self._lock:
            self.servos[servo_id].hand = path

    def set_load(self, servo_id: int, load: float) -> None:
        """The fraction of its stall torque the servo holds while torque is on (heats it)."""
        with self._lock:
            self.servos[servo_id].load = load

    def set_temperature(self, servo_id: int, celsius: float) -> None:
        with self._lock:
            self.servos[servo_id].temperature_c = celsius

    def pin_raw_temperature(self, servo_id: int, raw: int | None) -> None:
        """RAM 55 reads `raw` from now on (None: the servo's own temperature again)."""
        with self._lock:
            self.servos[servo_id].pinned_temperature = raw

    def set_supply(self, volts: float) -> None:
        """The battery every servo is on now reads `volts`."""
        with self._lock:
            for servo in self.servos.values():
                servo.supply_v = volts

    def latch(self, servo_id: int, bits: int) -> None:
        """The servo detects `bits` now: latched, and the torque policy applied."""
        with self._lock:
            self._latch(self.servos[servo_id], bits)

    def torque_on(self, servo_id: int) -> bool:
        with self._lock:
            return self.servos[servo_id].torque_on

    def position(self, servo_id: int) -> float:
        """Where the shaft is now (raw units)."""
        with self._lock:
            self._refresh(servo_id)
            return self.servos[servo_id].axis.present

    # --- the servo's own behaviour --------------------------------------------------------

    def _latch(self, servo: Servo, bits: int) -> None:
        servo.latched |= bits
        if servo.latched & servo.torque_policy:
            servo.ram[hx.Ram.TORQUE_CONTROL] = hx.TorqueControl.FREE

    def _heat(self, servo: Servo, now: float) -> None:
        elapsed = 0.0 if servo.heat_stamp is None else now - servo.heat_stamp
        servo.heat_stamp = now
        if servo.torque_on:
            moving = abs(servo.axis.goal - servo.axis.present) > INPOSITION_MARGIN
            # Moving without a load warms a servo only a little; holding a load, much more.
            servo.temperature_c += elapsed * self.heat_c_per_s * (servo.load + 0.05 * moving)
        servo.temperature_c = max(
            AMBIENT_C, servo.temperature_c - elapsed * self.cool_c_per_s * (not servo.load)
        )
        raw = hx.raw_temperature(servo.temperature_c)
        # A pinned byte is what the reply says, not what the servo's protection sees.
        servo.ram[hx.Ram.TEMPERATURE] = (
            raw if servo.pinned_temperature is None else servo.pinned_temperature
        )
        if raw >= servo.ram[hx.Ram.MAX_TEMPERATURE]:
            self._latch(servo, hx.StatusError.EXCEED_TEMPERATURE)

    def _power_up(self, servo: Servo) -> None:
        """What a servo checks as it powers up: its supply, against the limits it just copied."""
        self._check_supply(servo)

    def _check_supply(self, servo: Servo) -> None:
        if servo.supply_v is None:
            return
        raw = min(0xFF, round(servo.supply_v / hx.VOLTS_PER_UNIT))
        servo.ram[hx.Ram.VOLTAGE] = raw
        if not servo.ram[hx.Ram.MIN_VOLTAGE] <= raw <= servo.ram[hx.Ram.MAX_VOLTAGE]:
            self._latch(servo, hx.StatusError.EXCEED_INPUT_VOLTAGE)

    def _refresh(self, servo_id: int) -> None:
        now = self.clock()
        servo = self.servos[servo_id]
        self._heat(servo, now)
        self._check_supply(servo)
        injected = self.faults.error_bits.get(servo_id, 0)
        if injected & ~servo.latched:
            self._latch(servo, injected)
        axis = servo.axis
        axis.torque = servo.torque_on
        if not axis.torque and servo.hand is not None:
            axis.present = float(servo.hand(now))
        axis.update(now)
        present = round(axis.present)
        low = hx.u16(servo.ram, hx.Ram.MIN_POSITION)
        high = hx.u16(servo.ram, hx.Ram.MAX_POSITION)
        if not low <= present <= high:
            servo.latched |= hx.StatusError.EXCEED_POT_LIMIT
        flagged = hx.le16((present & hx.POSITION_BITS) | self.position_flags << 8)
        servo.ram[hx.Ram.CALIBRATED_POSITION : hx.Ram.CALIBRATED_POSITION + 2] = flagged
        servo.ram[hx.Ram.ABSOLUTE_POSITION : hx.Ram.ABSOLUTE_POSITION + 2] = flagged
        servo.ram[hx.Ram.STATUS_ERROR] = servo.latched
        detail = servo.detail
        if axis.torque:
            detail |= hx.StatusDetail.MOTOR_ON
            if abs(axis.goal - axis.present) > 0.5:
                detail |= hx.StatusDetail.MOVING
            if abs(axis.goal - axis.present) <= INPOSITION_MARGIN:
                detail |= hx.StatusDetail.INPOSITION
        servo.ram[hx.Ram.STATUS_DETAIL] = detail

    def _ack(self, servo_id: int, command: int, data: bytes = b"") -> tuple[int, bytes]:
        self._refresh(servo_id)
        ram = self.servos[servo_id].ram
        reply_id = self.faults.wrong_id.get(servo_id, servo_id)
        return servo_id, hx.ack(
            reply_id, command, data, ram[hx.Ram.STATUS_ERROR], ram[hx.Ram.STATUS_DETAIL]
        )

    def _invalid(self, servo_id: int, detail: int) -> None:
        servo = self.servos[servo_id]
        servo.detail |= detail
        self._latch(servo, hx.StatusError.INVALID_PACKET)

    def handle(self, packet: bytes) -> list[tuple[int, bytes]]:
        try:
            request = hx.decode_packet(packet)
        except hx.HerkulexError:
            addressed = packet[3] if len(packet) > 3 else None
            if addressed in self.servos:
                self._invalid(addressed, hx.StatusDetail.CHECKSUM_ERROR)
            return []
        if request.command in (hx.Command.S_JOG, hx.Command.I_JOG):
            self._jog(request.command, request.data)
            return []
        broadcast = request.servo_id == hx.BROADCAST_ID
        targets = list(self.servos) if broadcast else [request.servo_id]
        replies = []
        for servo_id in targets:
            if servo_id not in self.servos:
                continue
            reply = self._request(servo_id, request.command, request.data)
            if reply is None:
                continue
            answered = request.command == hx.Command.STAT or (
                not broadcast and self._answers(self.servos[servo_id], request.command)
            )
            if answered:
                replies.append(reply)
        return replies

    @staticmethod
    def _answers(servo: Servo, command: int) -> bool:
        if servo.policy >= hx.AckPolicy.ALWAYS:
            return True
        reads = (hx.Command.RAM_READ, hx.Command.EEP_READ)
        return servo.policy == hx.AckPolicy.READS_ONLY and command in reads

    def _request(self, servo_id: int, command: int, data: bytes) -> tuple[int, bytes] | None:
        servo = self.servos[servo_id]
        if command in (hx.Command.RAM_READ, hx.Command.EEP_READ):
            memory = servo.ram if command == hx.Command.RAM_READ else servo.eep
            address, length = data[0], data[1]
            if command == hx.Command.RAM_READ:
                self._refresh(servo_id)
            if address + length > len(memory):
                self._invalid(servo_id, hx.StatusDetail.EXCEED_REG_RANGE)
                return self._ack(servo_id, command, bytes((address, 0)))
            value = bytes(memory[address : address + length])
            return self._ack(servo_id, command, bytes((address, length)) + value)
        if command == hx.Command.RAM_WRITE:
            self._ram_write(servo_id, data[0], data[2 : 2 + data[1]])
            return self._ack(servo_id, command)
        if command == hx.Command.EEP_WRITE:
            address, value = data[0], data[2 : 2 + data[1]]
            servo.eep[address : address + len(value)] = value
            return self._ack(servo_id, command)
        if command in (hx.Command.STAT, hx.Command.ROLLBACK):
            return self._ack(servo_id, command)
        if command == hx.Command.REBOOT:
            new_id = servo.eep[hx.Eep.ID]
            fresh = Servo(new_id, "drs-0101", round(servo.axis.present), servo.axis.rate)
            fresh.eep[:] = servo.eep
            fresh.ram[0:48] = servo.eep[hx.Eep.ID : hx.Eep.ID + 48]
            fresh.temperature_c, fresh.heat_stamp = servo.temperature_c, servo.heat_stamp
            fresh.supply_v = servo.supply_v
            self._power_up(fresh)
            del self.servos[servo_id]
            self.servos[new_id] = fresh  # the id written to EEP 6 counts from now
            self.faults.error_bits.pop(servo_id, None)
            return None
        self._invalid(servo_id, hx.StatusDetail.UNKNOWN_COMMAND)
        return self._ack(servo_id, command)

    def _ram_write(self, servo_id: int, address: int, value: bytes) -> None:
        servo = self.servos[servo_id]
        self._refresh(servo_id)
        if address + len(value) > hx.Ram.RAM_SIZE:
            self._invalid(servo_id, hx.StatusDetail.EXCEED_REG_RANGE)
            return
        for offset, byte in enumerate(value):
            where = address + offset
            if where == hx.Ram.STATUS_ERROR:
                servo.latched = byte & servo.latched  # only zeros are taken
                if not byte:
                    self.faults.error_bits.pop(servo_id, None)  # the error is acknowledged
            elif where == hx.Ram.STATUS_DETAIL:
                servo.detail = byte & servo.detail
            elif where == hx.Ram.TORQUE_CONTROL:
                if byte == hx.TorqueControl.ON and servo.latched & servo.torque_policy:
                    continue  # under a policy error, torque stays off whatever is written
                if byte == hx.TorqueControl.ON and not servo.torque_on:
                    servo.axis.goal = servo.axis.present  # from free: hold where it is
                servo.ram[where] = byte
            else:
                servo.ram[where] = byte
        self._refresh(servo_id)

    def _jog(self, command: int, data: bytes) -> None:
        if command == hx.Command.S_JOG:
            entries = [(data[i : i + 4], data[0]) for i in range(1, len(data) - 3, 4)]
        else:
            entries = [(data[i : i + 4], data[i + 4]) for i in range(0, len(data) - 4, 5)]
        for entry, playtime in entries:
            servo_id = entry[3]
            servo = self.servos.get(servo_id)
            if servo is None:
                continue
            self._refresh(servo_id)
            flags = entry[2]
            if flags & hx.JogSet.INVALID:
                continue
            axis = servo.axis
            if flags & hx.JogSet.STOP:
                axis.goal = axis.present  # stop where it is
                continue
            goal = hx.u16(entry) & 0x7FFF
            servo.ram[hx.Ram.ABSOLUTE_GOAL_POSITION : hx.Ram.ABSOLUTE_GOAL_POSITION + 2] = entry[:2]
            seconds = max(1, playtime) * hx.PLAYTIME_SECONDS
            # The goal is reached in the play time, never faster than the servo can turn.
            axis.speed = min(axis.rate, abs(goal - axis.present) / seconds)
            axis.goal = float(goal)
