"""Settings of the servo buses and named joints (the `[servos]` table of kaspar.toml).

A joint's angle in degrees is measured from its servo's centre:
    degrees = direction * (raw - centre) * degrees_per_unit + offset_deg
so `offset_deg` is the joint's angle when the servo sits at its centre, and
`direction = -1` mirrors a servo mounted the other way round (a left arm). The
centre is the model's (512, 1500 us) unless the joint gives `centre_raw`: the
published robots set each servo's centre (Kaspar 3's mouth sits at raw 620, and
each robot's eyes at their own microseconds).

Virtual joints (`[[servos.virtual_joints]]`) name several real joints moved as one
(EYES_YAW, EYELIDS): each real joint goes to its ratio times the virtual joint's
angle. A coupling (`[[servos.couplings]]`) makes a joint follow another: its goal
is its own plus ratio times how far its leader is from the leader's rest (a lid
that follows its eyeball's pitch). Both are expanded by `ServoSettings.realise`,
the one place that turns a pose into real joints' goals.

Validation: a key's own limits are on its field (a Literal, or msgspec.Meta,
which msgspec holds while decoding and kasparctl.config words as "expected
X, found Y" from the Meta: its bounds, and `extra` "unit" or "expected").
Rules that tie several keys together are each class's `__post_init__`, in
one place, raising SettingsError (a ValueError, which msgspec reports at the
table's key).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Literal

import msgspec

from hal.errors import SettingsError, UnknownBus

Protocol = Literal["dynamixel1", "dynamixel2", "herkulex", "maestro"]
ModelName = Literal["ax-12a", "xl430-w250", "drs-0101", "drs-0201", "hs-82mg"]
Baud = Literal[
    9600, 19200, 38400, 57600, 115200, 200000, 250000, 400000, 500000,
    666666, 1000000, 2000000, 3000000,
]  # fmt: skip
BAUD_RATES: tuple[int, ...] = typing.get_args(Baud)
# The most a HerkuleX voltage register holds: 255 counts of 0.074 V (manual, RAM 6/7/54).
VOLTAGE_REGISTER_MAX_V = 18.87

# A number that is neither infinite nor NaN (both fall outside these bounds).
Finite = Annotated[
    float,
    msgspec.Meta(
        ge=-sys.float_info.max, le=sys.float_info.max, extra={"expected": "a finite number"}
    ),
]


@dataclass(frozen=True, slots=True)
class ServoModel:
    """A servo model's raw position units, how they map to degrees, and what it can report.

    `raw_min`..`raw_max` is what it can be commanded to; `sensor_min`..`sensor_max`
    what a position reading can be (anything else is an impossible reading, a
    fault, never "ok"); `off_reading` is the reading of a servo whose position is
    unknown (a hobby servo without pulses), None where every reading is a position.
    """

    protocol: Protocol
    raw_min: int
    raw_max: int
    raw_centre: int
    degrees_per_unit: float
    model_number: int | None  # what a ping or scan reports, where the protocol has one
    sensor_min: int
    sensor_max: int
    off_reading: int | None = None

    def readable(self, raw: int) -> bool:
        """True when `raw` is a reading this servo can give (a position, or its off reading)."""
        return raw == self.off_reading or self.sensor_min <= raw <= self.sensor_max

    def to_degrees(self, raw: float, direction: int, offset: float) -> float:
        """Degrees of a joint whose servo reads `raw`, given its direction (+1/-1) and offset."""
        return direction * (raw - self.raw_centre) * self.degrees_per_unit + offset

    def to_raw(self, degrees: float, direction: int, offset: float) -> int:
        """The raw goal for `degrees`, rounded and clamped to what the servo can take."""
        raw = round(self.raw_centre + direction * (degrees - offset) / self.degrees_per_unit)
        return min(self.raw_max, max(self.raw_min, raw))

    def reach(self, direction: int, offset: float) -> tuple[float, float]:
        """(lowest, highest) degrees the servo can reach with this direction and offset."""
        ends = sorted(self.to_degrees(r, direction, offset) for r in (self.raw_min, self.raw_max))
        return ends[0], ends[1]


# From the makers' manuals: AX-12A 0-1023 over 300 degrees; XL430 0-4095 over 360
# (position mode); DRS-0101 and DRS-0201 21-1002 commandable (EEP min/max position
# defaults) of a 10-bit reading, 0.325 degrees per unit; a Maestro target is in
# quarter-microseconds, 992-2000 us by default, and an HS-82MG turns about 0.09
# degrees per microsecond around 1500 us. A Maestro channel without pulses reads 0.
MODELS: dict[str, ServoModel] = {
    "ax-12a": ServoModel("dynamixel1", 0, 1023, 512, 300 / 1024, 12, 0, 1023),
    "xl430-w250": ServoModel("dynamixel2", 0, 4095, 2048, 360 / 4096, 1060, 0, 4095),
    "drs-0101": ServoModel("herkulex", 21, 1002, 512, 0.325, 0x0101, 0, 1023),
    "drs-0201": ServoModel("herkulex", 21, 1002, 512, 0.325, 0x0102, 0, 1023),
    "hs-82mg": ServoModel("maestro", 3968, 8000, 6000, 0.0225, None, 3968, 8000, off_reading=0),
}


@functools.cache
def centred(model: str, centre_raw: int | None) -> ServoModel:
    """The model `model` with its centre moved to `centre_raw` (its own centre if None)."""
    base = MODELS[model]
    return base if centre_raw is None else dataclasses.replace(base, raw_centre=centre_raw)


def model_named(model_number: int, protocol: str) -> str | None:
    """The MODELS name of a servo that reports `model_number` on `protocol`; None if unknown."""
    for name, model in MODELS.items():
        if model.protocol == protocol and model.model_number == model_number:
            return name
    return None


class _Settings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Strict (unknown keys rejected) and immutable.

    Subclasses repeat frozen=True only for mypy, which does not see it inherited.
    """


