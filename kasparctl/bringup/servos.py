"""The servos as bring-up sees them: who answers on a bus, and every configured joint's state.

`scan` pings every id on one port (nothing moves); `read_joints` reads every
configured joint: position, temperature, voltage, error bits and the readings a
servo cannot give. Both are what `kasparctl servos scan` and `servos read` print.
"""

from __future__ import annotations

from typing import Any

from hal.clock import MonotonicClock
from hal.errors import BusError
from hal.servos.api import JointStatus, ServoLimits
from hal.servos.bus import SerialBus
from hal.servos.drivers import DRIVERS
from hal.servos.joints import Joints
from hal.servos.settings import JointSettings, model_named
from hal.servos.sim import SimServos
from kasparctl.config import load_config

# The ids a scan tries by default, per protocol (channels on a Maestro).
DEFAULT_IDS = {
    "dynamixel1": (1, 30),
    "dynamixel2": (1, 30),
    "herkulex": (0, 30),
    "maestro": (0, 11),
}


async def scan(
    port: str, protocol: str, baud: int, ids: list[int], margin: float
) -> list[dict[str, Any]]:
    """Ping every id on one port; one row (id, model number, model) per servo that answers."""
    # No retries: a missing id costs one timeout, and most ids are missing.
    bus = SerialBus("scan", port, baud, timeout_margin=margin, retries=0)
    driver = DRIVERS[protocol](bus)
    await driver.start()
    found = []
    try:
        if not bus.connected:
            raise BusError(bus.unavailable())
        for servo_id in ids:
            model_number = await driver.ping(servo_id)
            if model_number is None:
                continue
            position = (await driver.read_positions([servo_id]))[servo_id]
            name = model_named(model_number, protocol) or (
                "maestro" if protocol == "maestro" else f"model {model_number}"
            )
            found.append(
                {"id": servo_id, "model": name, "model_number": model_number, "position": position}
            )
    finally:
        await driver.close()
    return found


async def read_joints(config_path: str) -> list[dict[str, Any]]:
    """Every configured joint's position, torque, temperature, voltage, error bits and problems.

    Moves nothing. On a HerkuleX bus it sets the servos' ACK policy and clears
    packet error bits, as the driver always does (both reported).
    """
    config = load_config(config_path, poses=False)
    settings, clock = config.servos, MonotonicClock()
    joints = (
        Joints.from_settings(settings, clock)
        if settings.backend == "real"
        else SimServos(settings, clock)
    )
    await joints.start(poll=False, read=False)
    try:
        statuses = await joints.survey()
    finally:
        await joints.close()
    by_name = {j.name: j for j in settings.joints}
    rows = [status_row(s, by_name[s.joint]) for s in statuses]
    battery = settings.battery
    for row in rows:
        if battery is not None and row["joint"] == battery.joint:
            volts = row["voltage_v"]
            row["battery"] = {
                "voltage_v": volts,
                "warn_below_v": battery.warn_below_v,
                "low": volts is not None and volts < battery.warn_below_v,
            }
    return rows


def format_battery(rows: list[dict[str, Any]]) -> str | None:
    """The battery line of `servos read`, or None when no [servos.battery] is configured."""
    for row in rows:
        battery = row.get("battery")
        if battery is None:
            continue
        volts = battery["voltage_v"]
        reading = "not read" if volts is None else f"{volts:.1f} V"
        low = "  LOW" if battery["low"] else ""
        return (f"battery {reading} (read by {row['joint']}; "
                f"warning below {battery['warn_below_v']:.1f} V){low}")
    return None


def status_row(status: JointStatus, joint: JointSettings) -> dict[str, Any]:
    """One joint as `servos read --json` prints it; `status` is "ok" only when healthy."""
    problems = list(status.problems)
    if status.fault is not None:
        problems.insert(0, f"{status.fault.kind.value}: {status.fault.detail}")
    if status.flags:
        problems.append("error bits: " + ", ".join(status.flags))
    return {
        "joint": status.joint,
        "bus": joint.bus,
        "id": joint.id,
        "model": joint.model,
        "position_deg": None if status.position_deg is None else round(status.position_deg, 1),
        "raw_position": status.raw_position,
        "temperature_c": None if status.temperature_c is None else round(status.temperature_c, 1),
        "voltage_v": None if status.voltage_v is None else round(status.voltage_v, 1),
        "flags": list(status.flags),
        "limits_eep": _limits(status.stored_limits),
        "limits_ram": _limits(status.active_limits),
        "problems": problems,
        "status": "ok" if status.healthy else "; ".join(problems),
    }


def _limits(limits: ServoLimits | None) -> dict[str, float | None] | None:
    if limits is None:
        return None
    hot = limits.max_temperature_c
    return {
        "max_temperature_c": None if hot is None else round(hot, 2),
        "min_voltage_v": round(limits.min_voltage_v, 2),
        "max_voltage_v": round(limits.max_voltage_v, 2),
    }


def _limits_text(limits: dict[str, float | None]) -> str:
    hot = limits["max_temperature_c"]
    return (f"{'?' if hot is None else f'{hot:.0f}'} C, "
            f"{limits['min_voltage_v']:.1f}-{limits['max_voltage_v']:.1f} V")


def format_row(row: dict[str, Any]) -> str:
    """One joint as a line of text: a reading the servo cannot give is marked with '!'."""
    impossible = " ".join(row["problems"])
    position = "   --  " if row["position_deg"] is None else f"{row['position_deg']:7.1f}"
    if row["raw_position"] is not None and "position reading" in impossible:
        position = f"!{row['raw_position']:>6}"
    temperature = "" if row["temperature_c"] is None else f"{row['temperature_c']:.1f} C"
    if temperature and "temperature" in impossible:
        temperature = "!" + temperature
    voltage = "" if row["voltage_v"] is None else f"{row['voltage_v']:.1f} V"
    if voltage and "voltage" in impossible:
        voltage = "!" + voltage
    limits = ""
    if row.get("limits_eep") is not None:
        limits += f"  [EEP 11-13: {_limits_text(row['limits_eep'])}"
        if row.get("limits_ram") is not None:
            limits += f"; RAM 5-7: {_limits_text(row['limits_ram'])}"
        limits += "]"
    return (
        f"{row['joint']:<20} {row['bus']:<6} id {row['id']:3d} {position} deg "
        f"{temperature:>7} {voltage:>7}  {row['status']}{limits}"
    )


