"""Bus drivers: the generic servo operations in each protocol's fewest packets.

Each driver owns a SerialBus and turns ServoDriver calls into codec packets:
positions by SYNC_READ where the protocol has it (Dynamixel 2.0), in one
write of every request on a Maestro, one READ per servo otherwise; goals in
one SYNC_WRITE, S_JOG or multiple-target packet per control step.
"""

from __future__ import annotations

import abc
import contextlib
import enum
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import structlog

from hal.errors import BusTimeout, CodecError, PortUnavailable, ServoSilent
from hal.servos import dynamixel1 as dx1
from hal.servos import dynamixel2 as dx2
from hal.servos import herkulex as hx
from hal.servos import maestro as mo
from hal.servos.api import FaultKind, Health, ServoLimits
from hal.servos.bus import Exchange, Framing, SerialBus
from hal.servos.settings import BusSettings

AX12_SPEED_DPS_PER_UNIT = 0.111 * 6  # moving speed unit: 0.111 rpm

log = structlog.get_logger("hal.servos.drivers")

# A scan's second look at the ids whose replies came late: this many times the margin.
LATE_MARGIN_FACTOR = 5

T = TypeVar("T")


def _flags(value: int, flag_type: type[enum.IntFlag]) -> tuple[str, ...]:
    return tuple(str(flag.name) for flag in flag_type if value & flag)


class BusDriver(abc.ABC):
    """A ServoDriver over one SerialBus; a subclass per protocol family says the packets.

    Every call runs on the event loop and awaits the bus thread. A servo that
    does not answer, or whose every reply is corrupt, raises ServoSilent naming
    it; a lost adapter raises PortUnavailable.
    """

    framing: Framing  # how the protocol's replies are cut out of the byte stream
    id_range: tuple[int, int]  # the ids (channels) a servo can have, as the codec states them

    def __init__(self, bus: SerialBus) -> None:
        """Drive the servos on `bus`; the bus is started and closed with the driver."""
        self.bus = bus

    async def _each(self, ids: Sequence[int], exchanges: list[Exchange]) -> list[Any]:
        """Run one exchange per servo; the first that failed is named as silent."""
        return self._named(ids, await self.bus.exchange_all(exchanges))

    def _named(self, ids: Sequence[int], outcomes: list[Any]) -> list[Any]:
        """The outcomes, if all succeeded; else the first failure, naming its servo."""
        for servo_id, outcome in zip(ids, outcomes, strict=True):
            if isinstance(outcome, PortUnavailable):
                raise outcome
            if isinstance(outcome, (BusTimeout, CodecError)):
                message = f"servo {servo_id} on bus {self.bus.name}: no valid reply ({outcome})"
                raise ServoSilent(servo_id, message)
            if isinstance(outcome, Exception):
                raise outcome
        return outcomes

    async def start(self) -> None:
        """Start the bus thread; returns within a second even while the port is away."""
        await self.bus.start()

    async def close(self) -> None:
        """Stop the bus thread and release the port."""
        await self.bus.close()

    def retried(self) -> int:
        """Replies this bus has retried so far (corrupt or late, then good)."""
        return self.bus.stats.retries

    @abc.abstractmethod
    async def ping(self, servo_id: int) -> int | None:
        """The model number of a servo that answers (0 if the protocol has none); None if silent."""

    async def answers(self, servo_id: int) -> bool:
        """Whether a servo answers at all, in the protocol's shortest exchange (a scan's)."""
        return await self.ping(servo_id) is not None

    async def answering(self, ids: Sequence[int]) -> list[int]:
        """Those of `ids` that answer, asked one after another (a scan)."""
        return [servo_id for servo_id in ids if await self.answers(servo_id)]

    @abc.abstractmethod
    async def read_positions(self, ids: Sequence[int]) -> dict[int, int]:
        """Present raw positions; ServoSilent names the first servo that did not answer."""

    @abc.abstractmethod
    async def write_goals(self, goals: Mapping[int, tuple[int, float]], step: float) -> None:
        """Raw goal and speed limit (deg/s) per servo, reached within `step` seconds."""

    @abc.abstractmethod
    async def set_torque(self, ids: Sequence[int], on: bool) -> None:
        """Torque on or off for every servo in `ids`, in as few packets as the protocol allows."""

    @abc.abstractmethod
    async def read_health(self, servo_id: int) -> Health:
        """One servo's condition; `kind` set when its error bits mean a fault."""

    @abc.abstractmethod
    async def reset_errors(self, ids: Sequence[int]) -> None:
        """Clear the servos' own latched error state, where the protocol latches one."""

    async def _ask(
        self, servo_id: int, request: bytes, decode: Callable[[list[bytes]], T], expect: int
    ) -> T:
        try:
            return await self.bus.transact(request, 1, self.framing, decode, expect)
        except (BusTimeout, CodecError) as error:
            # A servo whose every reply is corrupt is as unusable as a silent one.
            message = f"servo {servo_id} on bus {self.bus.name}: no valid reply ({error})"
            raise ServoSilent(servo_id, message) from None


