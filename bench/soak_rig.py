"""The soak's robot: the game on real HerkuleX drivers talking to a pty emulator, in simulated time.

Only what a fault needs is emulated: the servos answer on a pseudo-terminal in
the real protocol (so timeouts, corrupt replies and an unplugged adapter go
through the real bus thread, retries and reconnect), the keyfob is the
simulated one (it can be unplugged), and the voice is the real queue, timeout
and recovery code in front of an engine that can hang. The emulated shafts move
on the game's simulated clock (kasparctl.sim.simtime holds that clock while the bus
thread waits for a reply), and a monitor checks every goal packet the servos
receive against the joint's range and speed limit.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
from emulators.herkulex import HerkulexEmulator

from hal.clock import Clock
from hal.servos import herkulex as hx
from hal.servos.drivers import driver_for
from hal.servos.joints import Joints
from hal.servos.settings import JointSettings, ServoSettings
from hal.voice.sim import speaking_time

# A goal may differ from the last by the speed limit over one control step, plus the
# rounding of degrees to raw units on both goals (a DRS-0101 unit is 0.325 degrees).
SPEED_TOLERANCE = 1.01
RAW_UNITS_TOLERANCE = 2


@dataclass
class Violation:
    joint: str
    kind: str  # "range" or "speed"
    detail: str


@dataclass
class MotionMonitor:
    """Checks each goal a servo receives: inside its range, and no faster than its limit."""

    settings: ServoSettings
    report: Callable[[Violation], None]
    goals_checked: int = 0
    violations: int = 0
    _last_deg: dict[int, float | None] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._joints: dict[int, JointSettings] = {j.id: j for j in self.settings.joints}
        self._step = 1.0 / self.settings.control_hz

    def torque(self, servo_id: int, on: bool, present_raw: float) -> None:
        # Torque on holds the shaft where it is: the next goal must start from there.
        joint = self._joints.get(servo_id)
        if joint is not None:
            self._last_deg[servo_id] = self._degrees(joint, present_raw) if on else None

    def goal(self, servo_id: int, raw: int) -> None:
        joint = self._joints.get(servo_id)
        if joint is None:
            return
        self.goals_checked += 1
        degrees = self._degrees(joint, raw)
        unit = abs(self._degrees(joint, raw + 1) - degrees)
        low, high = joint.range_deg
        if not low - unit <= degrees <= high + unit:
            self._violate(joint, "range", f"goal {degrees:.2f} deg outside {low} to {high}")
        last = self._last_deg.get(servo_id)
        if last is not None:
            allowed = joint.max_speed_dps * self._step * SPEED_TOLERANCE
            allowed += RAW_UNITS_TOLERANCE * unit
            if abs(degrees - last) > allowed:
                self._violate(
                    joint,
                    "speed",
                    f"goal moved {abs(degrees - last):.2f} deg in one {self._step:.3f} s step "
                    f"(limit {joint.max_speed_dps} deg/s allows {allowed:.2f})",
                )
        self._last_deg[servo_id] = degrees

    def _degrees(self, joint: JointSettings, raw: float) -> float:
        return joint.servo.to_degrees(raw, joint.direction, joint.offset_deg)

    def _violate(self, joint: JointSettings, kind: str, detail: str) -> None:
        self.violations += 1
        self.report(Violation(joint.name, kind, detail))


class MonitoredHerkulex(HerkulexEmulator):
    """The HerkuleX emulator, showing the monitor every torque change and goal it takes."""

    def __init__(
        self, path: Path, ids: list[int], monitor: MotionMonitor, clock: Callable[[], float]
    ) -> None:
        self.monitor = monitor
        super().__init__(path, ids, clock=clock)

    def handle(self, packet: bytes) -> list[tuple[int, bytes]]:
        replies = super().handle(packet)
        try:
            request = hx.decode_packet(packet)
        except hx.HerkulexError:
            return replies
        data = request.data
        if request.command == hx.Command.S_JOG:
            for i in range(1, len(data) - 3, 4):
                entry = data[i : i + 4]
                if not entry[2] & hx.JogSet.STOP:
                    self.monitor.goal(entry[3], hx.u16(entry))
        elif request.command == hx.Command.RAM_WRITE:
            address, length = data[0], data[1]
            if address <= hx.Ram.TORQUE_CONTROL < address + length:
                on = data[2 + hx.Ram.TORQUE_CONTROL - address] == hx.TorqueControl.ON
                targets = list(self.axes) if request.servo_id == hx.BROADCAST_ID else [
                    request.servo_id
                ]
                for servo_id in targets:
                    if servo_id in self.axes:
                        self.monitor.torque(servo_id, on, self.axes[servo_id].present)
        return replies

    def torque_on(self, servo_id: int) -> bool:
        with self._lock:
            return self.ram[servo_id][hx.Ram.TORQUE_CONTROL] == hx.TorqueControl.ON


def emulated_settings(settings: ServoSettings, port: Path) -> ServoSettings:
    """The robot's servo table with its one HerkuleX bus on the emulator's pty."""
    if len(settings.buses) != 1 or settings.buses[0].protocol != "herkulex":
        raise ValueError("the soak emulates one HerkuleX bus, as on the demo robot")
    bus = msgspec.structs.replace(settings.buses[0], port=str(port))
    return msgspec.structs.replace(settings, backend="real", buses=(bus,))


class EmulatedServos(Joints):
    """The robot's own Joints and HerkuleX driver on the emulator; children push limp joints."""

    def __init__(self, settings: ServoSettings, emulator: MonitoredHerkulex, clock: Clock) -> None:
        (bus,) = settings.buses
        self.driver = driver_for(bus)
        super().__init__(settings, {bus.name: self.driver}, clock)
        self.emulator = emulator
        # A robot powered on limp, at rest.
        for joint in settings.joints:
            raw = joint.servo.to_raw(joint.rest_deg, joint.direction, joint.offset_deg)
            emulator.set_present(joint.id, raw)

    def push(self, joint: str, degrees: float) -> None:
        settings = next(j for j in self.settings.joints if j.name == joint)
        if not self.emulator.torque_on(settings.id):
            raw = settings.servo.to_raw(degrees, settings.direction, settings.offset_deg)
            self.emulator.set_present(settings.id, raw)


class HangingSink:
    """A voice Sink whose "engine" speaks for as long as the line takes, or hangs when told to.

    hal.voice.speaker.Voice in front of it is the robot's own: its queue, utterance timeout,
    cancellation and fallback handle the hang.
    """

    def __init__(self, clock: Clock, rate: int) -> None:
        self._clock = clock
        self._rate = rate
        self.hang_next = False
        self.hung = 0

    def target(self, via: str) -> tuple[Path, bool]:
        raise NotImplementedError("the soak's voice renders no files")

    async def play_file(self, path: Path, via: str) -> str | None:
        return None

    async def espeak(self, argv: list[str], text: str) -> str | None:
        if self.hang_next:
            self.hang_next = False
            self.hung += 1
            await asyncio.Event().wait()  # until the voice's timeout cancels it
        await self._clock.sleep(speaking_time(text, self._rate))
        return None

    def close(self) -> None:
        return None

