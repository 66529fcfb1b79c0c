"""Simulated servos with the same interface and the same safety code as the real ones.

SimServos is the Joints layer over SimDriver, a driver whose servos live in
memory: positions move toward their goals at the commanded speed as the
injected clock advances, torque can be off (a hand can then move the joint),
and faults can be injected per servo (silent, overheating, overload, ...).
So the game, the demo and the tests exercise exactly the clamps, speed
limits and fault handling that drive the robot.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from hal.clock import Clock
from hal.errors import ServoSilent, UnknownJoint
from hal.servos.api import FaultKind, Health
from hal.servos.joints import Joints
from hal.servos.settings import JointSettings, ServoModel, ServoSettings

# The simulated battery: a charged LiFePO4 pack (Kaspar 3's, 10-13.5 V) losing a little
# with every hour of the clock, so that a long simulated game sees it fall.
SIM_BATTERY_FULL_V = 13.2
SIM_BATTERY_FALL_V_PER_HOUR = 0.4
SIM_BATTERY_EMPTY_V = 10.0


@dataclass
class SimServo:
    """One simulated servo, in raw units; it moves only when the clock is read (lazily)."""

    model: ServoModel
    present: float  # raw units
    goal: float
    speed: float = 0.0  # raw units per second toward the goal
    torque: bool = False
    temperature_c: float = 35.0
    fault: FaultKind | None = None  # SILENT makes it stop answering
    # A hand holding the limp horn: raw position as a function of the clock's time.
    hand: Callable[[float], float] | None = None

    def reading(self) -> int:
        """What the servo reports: its position, or the model's off reading (no feedback, limp)."""
        if not self.torque and self.model.off_reading is not None:
            return self.model.off_reading
        return round(self.present)


@dataclass
class GoalWrite:
    """One goal packet, as the tests see it: when, and raw goal per servo id."""

    time: float
    goals: dict[int, int]


@dataclass(eq=False)  # identity-hashed: the joints layer groups joints by driver
class SimDriver:
    """A bus of simulated servos; `writes` records every goal packet sent."""

    name: str
    clock: Clock
    servos: dict[int, SimServo]
    writes: list[GoalWrite] = field(default_factory=list)
    _stamp: float | None = None
    _since: float | None = None  # when the simulated battery was charged (the first start)
    battery_full_v: float = SIM_BATTERY_FULL_V  # a test may start with a tired battery

    def battery_v(self) -> float:
        """The simulated battery's voltage now: falling slowly from full, never below empty."""
        now = self.clock.now()
        if self._since is None:
            self._since = now
        hours = (now - self._since) / 3600
        return max(SIM_BATTERY_EMPTY_V, self.battery_full_v - SIM_BATTERY_FALL_V_PER_HOUR * hours)

    def _advance(self) -> None:
        now = self.clock.now()
        elapsed = 0.0 if self._stamp is None else now - self._stamp
        self._stamp = now
        for servo in self.servos.values():
            if not servo.torque and servo.hand is not None:
                servo.present = servo.goal = servo.hand(now)
            if not servo.torque or servo.fault is FaultKind.SILENT:
                continue
            step = servo.speed * elapsed
            delta = servo.goal - servo.present
            servo.present = servo.goal if abs(delta) <= step else (
                servo.present + (step if delta > 0 else -step)
            )

    def _answering(self, servo_id: int) -> SimServo:
        servo = self.servos.get(servo_id)
        if servo is None or servo.fault is FaultKind.SILENT:
            raise ServoSilent(servo_id, f"servo {servo_id} on bus {self.name}: no reply")
        return servo

    async def start(self) -> None:
        """Start the motion clock (and the battery's) now."""
        self._advance()
        self.battery_v()

    async def close(self) -> None:
        """Nothing to release."""
        return None

    async def ping(self, servo_id: int) -> int | None:
        """The model's number (0 where it has none), or None for a silent or missing servo."""
        try:
            servo = self._answering(servo_id)
        except ServoSilent:
            return None
        return servo.model.model_number or 0

    async def read_positions(self, ids: Sequence[int]) -> dict[int, int]:
        """Present raw positions, moved up to now; ServoSilent for a silent or missing servo."""
        self._advance()
        return {servo_id: self._answering(servo_id).reading() for servo_id in ids}

    async def write_goals(self, goals: Mapping[int, tuple[int, float]], step: float) -> None:
        """Record the packet, then set each servo's goal and speed, turning its torque on.

        Torque goes on as on a Dynamixel; a silent servo ignores the packet, as
        a real one ignores a broadcast it cannot hear.
        """
        self._advance()
        self.writes.append(GoalWrite(self.clock.now(), {i: raw for i, (raw, _) in goals.items()}))
        for servo_id, (raw, speed_dps) in goals.items():
            servo = self.servos.get(servo_id)
            if servo is None or servo.fault is FaultKind.SILENT:
                continue  # a broadcast write: a silent servo just does not act on it
            servo.goal = raw
            servo.speed = speed_dps / servo.model.degrees_per_unit
            servo.torque = True  # as on a Dynamixel, a goal write turns torque on

    async def set_torque(self, ids: Sequence[int], on: bool) -> None:
        """Torque on or off for every answering servo in `ids`."""
        self._advance()
        for servo_id in ids:
            servo = self.servos.get(servo_id)
            if servo is not None and servo.fault is not FaultKind.SILENT:
                servo.torque = on

    async def reset_errors(self, ids: Sequence[int]) -> None:
        """Nothing: a simulated fault lasts until inject_fault(joint, None)."""
        return None

    def retried(self) -> int:
        """Always 0: a simulated bus never corrupts a reply."""
        return 0

    async def read_health(self, servo_id: int) -> Health:
        """The servo's temperature, the battery's voltage, injected fault, no load.

        ServoSilent if silent; a Maestro's hobby servo reads no voltage.
        """
        self._advance()
        servo = self._answering(servo_id)
        return Health(
            position=servo.reading(),
            temperature_c=servo.temperature_c,
            voltage_v=None if servo.model.protocol == "maestro" else round(self.battery_v(), 2),
            load=0.0,
            flags=(servo.fault.name,) if servo.fault else (),
            kind=servo.fault,
        )