class Dynamixel1Driver(BusDriver):
    """AX-12A servos on Dynamixel Protocol 1.0."""

    framing = Framing(dx1.HEAD_SIZE, dx1.packet_length)
    id_range = dx1.ID_RANGE

    def _status(self, servo_id: int, length: int) -> Callable[[list[bytes]], dx1.Status]:
        def decode(packets: list[bytes]) -> dx1.Status:
            status = dx1.decode_status(packets[0])
            if status.servo_id != servo_id or len(status.params) != length:
                raise dx1.DynamixelError(
                    f"reply from id {status.servo_id} with {len(status.params)} bytes, "
                    f"expected id {servo_id} with {length}"
                )
            return status

        return decode

    async def _read(self, servo_id: int, address: int, length: int) -> dx1.Status:
        request = dx1.read(servo_id, address, length)
        return await self._ask(servo_id, request, self._status(servo_id, length), 6 + length)

    async def ping(self, servo_id: int) -> int | None:
        """PING, then READ of the model number; None when the PING goes unanswered.

        0 for a servo that answers its PING but not the read: at status return level
        0 (EEPROM 16) an AX-12A answers nothing else, so every read would time out.
        """
        try:
            await self._ask(servo_id, dx1.ping(servo_id), self._status(servo_id, 0), 6)
        except ServoSilent:
            return None
        try:
            status = await self._read(servo_id, dx1.AX12.MODEL_NUMBER, 2)
        except ServoSilent:
            return 0
        return dx1.u16(status.params)

    async def read_positions(self, ids: Sequence[int]) -> dict[int, int]:
        """One READ per servo (the AX-12A has no SYNC_READ), all in one hand-off."""
        # The AX-12A has neither SYNC_READ nor BULK_READ: one READ per servo, all
        # handed to the bus thread at once.
        exchanges = [
            Exchange(dx1.read(i, dx1.AX12.PRESENT_POSITION, 2), 1, self.framing,
                     self._status(i, 2), 8)
            for i in ids
        ]
        outcomes = await self._each(ids, exchanges)
        return {i: dx1.u16(status.params) for i, status in zip(ids, outcomes, strict=True)}

    async def write_goals(self, goals: Mapping[int, tuple[int, float]], step: float) -> None:
        """One SYNC_WRITE of goal and moving speed; speed never 0, which means "no limit"."""
        data = {}
        for servo_id, (raw, speed_dps) in goals.items():
            # Moving speed 0 means "as fast as possible": never send it.
            speed = min(1023, max(1, math.ceil(speed_dps / AX12_SPEED_DPS_PER_UNIT)))
            data[servo_id] = dx1.le16(raw) + dx1.le16(speed)
        await self.bus.transact(dx1.sync_write(dx1.AX12.GOAL_POSITION, 4, data))

    async def set_torque(self, ids: Sequence[int], on: bool) -> None:
        """One SYNC_WRITE of TORQUE_ENABLE."""
        data = {servo_id: bytes((int(on),)) for servo_id in ids}
        await self.bus.transact(dx1.sync_write(dx1.AX12.TORQUE_ENABLE, 1, data))

    async def reset_errors(self, ids: Sequence[int]) -> None:
        """Nothing to send: AX-12A error bits clear when their condition ends."""
        return None  # AX-12A error bits clear themselves once the condition has gone

    async def read_health(self, servo_id: int) -> Health:
        """One READ of position, speed, load, voltage, temperature; fault from the error byte."""
        status = await self._read(servo_id, dx1.AX12.PRESENT_POSITION, 8)
        params, error = status.params, status.error
        load_raw = dx1.u16(params, 4)
        load = (load_raw & 0x3FF) / 1023 * (-1 if load_raw & 0x400 else 1)
        kind = None
        if error & dx1.ErrorBits.OVERHEATING:
            kind = FaultKind.OVERHEATING
        elif error & dx1.ErrorBits.OVERLOAD:
            kind = FaultKind.OVERLOAD
        elif error & dx1.ErrorBits.INPUT_VOLTAGE:
            kind = FaultKind.VOLTAGE
        return Health(
            position=dx1.u16(params, 0),
            temperature_c=float(params[7]),
            voltage_v=params[6] / 10,
            load=load,
            flags=_flags(error, dx1.ErrorBits),
            kind=kind,
        )


