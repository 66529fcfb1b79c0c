"""Dynamixel servos on a pty: AX-12A on Protocol 1.0, XL430 on Protocol 2.0."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from emulators.base import Axis, Emulator, split_with
from hal.servos import dynamixel1 as dx1
from hal.servos import dynamixel2 as dx2


class Dynamixel1Emulator(Emulator):
    """AX-12A servos: a 50-byte control table each, status return level honoured."""

    def __init__(
        self, path: Path, ids: list[int], rate: float = 1200.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.tables: dict[int, bytearray] = {}
        self.axes: dict[int, Axis] = {}
        for servo_id in ids:
            table = bytearray(dx1.AX12_CONTROL_TABLE_SIZE)
            table[0:2] = dx1.le16(dx1.AX12_MODEL_NUMBER)
            table[dx1.AX12.FIRMWARE_VERSION] = 24
            table[dx1.AX12.ID] = servo_id
            table[dx1.AX12.BAUD_RATE] = 1
            table[dx1.AX12.RETURN_DELAY_TIME] = 250
            table[dx1.AX12.CCW_ANGLE_LIMIT : dx1.AX12.CCW_ANGLE_LIMIT + 2] = dx1.le16(1023)
            table[dx1.AX12.TEMPERATURE_LIMIT] = 70
            table[dx1.AX12.STATUS_RETURN_LEVEL] = 2
            table[dx1.AX12.PRESENT_VOLTAGE] = 120
            table[dx1.AX12.PRESENT_TEMPERATURE] = 32
            table[dx1.AX12.GOAL_POSITION : dx1.AX12.GOAL_POSITION + 2] = dx1.le16(512)
            self.tables[servo_id] = table
            self.axes[servo_id] = Axis(512, 512, rate)
        super().__init__(path, clock)

    def split(self, buffer: bytes) -> tuple[bytes | None, bytes]:
        return split_with(dx1.HEAD_SIZE, dx1.HEADER, dx1.packet_length, buffer)

    def set_present(self, servo_id: int, raw: int) -> None:
        """A hand moves the horn (only meaningful while torque is off)."""
        with self._lock:
            self.axes[servo_id].present = raw

    def _refresh(self, servo_id: int) -> None:
        table, axis = self.tables[servo_id], self.axes[servo_id]
        axis.torque = bool(table[dx1.AX12.TORQUE_ENABLE])
        axis.goal = dx1.u16(table, dx1.AX12.GOAL_POSITION)
        present = axis.update(self.clock())
        table[dx1.AX12.PRESENT_POSITION : dx1.AX12.PRESENT_POSITION + 2] = dx1.le16(present)
        table[dx1.AX12.MOVING] = int(present != axis.goal)

    def _status(self, servo_id: int, params: bytes = b"") -> tuple[int, bytes]:
        reply_id = self.faults.wrong_id.get(servo_id, servo_id)
        error = self.faults.error_bits.get(servo_id, 0)
        return servo_id, dx1.status(reply_id, error, params)

    def handle(self, packet: bytes) -> list[tuple[int, bytes]]:
        try:
            request = dx1.decode_instruction(packet)
        except dx1.DynamixelError:
            return []  # a servo ignores a packet with a bad checksum
        if request.instruction == dx1.Instruction.SYNC_WRITE:
            address, length = request.params[0], request.params[1]
            for start in range(2, len(request.params), length + 1):
                servo_id = request.params[start]
                if servo_id in self.tables:
                    self._write(servo_id, address, request.params[start + 1 : start + 1 + length])
            return []
        servo_id = request.servo_id
        if servo_id not in self.tables:
            return []
        level = self.tables[servo_id][dx1.AX12.STATUS_RETURN_LEVEL]
        if request.instruction == dx1.Instruction.PING:
            return [self._status(servo_id)]
        if request.instruction == dx1.Instruction.READ:
            self._refresh(servo_id)
            address, length = request.params[0], request.params[1]
            data = bytes(self.tables[servo_id][address : address + length])
            return [self._status(servo_id, data)] if level >= 1 else []
        if request.instruction == dx1.Instruction.WRITE:
            self._write(servo_id, request.params[0], request.params[1:])
            return [self._status(servo_id)] if level >= 2 else []
        return [self._status(servo_id)] if level >= 2 else []

    def _write(self, servo_id: int, address: int, data: bytes) -> None:
        self._refresh(servo_id)
        self.tables[servo_id][address : address + len(data)] = data
        self._refresh(servo_id)


class Dynamixel2Emulator(Emulator):
    """XL430 servos: Protocol 2.0 with SYNC_READ, BULK_READ and REBOOT."""

    def __init__(
        self, path: Path, ids: list[int], rate: float = 4000.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.tables: dict[int, bytearray] = {}
        self.axes: dict[int, Axis] = {}
        for servo_id in ids:
            table = bytearray(dx2.X_CONTROL_TABLE_SIZE)
            table[0:2] = dx2.le16(dx2.XL430_MODEL_NUMBER)
            table[dx2.XSeries.FIRMWARE_VERSION] = 45
            table[dx2.XSeries.ID] = servo_id
            table[dx2.XSeries.STATUS_RETURN_LEVEL] = 2
            table[dx2.XSeries.TEMPERATURE_LIMIT] = 72
            table[dx2.XSeries.PRESENT_INPUT_VOLTAGE : dx2.XSeries.PRESENT_INPUT_VOLTAGE + 2] = (
                dx2.le16(120)
            )
            table[dx2.XSeries.PRESENT_TEMPERATURE] = 30
            table[dx2.XSeries.GOAL_POSITION : dx2.XSeries.GOAL_POSITION + 4] = dx2.le32(2048)
            self.tables[servo_id] = table
            self.axes[servo_id] = Axis(2048, 2048, rate)
        super().__init__(path, clock)

    def split(self, buffer: bytes) -> tuple[bytes | None, bytes]:
        return split_with(dx2.HEAD_SIZE, dx2.HEADER, dx2.packet_length, buffer)

    def set_present(self, servo_id: int, raw: int) -> None:
        with self._lock:
            self.axes[servo_id].present = raw

    def _refresh(self, servo_id: int) -> None:
        table, axis = self.tables[servo_id], self.axes[servo_id]
        axis.torque = bool(table[dx2.XSeries.TORQUE_ENABLE])
        axis.goal = dx2.s32(table, dx2.XSeries.GOAL_POSITION)
        present = axis.update(self.clock())
        table[dx2.XSeries.PRESENT_POSITION : dx2.XSeries.PRESENT_POSITION + 4] = dx2.le32(present)
        table[dx2.XSeries.MOVING] = int(present != axis.goal)
        table[dx2.XSeries.HARDWARE_ERROR_STATUS] = self.faults.error_bits.get(servo_id, 0)

    def _status(self, servo_id: int, params: bytes = b"", error: int = 0) -> tuple[int, bytes]:
        reply_id = self.faults.wrong_id.get(servo_id, servo_id)
        if self.faults.error_bits.get(servo_id):
            error |= dx2.ALERT
        return servo_id, dx2.status(reply_id, error, params)

    def _read(self, servo_id: int, address: int, length: int) -> tuple[int, bytes]:
        self._refresh(servo_id)
        return self._status(servo_id, bytes(self.tables[servo_id][address : address + length]))

    def handle(self, packet: bytes) -> list[tuple[int, bytes]]:
        try:
            request = dx2.decode_instruction(packet)
        except dx2.DynamixelError:
            return []
        params = request.params
        if request.instruction == dx2.Instruction.SYNC_WRITE:
            address, length = dx2.u16(params, 0), dx2.u16(params, 2)
            for start in range(4, len(params), length + 1):
                if params[start] in self.tables:
                    self._write(params[start], address, params[start + 1 : start + 1 + length])
            return []
        if request.instruction == dx2.Instruction.SYNC_READ:
            address, length = dx2.u16(params, 0), dx2.u16(params, 2)
            return [self._read(i, address, length) for i in params[4:] if i in self.tables]
        if request.instruction == dx2.Instruction.BULK_READ:
            return [
                self._read(params[i], dx2.u16(params, i + 1), dx2.u16(params, i + 3))
                for i in range(0, len(params), 5)
                if params[i] in self.tables
            ]
        servo_id = request.servo_id
        if servo_id not in self.tables:
            return []
        if request.instruction == dx2.Instruction.PING:
            table = self.tables[servo_id]
            return [self._status(servo_id, bytes(table[0:2]) + bytes((table[6],)))]
        if request.instruction == dx2.Instruction.READ:
            return [self._read(servo_id, dx2.u16(params, 0), dx2.u16(params, 2))]
        if request.instruction == dx2.Instruction.WRITE:
            self._write(servo_id, dx2.u16(params, 0), params[2:])
            return [self._status(servo_id)]
        if request.instruction == dx2.Instruction.REBOOT:
            self.tables[servo_id][dx2.XSeries.TORQUE_ENABLE] = 0
            self.faults.error_bits.pop(servo_id, None)
            return [self._status(servo_id)]
        return [self._status(servo_id, error=dx2.ErrorNumber.INSTRUCTION)]

    def _write(self, servo_id: int, address: int, data: bytes) -> None:
        self._refresh(servo_id)
        self.tables[servo_id][address : address + len(data)] = data
        self._refresh(servo_id)