class SimServos(Joints):
    """The ServoApi on simulated servos; they start at rest, limp, as a robot is powered on."""

    def __init__(self, settings: ServoSettings, clock: Clock) -> None:
        """One SimDriver per configured bus, every servo at its rest position with torque off."""
        drivers: dict[str, SimDriver] = {}
        for bus in settings.buses:
            servos = {}
            for joint in settings.joints:
                if joint.bus == bus.name:
                    raw = joint.servo.to_raw(joint.rest_deg, joint.direction, joint.offset_deg)
                    servos[joint.id] = SimServo(joint.servo, raw, raw)
            drivers[bus.name] = SimDriver(bus.name, clock, servos)
        super().__init__(settings, drivers, clock)
        self.drivers: dict[str, SimDriver] = drivers

    def servo(self, joint: str) -> SimServo:
        """The simulated servo behind `joint`; UnknownJoint if there is no such joint."""
        settings = self._joint_settings(joint)
        return self.drivers[settings.bus].servos[settings.id]

    def _joint_settings(self, joint: str) -> JointSettings:
        for settings in self.settings.joints:
            if settings.name == joint:
                return settings
        raise UnknownJoint(f"unknown joint {joint!r}")

    def inject_fault(self, joint: str, kind: FaultKind | None) -> None:
        """From now on the joint's servo reports `kind` (None heals it); the poll latches it."""
        self.servo(joint).fault = kind

    def push(self, joint: str, degrees: float) -> None:
        """A child moves a limp joint by hand (ignored while its torque is on)."""
        settings = self._joint_settings(joint)
        servo = self.servo(joint)
        if not servo.torque:
            servo.present = servo.goal = settings.servo.to_raw(
                degrees, settings.direction, settings.offset_deg
            )

    def hand(self, joint: str, path: Callable[[float], float] | None) -> None:
        """From now on a hand holds the joint: while it is limp it follows `path(time)` degrees.

        `time` is the clock's; None lets go. Used to demonstrate calibration and poses
        without a robot (and by their tests).
        """
        settings = self._joint_settings(joint)
        servo = self.servo(joint)
        if path is None:
            servo.hand = None
            return

        def raw(now: float) -> float:
            degrees = path(now)
            return settings.servo.raw_centre + settings.direction * (
                degrees - settings.offset_deg
            ) / settings.servo.degrees_per_unit

        servo.hand = raw

    def true_position(self, joint: str) -> float:
        """Where the simulated joint really is, in degrees (for tests and the demo)."""
        settings = self._joint_settings(joint)
        # Motion is simulated lazily, at each bus operation: bring it up to now first.
        self.drivers[settings.bus]._advance()
        return settings.servo.to_degrees(
            self.servo(joint).present, settings.direction, settings.offset_deg
        )