class Dynamixel2Driver(BusDriver):
    """X series servos (XL430) on Dynamixel Protocol 2.0."""

    framing = Framing(dx2.HEAD_SIZE, dx2.packet_length)
    id_range = dx2.ID_RANGE

    def _status(self, servo_id: int, length: int) -> Callable[[list[bytes]], dx2.Status]:
        def decode(packets: list[bytes]) -> dx2.Status:
            status = dx2.decode_status(packets[0])
            if status.servo_id != servo_id or len(status.params) != length:
                raise dx2.DynamixelError(f"reply from id {status.servo_id}, expected {servo_id}")
            return status

        return decode

    async def _read(self, servo_id: int, address: int, length: int) -> dx2.Status:
        request = dx2.read(servo_id, address, length)
        return await self._ask(servo_id, request, self._status(servo_id, length), 11 + length)

    async def ping(self, servo_id: int) -> int | None:
        """PING; the model number is in its reply."""
        try:
            status = await self._ask(servo_id, dx2.ping(servo_id), self._status(servo_id, 3), 14)
        except ServoSilent:
            return None
        return dx2.u16(status.params)

    async def read_positions(self, ids: Sequence[int]) -> dict[int, int]:
        """One SYNC_READ; if a servo is silent, a READ each to name which one."""
        ids = list(ids)

        def decode(packets: list[bytes]) -> dict[int, int]:
            positions = {}
            for servo_id, packet in zip(ids, packets, strict=True):
                status = dx2.decode_status(packet)
                if status.servo_id != servo_id or len(status.params) != 4:
                    raise dx2.DynamixelError(f"reply from {status.servo_id}, not {servo_id}")
                positions[servo_id] = dx2.s32(status.params)
            return positions

        request = dx2.sync_read(dx2.XSeries.PRESENT_POSITION, 4, ids)
        try:
            return await self.bus.transact(request, len(ids), self.framing, decode, 15 * len(ids))
        except (BusTimeout, CodecError):
            pass
        # One servo is silent and the SYNC_READ cannot say which: ask each, to name it.
        positions = {}
        for servo_id in ids:
            status = await self._read(servo_id, dx2.XSeries.PRESENT_POSITION, 4)
            positions[servo_id] = dx2.s32(status.params)
        return positions

    async def write_goals(self, goals: Mapping[int, tuple[int, float]], step: float) -> None:
        """One SYNC_WRITE of goal positions (speed is left to the profile)."""
        data = {servo_id: dx2.le32(raw) for servo_id, (raw, _speed) in goals.items()}
        await self.bus.transact(dx2.sync_write(dx2.XSeries.GOAL_POSITION, 4, data))

    async def set_torque(self, ids: Sequence[int], on: bool) -> None:
        """One SYNC_WRITE of TORQUE_ENABLE."""
        data = {servo_id: bytes((int(on),)) for servo_id in ids}
        await self.bus.transact(dx2.sync_write(dx2.XSeries.TORQUE_ENABLE, 1, data))

    async def reset_errors(self, ids: Sequence[int]) -> None:
        """REBOOT each servo: an X series keeps Hardware Error Status until then (torque off)."""
        # An X series servo keeps its Hardware Error Status until rebooted (torque stays off).
        for servo_id in ids:
            await self._ask(servo_id, dx2.reboot(servo_id), self._status(servo_id, 0), 11)

    async def read_health(self, servo_id: int) -> Health:
        """READ from load to temperature; Hardware Error Status too if the alert bit is set."""
        start = dx2.XSeries.PRESENT_LOAD
        length = dx2.XSeries.PRESENT_TEMPERATURE + 1 - start
        status = await self._read(servo_id, start, length)
        params = status.params
        hardware = 0
        if status.alert:
            reply = await self._read(servo_id, dx2.XSeries.HARDWARE_ERROR_STATUS, 1)
            hardware = reply.params[0]
        kind = None
        if hardware & dx2.HardwareError.OVERHEATING:
            kind = FaultKind.OVERHEATING
        elif hardware & dx2.HardwareError.OVERLOAD:
            kind = FaultKind.OVERLOAD
        elif hardware & dx2.HardwareError.INPUT_VOLTAGE:
            kind = FaultKind.VOLTAGE
        elif hardware:
            kind = FaultKind.HARDWARE
        load = int.from_bytes(params[0:2], "little", signed=True) / 1000
        return Health(
            position=dx2.s32(params, dx2.XSeries.PRESENT_POSITION - start),
            temperature_c=float(params[dx2.XSeries.PRESENT_TEMPERATURE - start]),
            voltage_v=dx2.u16(params, dx2.XSeries.PRESENT_INPUT_VOLTAGE - start) / 10,
            load=load,
            flags=_flags(hardware, dx2.HardwareError),
            kind=kind,
        )