class BusSettings(_Settings, frozen=True):
    """One serial port and the protocol its servos speak."""

    name: Annotated[str, msgspec.Meta(pattern=r"\S", extra={"expected": "a bus name"})]
    port: str  # a stable udev name such as /dev/kaspar-body
    protocol: Protocol
    baud: Baud = 57600
    # Added to the wire time of every transaction: the servo's return delay,
    # the USB latency timer and scheduling. 20 ms covers an FTDI at 1 ms latency.
    timeout_margin_ms: Annotated[float, msgspec.Meta(gt=0, le=1000, extra={"unit": "ms"})] = 20.0
    retries: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2
    # HerkuleX only: the supply limits written to every servo's RAM (6, 7) at start, so
    # that a battery above the factory limits (6.7-10.1 V) is not a voltage error. The
    # servos' EEP is never written for them (only by `kasparctl servos set-voltage`).
    min_voltage_v: Annotated[float, msgspec.Meta(ge=0, le=VOLTAGE_REGISTER_MAX_V,
                                                 extra={"unit": "V"})] | None = None
    max_voltage_v: Annotated[float, msgspec.Meta(ge=0, le=VOLTAGE_REGISTER_MAX_V,
                                                 extra={"unit": "V"})] | None = None

    def __post_init__(self) -> None:
        """Voltage limits come in pairs, low below high, on a HerkuleX bus only."""
        limits = (self.min_voltage_v, self.max_voltage_v)
        if limits == (None, None):
            return
        where = f"bus {self.name!r}"
        if self.protocol != "herkulex":
            raise SettingsError(
                f"{where}: min_voltage_v and max_voltage_v are HerkuleX registers; "
                f"a {self.protocol} bus has none"
            )
        if None in limits:
            raise SettingsError(f"{where}: give both min_voltage_v and max_voltage_v, or neither")
        low, high = limits
        assert low is not None and high is not None
        if not low < high:
            raise SettingsError(
                f"{where}: min_voltage_v {low} must be below max_voltage_v {high}"
            )

    @property
    def voltage_limits(self) -> tuple[float, float] | None:
        """(min, max) volts for the servos' RAM, or None when the servos keep their own."""
        if self.min_voltage_v is None or self.max_voltage_v is None:
            return None
        return self.min_voltage_v, self.max_voltage_v


