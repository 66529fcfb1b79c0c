"""What the game sees of the servos (ServoApi), and what a bus driver gives the joints layer.

The game speaks in named joints, groups and degrees; it never sees a bus, an
id or a raw unit. Both the real joints (hal.servos.joints.Joints) and the simulated
ones (hal.servos.sim.SimServos) implement ServoApi, with the same safety rules.

Two paths move a joint, and ServoApi arbitrates them joint by joint: `move` plays a
whole profile and claims the joints it moves until it ends; `stream` sends one control
step and moves only joints nobody has claimed (the body's loop: gaze, blinks, the
mouth). So the mouth follows a line while the arm points.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from hal.clock import Clock


class FaultKind(enum.Enum):
    """Why a joint's fault was latched; the value is what logs and session records show."""

    SILENT = "silent"  # the servo stopped answering
    OVERHEATING = "overheating"
    OVERLOAD = "overload"
    VOLTAGE = "voltage"  # input voltage outside the servo's limits
    HARDWARE = "hardware"  # encoder, driver or memory fault reported by the servo
    BUS_LOST = "bus_lost"  # the serial adapter vanished
    IMPOSSIBLE = "impossible_reading"  # a position the servo cannot report: never trusted


@dataclass(frozen=True, slots=True)
class Fault:
    """A latched fault: it stays until clear_faults(), and it names the joint."""

    joint: str
    kind: FaultKind
    detail: str
    time: float  # Clock.now() when it was latched

    def __str__(self) -> str:
        """"joint: kind (detail)", as the robot logs and announces it."""
        return f"{self.joint}: {self.kind.value} ({self.detail})"


@dataclass(frozen=True, slots=True)
class ServoLimits:
    """A servo's own temperature and supply limits, where its protocol keeps them.

    HerkuleX keeps them twice: in EEP (11 Max Temperature, 12 Min Voltage, 13 Max
    Voltage: copied to RAM at power-up) and in RAM (5, 6, 7: what it acts on now).
    """

    max_temperature_c: float | None  # None: a raw value beyond the manual's table
    min_voltage_v: float
    max_voltage_v: float

    def __str__(self) -> str:
        """"84 C, 6.7-10.1 V", as `servos read` prints it."""
        hot = "?" if self.max_temperature_c is None else f"{self.max_temperature_c:.0f}"
        return f"{hot} C, {self.min_voltage_v:.1f}-{self.max_voltage_v:.1f} V"


@dataclass(frozen=True, slots=True)
class JointStatus:
    """One joint as `kasparctl servos read` and the health poll see it.

    `flags` are the error bits the servo reported (latched ones included, even
    those cleared since); `problems` name what is impossible or unsafe in the
    reading itself (a position the servo cannot report, a temperature no servo
    reaches). A joint is healthy only with no fault, no flags and no problems.
    """

    joint: str
    position_deg: float | None
    torque: bool
    temperature_c: float | None = None
    voltage_v: float | None = None
    load: float | None = None  # fraction of maximum torque, signed by direction
    fault: Fault | None = None
    raw_position: int | None = None
    flags: tuple[str, ...] = ()
    problems: tuple[str, ...] = ()
    stored_limits: ServoLimits | None = None  # the servo's own EEP limits, as read
    active_limits: ServoLimits | None = None  # the limits it works to now (RAM)

    @property
    def healthy(self) -> bool:
        """No fault, no error bit, nothing impossible."""
        return self.fault is None and not self.flags and not self.problems


@dataclass(frozen=True, slots=True)
class BatteryReading:
    """The battery as the servos last read it ([servos.battery]): volts, and its warning line.

    `voltage_v` is None until the battery's servo has been read (or while it is silent).
    """

    joint: str  # whose servo reads it
    voltage_v: float | None
    warn_below_v: float

    @property
    def low(self) -> bool:
        """Below its warning line (False while unread)."""
        return self.voltage_v is not None and self.voltage_v < self.warn_below_v


Pose = Mapping[str, float]  # joint name -> degrees

# Who sent a goal, when nobody says: a move() of the game, a stream() step of the body.
MOVE = "move"
STREAM = "stream"


@dataclass(frozen=True, slots=True)
class Goal:
    """One goal the joints layer wrote to a joint: when, where to, and who asked.

    `source` names the path: a move's (MOVE, or what its caller called it: "point",
    "rest"), a streamed step's (STREAM, or the body's layer: "mouth", "blink", ...),
    "torque_on" (the hold written before torque goes on), "into_range".
    """

    time: float  # Clock.now() when it was written
    joint: str
    degrees: float
    source: str