def _ack_policy_packet() -> bytes:
    """Every HerkuleX servo: answer reads only (RAM register 1; the published Kaspar driver
    wrote it to 0x34, the torque register)."""
    return hx.ram_write(hx.BROADCAST_ID, hx.Ram.ACK_POLICY, bytes((hx.AckPolicy.READS_ONLY,)))


def _greeting(voltage_limits: tuple[float, float] | None) -> bytes:
    """What every servo is told each time the port opens: its ACK policy, its supply limits."""
    greeting = _ack_policy_packet()
    if voltage_limits is not None:
        greeting += hx.voltage_limits_write(hx.BROADCAST_ID, *voltage_limits)
    return greeting


def _limits(raw: bytes) -> ServoLimits:
    """Max Temperature, Min Voltage, Max Voltage (EEP 11-13 or RAM 5-7) in degrees and volts."""
    try:
        hot: float | None = hx.temperature_c(raw[0])
    except hx.HerkulexError:
        hot = None
    return ServoLimits(hot, hx.voltage_v(raw[1]), hx.voltage_v(raw[2]))


class HerkulexDriver(BusDriver):
    """HerkuleX DRS-0101/0201 servos, whatever ACK policy a previous program left them at.

    At start, and again after the adapter reconnects or a servo stops answering
    a read, every servo is told to answer reads only (RAM 1, ACK policy 1) by one
    broadcast write, which no servo answers whatever its policy; with
    `voltage_limits` (the bus's min_voltage_v, max_voltage_v) the same broadcast
    sets every servo's RAM Min/Max Voltage, so that a battery above the factory
    limits is no error (EEP is not written). Pings are STAT, which every policy
    answers. Positions keep their 10 position bits: real servos set flags in the
    high byte. Error bits that are about a packet or a position limit are written
    back to zero at once (reported as `cleared`); so is the voltage bit, once per
    servo and only while the voltage is inside the configured limits, because a
    servo latches it at power-up under its factory limits. Any other voltage bit is
    a fault, and every fault bit stays latched until reset_errors().
    """

    framing = Framing(hx.HEAD_SIZE, hx.packet_length)
    id_range = hx.ID_RANGE

    def __init__(self, bus: SerialBus, voltage_limits: tuple[float, float] | None = None) -> None:
        """Drive the HerkuleX servos on `bus`; nothing is sent before start()."""
        super().__init__(bus)
        self.voltage_limits = voltage_limits
        self._stored: dict[int, ServoLimits] = {}  # EEP 11-13, read once per servo
        # Servos whose voltage bit has been judged since their RAM limits were set: only the
        # first reading after that may carry the bit latched at power-up.
        self._judged: set[int] = set()
        # Sent by the bus's owner thread each time the port opens, before anything else:
        # a reconnect may follow a power cycle, after which each servo has its EEP policy
        # and limits back, and a read must not go first.
        bus.greeting = _greeting(voltage_limits)

    async def _send_ack_policy(self) -> None:
        await self.bus.transact(_ack_policy_packet())

    def _ack(self, servo_id: int, command: hx.Command) -> Callable[[list[bytes]], hx.Ack]:
        def decode(packets: list[bytes]) -> hx.Ack:
            reply = hx.decode_ack(packets[0])
            if reply.servo_id != servo_id or reply.command is not command:
                raise hx.HerkulexError(
                    f"reply {reply.command.name} from id {reply.servo_id}, "
                    f"expected {command.name} from {servo_id}"
                )
            return reply

        return decode

    def _value(
        self, servo_id: int, command: hx.Command, address: int, length: int
    ) -> Callable[[list[bytes]], hx.Ack]:
        check = self._ack(servo_id, command)

        def decode(packets: list[bytes]) -> hx.Ack:
            reply = check(packets)
            read_address, value = reply.read_value()
            if read_address != address or len(value) != length:
                raise hx.HerkulexError(f"servo {servo_id}: reply for the wrong register")
            return reply

        return decode

    async def _read(
        self, servo_id: int, address: int, length: int, eep: bool = False
    ) -> hx.Ack:
        """One RAM_READ (or EEP_READ); if nothing at all answers, the ACK policy once more.

        A servo left at policy 0 (or power-cycled back to it) answers no read, yet
        is there (it answers STAT); a servo that answers garbage is not helped by
        it, so a corrupt reply is never given that second chance.
        """
        command = hx.Command.EEP_READ if eep else hx.Command.RAM_READ
        build = hx.eep_read if eep else hx.ram_read
        exchange = Exchange(build(servo_id, address, length), 1, self.framing,
                            self._value(servo_id, command, address, length), 11 + length)
        (outcome,) = await self._reasserted([exchange])
        (reply,) = self._named([servo_id], [outcome])
        assert isinstance(reply, hx.Ack)
        return reply

    async def _reasserted(self, exchanges: list[Exchange]) -> list[Any]:
        """Run the exchanges; those that got no answer at all run again after the ACK policy."""
        outcomes = await self.bus.exchange_all(exchanges)
        unanswered = [k for k, outcome in enumerate(outcomes) if isinstance(outcome, BusTimeout)]
        if unanswered:
            await self._send_ack_policy()
            again = await self.bus.exchange_all([exchanges[k] for k in unanswered])
            for k, outcome in zip(unanswered, again, strict=True):
                outcomes[k] = outcome
        return outcomes

    async def answers(self, servo_id: int) -> bool:
        """STAT only: answered at every ACK policy, the shortest exchange (a scan's)."""
        try:
            await self._ask(servo_id, hx.stat(servo_id), self._ack(servo_id, hx.Command.STAT), 9)
        except ServoSilent:
            return False
        return True

    async def answering(self, ids: Sequence[int]) -> list[int]:
        """One STAT per id, all in one hand-off to the bus thread: a scan of 254 ids.

        A reply that comes after its deadline lands in the next id's exchange: that
        servo, and the one whose exchange it spoiled, are asked once more with a
        margin LATE_MARGIN_FACTOR times as long (a busy machine, a slow adapter).
        """
        heard: set[int] = set()  # ids whose reply came in another id's exchange
        spoiled: set[int] = set()  # ids whose exchange got another id's reply
        answered = await self._stats(ids, heard, spoiled)
        again = sorted((heard | spoiled) - set(answered))
        if again:
            margin = self.bus.timeout_margin
            self.bus.timeout_margin = margin * LATE_MARGIN_FACTOR
            try:
                answered += await self._stats(again, heard, spoiled)
            finally:
                self.bus.timeout_margin = margin
        return sorted(answered)

    async def _stats(self, ids: Sequence[int], heard: set[int], spoiled: set[int]) -> list[int]:
        def decode_for(servo_id: int) -> Callable[[list[bytes]], hx.Ack]:
            check = self._ack(servo_id, hx.Command.STAT)

            def decode(packets: list[bytes]) -> hx.Ack:
                try:
                    return check(packets)
                except hx.HerkulexError:
                    with contextlib.suppress(CodecError):
                        other = hx.decode_ack(packets[0]).servo_id
                        if other != servo_id:
                            heard.add(other)
                            spoiled.add(servo_id)
                    raise

            return decode

        exchanges = [Exchange(hx.stat(i), 1, self.framing, decode_for(i), 9) for i in ids]
        outcomes = await self.bus.exchange_all(exchanges)
        for outcome in outcomes:
            if isinstance(outcome, PortUnavailable):
                raise outcome
        return [i for i, outcome in zip(ids, outcomes, strict=True)
                if not isinstance(outcome, Exception)]

    async def ping(self, servo_id: int) -> int | None:
        """STAT (answered at every ACK policy), then the model number; None when silent.

        0 for a servo that answers STAT but not the model read.
        """
        if not await self.answers(servo_id):
            return None
        try:
            reply = await self._read(servo_id, hx.Eep.MODEL_NO_1, 2, eep=True)
        except ServoSilent:
            return 0
        return hx.model_number(reply.read_value()[1])

    async def read_positions(self, ids: Sequence[int]) -> dict[int, int]:
        """One RAM_READ of the calibrated position per servo, all in one hand-off."""
        address = hx.Ram.CALIBRATED_POSITION
        exchanges = [
            Exchange(hx.ram_read(i, address, 2), 1, self.framing,
                     self._value(i, hx.Command.RAM_READ, address, 2), 13)
            for i in ids
        ]
        # A servo left at ACK policy 0 (or power-cycled) answers no read: told again, once.
        outcomes = self._named(ids, await self._reasserted(exchanges))
        return {
            i: hx.position(reply.read_value()[1])
            for i, reply in zip(ids, outcomes, strict=True)
        }

    async def write_goals(self, goals: Mapping[int, tuple[int, float]], step: float) -> None:
        """One S_JOG with the play time of one control step (1 to 255 units of 11.2 ms)."""
        playtime = min(hx.MAX_PLAYTIME, max(1, round(step / hx.PLAYTIME_SECONDS)))
        moves = [(servo_id, raw, 0) for servo_id, (raw, _speed) in goals.items()]
        await self.bus.transact(hx.s_jog(playtime, moves))

    async def set_torque(self, ids: Sequence[int], on: bool) -> None:
        """RAM_WRITE of TORQUE_CONTROL per servo in one write; unanswered at ACK policy 1."""
        value = bytes((hx.TorqueControl.ON if on else hx.TorqueControl.FREE,))
        request = b"".join(hx.ram_write(i, hx.Ram.TORQUE_CONTROL, value) for i in ids)
        await self.bus.transact(request)

    async def reset_errors(self, ids: Sequence[int]) -> None:
        """RAM_WRITE of zero to STATUS_ERROR and STATUS_DETAIL (a HerkuleX latches them).

        Never blindly: a servo whose voltage bit is set while its voltage is still
        outside its limits keeps its bits (logged); the next poll names the fault again.
        """
        for servo_id in ids:
            reply = await self._read(servo_id, hx.Ram.STATUS_ERROR, hx.Ram.VOLTAGE + 1 -
                                     hx.Ram.STATUS_ERROR)
            volts = hx.voltage_v(reply.read_value()[1][-1])
            if reply.status_error & hx.StatusError.EXCEED_INPUT_VOLTAGE:
                limits = await self._active_limits(servo_id)
                if not limits.min_voltage_v <= volts <= limits.max_voltage_v:
                    log.warning("servo voltage still outside its limits: errors kept",
                                bus=self.bus.name, servo=servo_id, voltage_v=round(volts, 2),
                                limits=str(limits))
                    continue
            await self._write_zero(servo_id)

    async def _write_zero(self, servo_id: int) -> None:
        await self.bus.transact(hx.ram_write(servo_id, hx.Ram.STATUS_ERROR, bytes((0, 0))))

    async def read_health(self, servo_id: int) -> Health:
        """One RAM_READ from the status error to the position, and the servo's limits.

        Temperature is converted with the manual's table (a raw 0xFF is no servo's:
        an impossible reading, named). The servo's EEP limits (11-13) are read once,
        its RAM limits (5-7) each time: a servo whose RAM limits are not the bus's
        (it was power-cycled behind a live adapter) has them written again.
        """
        first = hx.Ram.STATUS_ERROR
        length = hx.Ram.CALIBRATED_POSITION + 2 - first
        reply = await self._read(servo_id, first, length)
        registers = reply.read_value()[1]
        error = reply.status_error
        stored = await self._stored_limits(servo_id)
        active = await self._active_limits(servo_id)
        flags = _flags(error, hx.StatusError)
        if error & hx.StatusError.INVALID_PACKET:
            why = reply.status_detail & ~(
                hx.StatusDetail.MOVING | hx.StatusDetail.INPOSITION | hx.StatusDetail.MOTOR_ON
            )
            flags += _flags(why, hx.StatusDetail)
        volts = hx.voltage_v(registers[hx.Ram.VOLTAGE - first])
        clearable = error & hx.TRANSIENT_ERRORS
        detail = ""
        if error & hx.StatusError.EXCEED_INPUT_VOLTAGE:
            if self._latched_at_power_up(servo_id, volts):
                # Expected on every servo of a battery above the factory limits: cleared and
                # logged here, not reported as an error bit of the servo's health.
                clearable |= hx.StatusError.EXCEED_INPUT_VOLTAGE
                flags = tuple(f for f in flags if f != "EXCEED_INPUT_VOLTAGE")
                log.info("power-up voltage error bit cleared", bus=self.bus.name,
                         servo=servo_id, voltage_v=round(volts, 2), limits=str(active))
            else:
                detail = self._voltage_fault(volts, active)
        self._judged.add(servo_id)
        cleared: tuple[str, ...] = ()
        if error and not error & ~clearable:
            # Only packet, limit and power-up voltage bits: safe to clear (the torque
            # policy acts on the voltage bit, so a stale one would keep the torque off).
            await self._write_zero(servo_id)
            cleared = _flags(error, hx.StatusError)
        kind = None
        faulty = error & ~clearable
        if faulty & hx.StatusError.EXCEED_TEMPERATURE:
            kind = FaultKind.OVERHEATING
        elif faulty & hx.StatusError.OVERLOAD:
            kind = FaultKind.OVERLOAD
        elif faulty & hx.StatusError.EXCEED_INPUT_VOLTAGE:
            kind = FaultKind.VOLTAGE
        elif faulty & (hx.StatusError.DRIVER_FAULT | hx.StatusError.EEP_DISTORTED):
            kind = FaultKind.HARDWARE
        raw_temperature = registers[hx.Ram.TEMPERATURE - first]
        temperature: float | None
        try:
            temperature = hx.temperature_c(raw_temperature)
        except hx.HerkulexError as impossible:
            temperature = None
            flags += (f"TEMPERATURE_READING_{raw_temperature:#04X}",)
            kind = kind or FaultKind.IMPOSSIBLE
            detail = detail or f"servo {servo_id}: {impossible}"
        return Health(
            position=hx.position(registers[-2:]),
            temperature_c=temperature,
            voltage_v=volts,
            flags=flags,
            kind=kind,
            cleared=cleared,
            temperature_limit_c=active.max_temperature_c,
            stored_limits=stored,
            active_limits=active,
            detail=detail if kind is not None else "",
        )

    def _latched_at_power_up(self, servo_id: int, volts: float) -> bool:
        """A voltage bit from before the bus's limits were set, the voltage now inside them."""
        if self.voltage_limits is None or servo_id in self._judged:
            return False
        low, high = self.voltage_limits
        return low <= volts <= high

    def _voltage_fault(self, volts: float, active: ServoLimits) -> str:
        why = (
            f"voltage {volts:.1f} V, the servo's limits {active.min_voltage_v:.1f}-"
            f"{active.max_voltage_v:.1f} V"
        )
        if self.voltage_limits is None:
            why += (f" (bus {self.bus.name} sets none: min_voltage_v and max_voltage_v put "
                    "the battery's range in the servos' RAM)")
        return why

    async def _stored_limits(self, servo_id: int) -> ServoLimits:
        limits = self._stored.get(servo_id)
        if limits is None:
            reply = await self._read(servo_id, hx.Eep.MAX_TEMPERATURE, 3, eep=True)
            limits = self._stored[servo_id] = _limits(reply.read_value()[1])
        return limits

    async def _active_limits(self, servo_id: int) -> ServoLimits:
        reply = await self._read(servo_id, hx.Ram.MAX_TEMPERATURE, 3)
        raw = reply.read_value()[1]
        if self.voltage_limits is not None:
            wanted = tuple(hx.raw_voltage(v) for v in self.voltage_limits)
            if tuple(raw[1:3]) != wanted:
                # The servo has its EEP limits back: power-cycled behind a live adapter.
                log.info("servo voltage limits set again", bus=self.bus.name, servo=servo_id,
                         found=str(_limits(raw)))
                await self.bus.transact(hx.voltage_limits_write(servo_id, *self.voltage_limits))
                self._judged.discard(servo_id)
                raw = bytes((raw[0], *wanted))
        return _limits(raw)

    # --- bring-up only: what the engineer asks for on purpose -------------------------------

    async def write_voltage_limits(
        self, ids: Sequence[int], low_v: float, high_v: float, eep: bool
    ) -> None:
        """Min/Max Voltage of each servo: RAM always, EEP too with `eep` (kept across power)."""
        for servo_id in ids:
            await self.bus.transact(hx.voltage_limits_write(servo_id, low_v, high_v))
            if eep:
                await self.bus.transact(hx.voltage_limits_write(servo_id, low_v, high_v, eep=True))

    async def read_eep(self, servo_id: int, address: int, length: int) -> bytes:
        """`length` bytes of EEP from `address`; ServoSilent when the servo does not answer."""
        return (await self._read(servo_id, address, length, eep=True)).read_value()[1]

    async def write_id(self, servo_id: int, new_id: int) -> None:
        """EEP_WRITE of the id (EEP 6): the servo takes it at its next reboot."""
        await self.bus.transact(hx.eep_write(servo_id, hx.Eep.ID, bytes((new_id,))))

    async def reboot(self, servo_id: int) -> None:
        """REBOOT (no reply): the servo restarts from its EEP."""
        await self.bus.transact(hx.reboot(servo_id))
        self._stored.pop(servo_id, None)
        self._judged.discard(servo_id)


