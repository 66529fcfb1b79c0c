"""Settings of the servo buses and named joints (the `[servos]` table of kaspar.toml).

A joint's angle in degrees is measured from its servo's centre:
    degrees = direction * (raw - centre) * degrees_per_unit + offset_deg
so `offset_deg` is the joint's angle when the servo sits at its centre, and
`direction = -1` mirrors a servo mounted the other way round (a left arm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import msgspec

Protocol = Literal["dynamixel1", "dynamixel2", "herkulex", "maestro"]


@dataclass(frozen=True, slots=True)
class ServoModel:
    protocol: Protocol
    raw_min: int
    raw_max: int
    raw_centre: int
    degrees_per_unit: float
    model_number: int | None  # what a ping or scan reports, where the protocol has one

    def to_degrees(self, raw: float, direction: int, offset: float) -> float:
        return direction * (raw - self.raw_centre) * self.degrees_per_unit + offset

    def to_raw(self, degrees: float, direction: int, offset: float) -> int:
        raw = round(self.raw_centre + direction * (degrees - offset) / self.degrees_per_unit)
        return min(self.raw_max, max(self.raw_min, raw))

    def reach(self, direction: int, offset: float) -> tuple[float, float]:
        ends = sorted(self.to_degrees(r, direction, offset) for r in (self.raw_min, self.raw_max))
        return ends[0], ends[1]


# From the makers' manuals: AX-12A 0-1023 over 300 degrees; XL430 0-4095 over 360;
# DRS-0101 21-1002 at 0.325 degrees per unit; a Maestro target is in quarter-microseconds
# and an HS-82MG turns about 0.09 degrees per microsecond around 1500 us (992-2000 us).
MODELS: dict[str, ServoModel] = {
    "ax-12a": ServoModel("dynamixel1", 0, 1023, 512, 300 / 1024, 12),
    "xl430-w250": ServoModel("dynamixel2", 0, 4095, 2048, 360 / 4096, 1060),
    "drs-0101": ServoModel("herkulex", 21, 1002, 512, 0.325, 0x0101),
    "hs-82mg": ServoModel("maestro", 3968, 8000, 6000, 0.0225, None),
}

BAUD_RATES = (9600, 19200, 38400, 57600, 115200, 200000, 250000, 400000, 500000,
              666666, 1000000, 2000000, 3000000)


def model_named(model_number: int, protocol: str) -> str | None:
    for name, model in MODELS.items():
        if model.protocol == protocol and model.model_number == model_number:
            return name
    return None


class _Settings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    pass


class BusSettings(_Settings):
    name: str
    port: str  # a stable udev name such as /dev/kaspar-body
    protocol: Protocol
    baud: int = 57600
    # Added to the wire time of every transaction: the servo's return delay,
    # the USB latency timer and scheduling. 20 ms covers an FTDI at 1 ms latency.
    timeout_margin_ms: float = 20.0
    retries: int = 2

    def __post_init__(self) -> None:
        if not self.name.strip():
            raise ValueError("expected a bus name, found an empty string")
        if self.baud not in BAUD_RATES:
            rates = ", ".join(map(str, BAUD_RATES))
            raise ValueError(f"baud: expected one of {rates}, found {self.baud}")
        if not 0 < self.timeout_margin_ms <= 1000:
            raise ValueError(
                f"timeout_margin_ms: expected 0 < ms <= 1000, found {self.timeout_margin_ms}"
            )
        if not 0 <= self.retries <= 10:
            raise ValueError(f"retries: expected 0 to 10, found {self.retries}")


class JointSettings(_Settings):
    name: str
    bus: str
    id: int  # servo id, or channel on a Maestro
    model: Literal["ax-12a", "xl430-w250", "drs-0101", "hs-82mg"]
    range_deg: tuple[float, float]  # the safe range: nothing is commanded outside it
    offset_deg: float = 0.0
    direction: Literal[1, -1] = 1
    max_speed_dps: float = 60.0
    rest_deg: float = 0.0
    group: str = "body"

    def __post_init__(self) -> None:
        low, high = self.range_deg
        if not all(math.isfinite(v) for v in (low, high, self.offset_deg, self.rest_deg)):
            raise ValueError(f"joint {self.name!r}: angles must be finite numbers")
        if not low < high:
            raise ValueError(f"joint {self.name!r}: range_deg must be [low, high] with low < high")
        if not low <= self.rest_deg <= high:
            raise ValueError(
                f"joint {self.name!r}: rest_deg {self.rest_deg} is outside "
                f"range_deg [{low}, {high}]"
            )
        if not 0 < self.max_speed_dps <= 720:
            raise ValueError(f"joint {self.name!r}: max_speed_dps expected 0 < v <= 720")
        if not 0 <= self.id <= 253:
            raise ValueError(f"joint {self.name!r}: id expected 0 to 253, found {self.id}")
        reach_low, reach_high = MODELS[self.model].reach(self.direction, self.offset_deg)
        if low < reach_low - 1e-6 or high > reach_high + 1e-6:
            raise ValueError(
                f"joint {self.name!r}: range_deg [{low}, {high}] goes beyond what a {self.model} "
                f"can reach with this offset and direction [{reach_low:.1f}, {reach_high:.1f}]"
            )

    @property
    def servo(self) -> ServoModel:
        return MODELS[self.model]


class ServoSettings(_Settings):
    # "sim" runs the simulated servos (tests, demos, a laptop); "real" drives the buses.
    backend: Literal["real", "sim"] = "sim"
    # What a latched fault does to the robot: "hold" keeps every healthy joint where it
    # is; "torque_off" lets the whole robot go limp. The faulty servo is always freed.
    safe_action: Literal["torque_off", "hold"] = "hold"
    poll_interval_s: float = 1.0  # temperature, load, voltage and error bits
    control_hz: float = 50.0  # rate of goal updates during a move
    max_temperature_c: float = 65.0  # a fault before the servo's own shutdown
    buses: tuple[BusSettings, ...] = ()
    joints: tuple[JointSettings, ...] = ()

    def __post_init__(self) -> None:
        if not 0.05 <= self.poll_interval_s <= 60:
            raise ValueError(f"poll_interval_s: expected 0.05 to 60, found {self.poll_interval_s}")
        if not 1 <= self.control_hz <= 200:
            raise ValueError(f"control_hz: expected 1 to 200, found {self.control_hz}")
        buses = {}
        for index, bus in enumerate(self.buses):
            if bus.name in buses:
                raise ValueError(f"buses[{index}]: bus name {bus.name!r} is used twice")
            if any(other.port == bus.port for other in buses.values()):
                raise ValueError(
                    f"buses[{index}] ({bus.name}): port {bus.port} is used by another bus"
                )
            buses[bus.name] = bus
        seen_names: set[str] = set()
        seen_ids: dict[tuple[str, int], str] = {}
        for index, joint in enumerate(self.joints):
            where = f"joints[{index}] ({joint.name})"
            if joint.name in seen_names:
                raise ValueError(f"{where}: joint name {joint.name!r} is used twice")
            seen_names.add(joint.name)
            bus = buses.get(joint.bus)
            if bus is None:
                known = ", ".join(buses) or "none configured"
                raise ValueError(f"{where}: bus {joint.bus!r} is not a configured bus ({known})")
            if joint.servo.protocol != bus.protocol:
                raise ValueError(
                    f"{where}: a {joint.model} does not speak {bus.protocol} (bus {bus.name})"
                )
            other = seen_ids.get((joint.bus, joint.id))
            if other is not None:
                raise ValueError(f"{where}: id {joint.id} on bus {joint.bus} is also {other}")
            seen_ids[(joint.bus, joint.id)] = joint.name
            if joint.group in seen_names and joint.group != joint.name:
                raise ValueError(f"{where}: group {joint.group!r} is also a joint name")
        if self.backend == "real" and not self.joints:
            raise ValueError("backend 'real' needs at least one joint")

    def bus(self, name: str) -> BusSettings:
        return next(bus for bus in self.buses if bus.name == name)

    @property
    def groups(self) -> dict[str, tuple[str, ...]]:
        groups: dict[str, list[str]] = {}
        for joint in self.joints:
            groups.setdefault(joint.group, []).append(joint.name)
        return {name: tuple(members) for name, members in groups.items()}