class BatterySettings(_Settings, frozen=True):
    """`[servos.battery]`: which servo reads the battery, and when Kaspar says it is low."""

    joint: Annotated[str, msgspec.Meta(pattern=r"\S", extra={"expected": "a joint name"})]
    warn_below_v: Annotated[float, msgspec.Meta(gt=0, le=VOLTAGE_REGISTER_MAX_V,
                                                extra={"unit": "V"})]


class JointSettings(_Settings, frozen=True):
    """One named joint: its servo, safe range, mounting and speed limit, in degrees."""

    name: str
    bus: str
    id: Annotated[int, msgspec.Meta(ge=0, le=253)]  # servo id, or channel on a Maestro
    model: ModelName
    range_deg: tuple[Finite, Finite]  # the safe range: nothing is commanded outside it
    offset_deg: Finite = 0.0
    direction: Literal[1, -1] = 1
    max_speed_dps: Annotated[float, msgspec.Meta(gt=0, le=720, extra={"unit": "deg/s"})] = 60.0
    rest_deg: Finite = 0.0
    group: str = "body"
    # The raw position at which the joint reads offset_deg; the model's centre if unset.
    centre_raw: int | None = None

    def __post_init__(self) -> None:
        """Range, rest and reach agree; SettingsError names the joint otherwise."""
        model = MODELS[self.model]
        if self.centre_raw is not None and not model.raw_min <= self.centre_raw <= model.raw_max:
            unit = " (quarter-microseconds: 1500 us is 6000)" if model.protocol == "maestro" else ""
            raise SettingsError(
                f"joint {self.name!r}: centre_raw {self.centre_raw} is outside what a "
                f"{self.model} can take, {model.raw_min} to {model.raw_max}{unit}"
            )
        low, high = self.range_deg
        if not low < high:
            raise SettingsError(
                f"joint {self.name!r}: range_deg must be [low, high] with low < high"
            )
        if not low <= self.rest_deg <= high:
            raise SettingsError(
                f"joint {self.name!r}: rest_deg {self.rest_deg} is outside "
                f"range_deg [{low}, {high}]"
            )
        reach_low, reach_high = self.servo.reach(self.direction, self.offset_deg)
        if low < reach_low - 1e-6 or high > reach_high + 1e-6:
            raise SettingsError(
                f"joint {self.name!r}: range_deg [{low}, {high}] goes beyond what a {self.model} "
                f"can reach with this offset and direction [{reach_low:.1f}, {reach_high:.1f}]"
            )

    @property
    def servo(self) -> ServoModel:
        """The model of the joint's servo (units, protocol), centred at centre_raw if set."""
        return centred(self.model, self.centre_raw)


Ratio = Annotated[
    float,
    msgspec.Meta(ge=-10, le=10, extra={"expected": "a ratio from -10 to 10, not 0"}),
]


class VirtualJointSettings(_Settings, frozen=True):
    """Several real joints moved as one (both eyes' yaw): each to ratio * the angle."""

    name: Annotated[str, msgspec.Meta(pattern=r"^[a-z][a-z0-9_]*$",
                                      extra={"expected": "a name of a-z, 0-9 and _"})]
    drives: dict[str, Ratio]  # real joint -> ratio


class CouplingSettings(_Settings, frozen=True):
    """A joint that follows another: its goal plus ratio * (leader - leader's rest)."""

    joint: str
    follows: str
    ratio: Ratio