class MaestroDriver(BusDriver):
    """Hobby servos on a Pololu Maestro's channels (compact protocol); ids are channels."""

    framing = Framing(2, lambda head: 2)
    id_range = mo.ID_RANGE

    async def ping(self, servo_id: int) -> int | None:
        """Get Errors; 0 (a Maestro has no model number), or None when unanswered."""
        try:
            await self._ask(servo_id, mo.get_errors(), lambda p: mo.decode_errors(p[0]), 2)
        except ServoSilent:
            return None
        return 0

    async def read_positions(self, ids: Sequence[int]) -> dict[int, int]:
        """Every Get Position in one write; a silent Maestro names the first channel."""
        ids = list(ids)
        # Every Get Position in one write; the replies come back in order, 2 bytes each.
        request = b"".join(mo.get_position(channel) for channel in ids)

        def decode(packets: list[bytes]) -> dict[int, int]:
            return {c: mo.decode_position(p) for c, p in zip(ids, packets, strict=True)}

        try:
            return await self.bus.transact(request, len(ids), self.framing, decode, 2 * len(ids))
        except (BusTimeout, CodecError):
            raise ServoSilent(ids[0], f"maestro on bus {self.bus.name} did not answer") from None

    async def write_goals(self, goals: Mapping[int, tuple[int, float]], step: float) -> None:
        """Set Multiple Targets per run of consecutive channels, Set Target otherwise."""
        await self.bus.transact(self._targets({c: raw for c, (raw, _) in goals.items()}))

    @staticmethod
    def _targets(targets: Mapping[int, int]) -> bytes:
        # Consecutive channels share one Set Multiple Targets; the rest get Set Target.
        out = b""
        channels = sorted(targets)
        start = 0
        while start < len(channels):
            end = start
            while end + 1 < len(channels) and channels[end + 1] == channels[end] + 1:
                end += 1
            run = channels[start : end + 1]
            if len(run) > 1:
                out += mo.set_multiple_targets(run[0], [targets[c] for c in run])
            else:
                out += mo.set_target(run[0], targets[run[0]])
            start = end + 1
        return out

    async def set_torque(self, ids: Sequence[int], on: bool) -> None:
        """Target 0 stops a channel's pulses (limp); on needs no packet, the next goal does."""
        # A hobby servo has no torque switch: target 0 stops its pulses (limp). Turning
        # it back on is the next goal write, which the joints layer makes the present position.
        if not on:
            await self.bus.transact(self._targets(dict.fromkeys(ids, 0)))

    async def reset_errors(self, ids: Sequence[int]) -> None:
        """Get Errors, which also clears the Maestro's error register."""
        await self._ask(ids[0] if ids else 0, mo.get_errors(), lambda p: mo.decode_errors(p[0]), 2)

    async def read_health(self, servo_id: int) -> Health:
        """Get Errors as flags only: they are the Maestro's link and script, not a servo."""
        errors = await self._ask(servo_id, mo.get_errors(), lambda p: mo.decode_errors(p[0]), 2)
        # The Maestro's errors are about its serial link and script, not a servo: report them
        # as flags without latching a fault.
        return Health(flags=_flags(errors, mo.Errors))


DRIVERS: dict[str, type[BusDriver]] = {
    "dynamixel1": Dynamixel1Driver,
    "dynamixel2": Dynamixel2Driver,
    "herkulex": HerkulexDriver,
    "maestro": MaestroDriver,
}


def driver_for(settings: BusSettings) -> BusDriver:
    """The driver of the bus's protocol over a new SerialBus (not started) on its port."""
    bus = SerialBus(
        settings.name,
        settings.port,
        settings.baud,
        timeout_margin=settings.timeout_margin_ms / 1000,
        retries=settings.retries,
    )
    if settings.protocol == "herkulex":
        return HerkulexDriver(bus, voltage_limits=settings.voltage_limits)
    return DRIVERS[settings.protocol](bus)
