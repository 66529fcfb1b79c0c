"""HerkuleX DRS-0101 servos on a pty: RAM map, ACK policy, S_JOG/I_JOG motion, STAT."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from emulators.base import Axis, Emulator, split_with
from hal.servos import herkulex as hx


class HerkulexEmulator(Emulator):
    def __init__(
        self, path: Path, ids: list[int], rate: float = 1100.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.ram: dict[int, bytearray] = {}
        self.axes: dict[int, Axis] = {}
        for servo_id in ids:
            ram = bytearray(hx.Ram.RAM_SIZE)
            ram[hx.Ram.ID] = servo_id
            ram[hx.Ram.ACK_POLICY] = hx.AckPolicy.READS_ONLY
            ram[hx.Ram.VOLTAGE] = 120
            ram[hx.Ram.TEMPERATURE] = 90
            ram[hx.Ram.CALIBRATED_POSITION : hx.Ram.CALIBRATED_POSITION + 2] = hx.le16(512)
            self.ram[servo_id] = ram
            self.axes[servo_id] = Axis(512, 512, rate)
        super().__init__(path, clock)

    def split(self, buffer: bytes) -> tuple[bytes | None, bytes]:
        return split_with(hx.HEAD_SIZE, hx.HEADER, hx.packet_length, buffer)

    def corrupt(self, reply: bytes) -> bytes:
        return reply[:5] + bytes((reply[5] ^ 0x02,)) + reply[6:]

    def set_present(self, servo_id: int, raw: int) -> None:
        with self._lock:
            self.axes[servo_id].present = raw

    def _refresh(self, servo_id: int) -> None:
        ram, axis = self.ram[servo_id], self.axes[servo_id]
        axis.torque = ram[hx.Ram.TORQUE_CONTROL] == hx.TorqueControl.ON
        present = axis.update(self.clock())
        ram[hx.Ram.CALIBRATED_POSITION : hx.Ram.CALIBRATED_POSITION + 2] = hx.le16(present)
        error = self.faults.error_bits.get(servo_id, 0)
        ram[hx.Ram.STATUS_ERROR] = error
        detail = hx.StatusDetail.MOTOR_ON if axis.torque else 0
        if present != axis.goal:
            detail |= hx.StatusDetail.MOVING
        ram[hx.Ram.STATUS_DETAIL] = detail

    def _ack(self, servo_id: int, command: int, data: bytes = b"") -> tuple[int, bytes]:
        self._refresh(servo_id)
        ram = self.ram[servo_id]
        reply_id = self.faults.wrong_id.get(servo_id, servo_id)
        return servo_id, hx.ack(
            reply_id, command, data, ram[hx.Ram.STATUS_ERROR], ram[hx.Ram.STATUS_DETAIL]
        )

    def handle(self, packet: bytes) -> list[tuple[int, bytes]]:
        try:
            request = hx.decode_packet(packet)
        except hx.HerkulexError:
            return []
        data = request.data
        if request.command in (hx.Command.S_JOG, hx.Command.I_JOG):
            self._jog(request.command, data)
            return []
        targets = list(self.ram) if request.servo_id == hx.BROADCAST_ID else [request.servo_id]
        replies = []
        for servo_id in targets:
            if servo_id not in self.ram:
                continue
            policy = self.ram[servo_id][hx.Ram.ACK_POLICY]
            if request.command == hx.Command.RAM_READ:
                address, length = data[0], data[1]
                self._refresh(servo_id)
                value = bytes(self.ram[servo_id][address : address + length])
                replies.append(self._ack(servo_id, request.command, data[:2] + value))
            elif request.command == hx.Command.RAM_WRITE:
                address, length = data[0], data[1]
                self._refresh(servo_id)
                self.ram[servo_id][address : address + length] = data[2 : 2 + length]
                if address <= hx.Ram.STATUS_ERROR < address + length and not data[2]:
                    self.faults.error_bits.pop(servo_id, None)  # the error is acknowledged
                if address <= hx.Ram.TORQUE_CONTROL < address + length:
                    # Torque on from free: the servo holds where it is.
                    self.axes[servo_id].goal = self.axes[servo_id].present
                if policy == hx.AckPolicy.ALWAYS:
                    replies.append(self._ack(servo_id, request.command))
            elif request.command == hx.Command.EEP_READ:
                model = bytes((0x01, 0x01, 0x00, 0x00))  # DRS-0101: model 1, 1
                address, length = data[0], data[1]
                replies.append(self._ack(servo_id, request.command, data[:2] + model[address : address + length]))
            elif request.command == hx.Command.STAT:
                replies.append(self._ack(servo_id, request.command))
            elif request.command == hx.Command.REBOOT:
                self.faults.error_bits.pop(servo_id, None)
                self.ram[servo_id][hx.Ram.TORQUE_CONTROL] = hx.TorqueControl.FREE
        return [] if request.servo_id == hx.BROADCAST_ID else replies

    def _jog(self, command: int, data: bytes) -> None:
        if command == hx.Command.S_JOG:
            entries = [(data[i : i + 4], data[0]) for i in range(1, len(data) - 3, 4)]
        else:
            entries = [(data[i : i + 4], data[i + 4]) for i in range(0, len(data) - 4, 5)]
        for entry, _playtime in entries:
            servo_id = entry[3]
            if servo_id in self.ram and not entry[2] & hx.JogSet.STOP:
                self._refresh(servo_id)
                self.axes[servo_id].goal = hx.u16(entry)
                ram = self.ram[servo_id]
                ram[hx.Ram.ABSOLUTE_GOAL_POSITION : hx.Ram.ABSOLUTE_GOAL_POSITION + 2] = entry[:2]