@runtime_checkable
class ServoApi(Protocol):
    """The servos as the game uses them. Every method is safe to call at any time.

    Safety is the implementation's job, not the caller's: targets outside a
    joint's range are clamped (and the clamp is logged), no joint moves faster
    than its limit whatever `duration` says, turning torque on never makes a
    joint jump, and while a fault is latched motion is refused.

    Arbitration is per joint. A move claims the joints of its pose for as long as it
    runs; a second move sharing a joint with a move running or waiting waits for it
    (moves sharing joints start in the order they were asked), and moves with no joint
    in common run side by side. A stream step sends goals only to joints no move, no
    set_compliant and no rest holds: those of a claimed joint are dropped (the claim
    owns it), the others go out at once. set_compliant and rest claim what they touch.
    A cancelled move lets its joints go at once, where they are.
    """

    @property
    def clock(self) -> Clock:
        """The clock that times every move and stamps every goal."""
        ...

    @property
    def joints(self) -> tuple[str, ...]:
        """Every configured joint name."""
        ...

    @property
    def groups(self) -> Mapping[str, tuple[str, ...]]:
        """Group name (left_arm, head, ...) -> its joints."""
        ...

    def scale_speeds(self, scale: float) -> None:
        """Every joint's speed limit times `scale` (0 < scale <= 1) from the next goal on:
        a session's slower robot. UnsafeCommand for a scale outside that."""
        ...

    @property
    def faults(self) -> tuple[Fault, ...]:
        """The latched faults, oldest first; empty when all is well."""
        ...

    async def start(self) -> None:
        """Open the buses and read where every joint is; torque is left as found."""
        ...

    async def close(self) -> None:
        """Stop polling and release the buses (torque is left as it is: no slump)."""
        ...

    async def read_positions(self, group: str | None = None) -> dict[str, float]:
        """Present positions in degrees of a group's (or one joint's) joints; all if None.

        Raises UnknownJoint for a name that is neither a group nor a joint, and
        ServoFaultError when a servo does not answer (the fault is latched).
        """
        ...

    async def move(
        self,
        pose: Pose,
        duration: float | None = None,
        speed: float | None = None,
        *,
        source: str = MOVE,
    ) -> None:
        """Move the joints in `pose` together, arriving after `duration` seconds.

        Without a duration, each joint goes at `speed` deg/s, or at its own limit.
        The joints are claimed from the start to the end (see the class); `source`
        names the move in every Goal it writes. Returns when the motion has been
        commanded to its end. Raises
        ServoFaultError while a fault is latched (or one is latched during the
        move), UnsafeCommand for a joint whose torque has not been turned on by
        set_compliant(group, False) and for a NaN target or a negative, infinite
        duration or speed, and UnknownJoint (a HalError that is also a KeyError)
        naming every unknown joint; nothing moves when it raises before the start.
        """
        ...

    def commanded(self) -> dict[str, float]:
        """The last goal of every joint whose torque is on (where it is held), in degrees."""
        ...

    async def stream(
        self, pose: Pose, period: float, sources: Mapping[str, str] | None = None
    ) -> dict[str, float]:
        """One control step toward `pose`, for a loop that sends a goal every `period` s.

        Each goal is clamped to its joint's range and moves from the joint's last goal
        by at most its speed limit times the time since that goal (counting at most `period`,
        or the time one count takes at the limit if longer); a goal that would not change
        the servo's count is not sent and leaves the joint's last goal as it was.
        Joints claimed by a move, set_compliant or rest, and limp joints, are left alone.
        `sources` names the layer of each joint's goal (STREAM when not named). Returns
        the goals sent. Raises UnknownJoint, UnsafeCommand (NaN target, bad period) and
        ServoFaultError while a fault is latched.
        """
        ...

    def sends(self, pose: Pose, at: float, period: float) -> bool:
        """Whether stream(pose, period) at `at` would send any servo a new count (True while
        a fault is latched). Nothing is sent or changed: a loop asks it to rest through the
        steps that would change nothing a servo does."""
        ...

    def count_of(self, joint: str, degrees: float) -> int:
        """The raw count `joint`'s servo would be sent for `degrees` (clamped to its range)."""
        ...

    def speed_limit(self, joint: str) -> float:
        """`joint`'s speed limit now, degrees per second (the session's scale applied)."""
        ...

    async def set_compliant(self, group: str, compliant: bool) -> None:
        """Torque off (a child can move the arm by hand) or back on, holding where it is.

        `group` may also name one joint. Turning torque on raises ServoFaultError
        while a fault is latched and UnsafeCommand for a joint found outside its
        range (it stays limp); UnknownJoint for an unknown name.
        """
        ...

    async def rest(self, duration: float | None = None) -> None:
        """Move the joints to their rest positions, within their speed limits.

        Joints whose torque is still unknown (just after start) are first turned on
        the safe way, as by set_compliant(group, False); one found outside its range
        stays limp (logged). Joints made compliant on purpose stay limp.
        """
        ...

    def on_fault(self, listener: Callable[[Fault], None]) -> None:
        """Call `listener` with every newly latched fault, as it is latched."""
        ...

    def off_fault(self, listener: Callable[[Fault], None]) -> None:
        """Stop calling a listener given to on_fault (unknown listeners are ignored)."""
        ...

    async def clear_faults(self) -> None:
        """Reset the faulty servos' error state and forget the latched faults.

        Joints freed by the safe action stay limp: set_compliant(group, False)
        turns them back on, from where they are.
        """
        ...

    def on_goals(self, listener: Callable[[Goal], None]) -> None:
        """Call `listener` with every goal written, by any path, once its packet is sent."""
        ...

    def battery(self) -> BatteryReading | None:
        """The battery's last reading by the health poll; None when no battery is watched."""
        ...

    def off_goals(self, listener: Callable[[Goal], None]) -> None:
        """Stop calling a listener given to on_goals (unknown listeners are ignored)."""
        ...