class ServoSettings(_Settings, frozen=True):
    """The whole `[servos]` table: backend, safety, rates, buses and joints."""

    # "sim" runs the simulated servos (tests, demos, a laptop); "real" drives the buses.
    backend: Literal["real", "sim"] = "sim"
    # What a latched fault does to the robot: "hold" keeps every healthy joint where it
    # is; "torque_off" lets the whole robot go limp. The faulty servo is always freed.
    safe_action: Literal["torque_off", "hold"] = "hold"
    # Temperature, load, voltage and error bits are read this often.
    poll_interval_s: Annotated[float, msgspec.Meta(ge=0.05, le=60, extra={"unit": "s"})] = 1.0
    # Rate of goal updates during a move.
    control_hz: Annotated[float, msgspec.Meta(ge=1, le=200, extra={"unit": "Hz"})] = 50.0
    # A fault before the servo's own shutdown; a warning is logged this many degrees before.
    max_temperature_c: Annotated[float, msgspec.Meta(ge=20, le=120, extra={"unit": "C"})] = 65.0
    buses: tuple[BusSettings, ...] = ()
    joints: tuple[JointSettings, ...] = ()
    virtual_joints: tuple[VirtualJointSettings, ...] = ()
    couplings: tuple[CouplingSettings, ...] = ()
    battery: BatterySettings | None = None  # absent: the battery is not watched

    def __post_init__(self) -> None:
        """Buses and joints agree with each other; SettingsError names the entry otherwise."""
        buses: dict[str, BusSettings] = {}
        for index, bus in enumerate(self.buses):
            if bus.name in buses:
                raise SettingsError(f"buses[{index}]: bus name {bus.name!r} is used twice")
            if any(other.port == bus.port for other in buses.values()):
                raise SettingsError(
                    f"buses[{index}] ({bus.name}): port {bus.port} is used by another bus"
                )
            buses[bus.name] = bus
        seen_names: set[str] = set()
        seen_ids: dict[tuple[str, int], str] = {}
        for index, joint in enumerate(self.joints):
            where = f"joints[{index}] ({joint.name})"
            if joint.name in seen_names:
                raise SettingsError(f"{where}: joint name {joint.name!r} is used twice")
            seen_names.add(joint.name)
            joint_bus = buses.get(joint.bus)
            if joint_bus is None:
                known = ", ".join(buses) or "none configured"
                raise SettingsError(
                    f"{where}: bus {joint.bus!r} is not a configured bus ({known})"
                )
            if joint.servo.protocol != joint_bus.protocol:
                raise SettingsError(
                    f"{where}: a {joint.model} does not speak {joint_bus.protocol} "
                    f"(bus {joint_bus.name})"
                )
            other = seen_ids.get((joint.bus, joint.id))
            if other is not None:
                raise SettingsError(f"{where}: id {joint.id} on bus {joint.bus} is also {other}")
            seen_ids[(joint.bus, joint.id)] = joint.name
            if joint.group in seen_names and joint.group != joint.name:
                raise SettingsError(f"{where}: group {joint.group!r} is also a joint name")
        if self.backend == "real" and not self.joints:
            raise SettingsError("backend 'real' needs at least one joint")
        self._check_virtual(seen_names)
        self._check_couplings(seen_names)
        self._check_battery(buses)

    def _check_virtual(self, real: set[str]) -> None:
        names: set[str] = set()
        groups = {joint.group for joint in self.joints}
        for index, virtual in enumerate(self.virtual_joints):
            where = f"virtual_joints[{index}] ({virtual.name})"
            if virtual.name in real or virtual.name in names or virtual.name in groups:
                raise SettingsError(
                    f"{where}: name {virtual.name!r} is already a joint, group or virtual joint"
                )
            names.add(virtual.name)
            if not virtual.drives:
                raise SettingsError(f"{where}: drives: expected at least one real joint")
            for joint, ratio in virtual.drives.items():
                if joint not in real:
                    raise SettingsError(
                        f"{where}: drives.{joint}: expected a configured real joint "
                        f"({', '.join(sorted(real)) or 'none configured'}), found {joint!r}"
                    )
                if ratio == 0:
                    raise SettingsError(f"{where}: drives.{joint}: expected a ratio other than 0")

    def _check_couplings(self, real: set[str]) -> None:
        followers: set[str] = set()
        leaders = {c.follows for c in self.couplings}
        for index, coupling in enumerate(self.couplings):
            where = f"couplings[{index}] ({coupling.joint})"
            for key in ("joint", "follows"):
                name = getattr(coupling, key)
                if name not in real:
                    raise SettingsError(
                        f"{where}: {key}: expected a configured real joint "
                        f"({', '.join(sorted(real)) or 'none configured'}), found {name!r}"
                    )
            if coupling.joint == coupling.follows:
                raise SettingsError(f"{where}: follows: a joint cannot follow itself")
            if coupling.joint in followers:
                raise SettingsError(f"{where}: joint: {coupling.joint!r} already follows a joint")
            if coupling.joint in leaders:
                # One step only: a chain would make a lid depend on a joint two away.
                raise SettingsError(
                    f"{where}: joint: {coupling.joint!r} is itself followed: no chains"
                )
            if coupling.ratio == 0:
                raise SettingsError(f"{where}: ratio: expected a ratio other than 0")
            followers.add(coupling.joint)

    @property
    def virtual(self) -> dict[str, Mapping[str, float]]:
        """Virtual joint name -> {real joint: ratio}."""
        return {v.name: v.drives for v in self.virtual_joints}

    def expand(self, pose: Mapping[str, float]) -> dict[str, float]:
        """`pose` in real joints: each virtual joint replaced by the joints it drives.

        SettingsError for a name that is neither, or a real joint set twice (by name
        and through a virtual joint, or by two virtual joints).
        """
        virtual = self.virtual
        real = {joint.name for joint in self.joints}
        out: dict[str, float] = {}
        via: dict[str, str] = {}
        for name, degrees in pose.items():
            targets = virtual.get(name)
            if targets is None:
                if name not in real:
                    raise SettingsError(f"unknown joint {name!r}")
                targets = {name: 1.0}
            for joint, ratio in targets.items():
                if joint in out:
                    raise SettingsError(
                        f"joint {joint!r} is set twice: by {via[joint]} and by {name}"
                    )
                out[joint] = ratio * degrees
                via[joint] = name
        return out

    def realise(
        self, pose: Mapping[str, float], where: Mapping[str, float] | None = None
    ) -> dict[str, float]:
        """The real joints' goals for `pose`: virtual joints expanded, couplings applied.

        A follower's own value is its value in the pose, else `where` it is (its rest
        if unknown); it moves whenever it or its leader is in the pose, so a move of
        the eyeball's pitch carries the lid with it.
        """
        goals = self.expand(pose)
        if not self.couplings:
            return goals
        rests = {joint.name: joint.rest_deg for joint in self.joints}
        known = where or {}
        for coupling in self.couplings:
            follower, leader = coupling.joint, coupling.follows
            if follower not in goals and leader not in goals:
                continue
            own = goals.get(follower, known.get(follower, rests[follower]))
            lead = goals.get(leader, known.get(leader, rests[leader]))
            goals[follower] = own + coupling.ratio * (lead - rests[leader])
        return goals

    def _check_battery(self, buses: dict[str, BusSettings]) -> None:
        if self.battery is None:
            return
        joint = next((j for j in self.joints if j.name == self.battery.joint), None)
        if joint is None:
            known = ", ".join(j.name for j in self.joints) or "none configured"
            raise SettingsError(
                f"battery: joint {self.battery.joint!r} is not a configured joint ({known})"
            )
        if joint.servo.protocol == "maestro":
            raise SettingsError(
                f"battery: joint {joint.name!r} is a hobby servo on a Maestro, which reads no "
                "voltage; name a joint whose servo reports its supply (HerkuleX, Dynamixel)"
            )
        limits = buses[joint.bus].voltage_limits
        if limits is not None and not limits[0] <= self.battery.warn_below_v <= limits[1]:
            raise SettingsError(
                f"battery: warn_below_v {self.battery.warn_below_v} is outside bus "
                f"{joint.bus!r}'s min_voltage_v..max_voltage_v {limits[0]}..{limits[1]}"
            )

    def bus(self, name: str) -> BusSettings:
        """The bus called `name`; UnknownBus (a KeyError) if there is none."""
        for bus in self.buses:
            if bus.name == name:
                return bus
        raise UnknownBus(f"unknown bus {name!r}")

    @property
    def groups(self) -> dict[str, tuple[str, ...]]:
        """Group name -> its joints, in the order the joints are configured."""
        groups: dict[str, list[str]] = {}
        for joint in self.joints:
            groups.setdefault(joint.group, []).append(joint.name)
        return {name: tuple(members) for name, members in groups.items()}