@dataclass(frozen=True, slots=True)
class Health:
    """One servo's condition as its driver reads it; `kind` is set when it is a fault.

    `flags` names every error bit the servo reported, `cleared` those the driver
    wrote back to zero at once because they are about one packet or a limit, not
    the servo's health (HerkuleX invalid packet, position limit, and the voltage bit a
    servo latched at power-up under its factory limits when the voltage is inside the
    configured ones). `temperature_limit_c` is the servo's own cut-off where the protocol
    has one; `stored_limits` and `active_limits` its EEP and RAM limits (HerkuleX);
    `detail` says what a fault is in words, where the bits alone do not.
    """

    position: int | None = None
    temperature_c: float | None = None
    voltage_v: float | None = None
    load: float | None = None
    flags: tuple[str, ...] = ()  # the protocol's error bits, by name
    kind: FaultKind | None = None
    cleared: tuple[str, ...] = ()
    temperature_limit_c: float | None = None
    stored_limits: ServoLimits | None = None
    active_limits: ServoLimits | None = None
    detail: str = ""


class ServoDriver(Protocol):
    """The servos of one bus in raw units; each call is as few packets as the protocol allows.

    Only the joints layer calls a driver, from the event loop. Any call may raise
    PortUnavailable while the serial adapter is away, and another BusError when
    the bus fails otherwise (BusClosed after close()).
    """

    async def start(self) -> None:
        """Open the bus (a real one keeps retrying the port while it is away)."""
        ...

    async def close(self) -> None:
        """Release the bus; no call is made after this."""
        ...

    async def ping(self, servo_id: int) -> int | None:
        """The model number of a servo that answers, or None when it is silent."""
        ...

    async def read_positions(self, ids: Sequence[int]) -> dict[int, int]:
        """Present raw positions; raises ServoSilent naming the first servo that did not answer."""
        ...

    async def write_goals(self, goals: Mapping[int, tuple[int, float]], step: float) -> None:
        """Raw goal and speed limit (deg/s) per servo, reached within `step` seconds; one packet."""
        ...

    async def set_torque(self, ids: Sequence[int], on: bool) -> None:
        """Torque on or off for every servo in `ids` (on a Maestro, off stops the pulses)."""
        ...

    async def read_health(self, servo_id: int) -> Health:
        """One servo's condition; raises ServoSilent when it does not answer."""
        ...

    async def reset_errors(self, ids: Sequence[int]) -> None:
        """Clear the servos' own latched error state (where the protocol latches one)."""
        ...

    def retried(self) -> int:
        """Replies retried on this bus so far (corrupt or late, then good); 0 when simulated."""
        ...
