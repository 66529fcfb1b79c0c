"""The servos as bring-up sees them: who answers on a bus, and every configured joint's state.

`scan` pings every id on one port (nothing moves); `read_joints` reads every
configured joint: position, temperature, voltage, error bits and the readings a
servo cannot give. Both are what `kasparctl servos scan` and `servos read` print.
"""

from __future__ import annotations

from typing import Any

from hal.clock import MonotonicClock
from hal.errors import BusError
from hal.servos import herkulex as hx
from hal.servos.api import JointStatus, ServoLimits
from hal.servos.bus import SerialBus
from hal.servos.drivers import (
    DRIVERS,
    LATE_MARGIN_FACTOR,
    BusDriver,
    HerkulexDriver,
    driver_for,
)
from hal.servos.joints import Joints
from hal.servos.settings import JointSettings, model_named
from hal.servos.sim import SimServos
from kasparctl.bringup.engineer import BringUpError
from kasparctl.config import load_config

# The ids a scan tries by default, per protocol (channels on a Maestro): every id the
# protocol allows, as its codec states it (a factory-new HerkuleX answers at 253).
DEFAULT_IDS: dict[str, tuple[int, int]] = {
    protocol: driver.id_range for protocol, driver in DRIVERS.items()
}
# Reply time allowed beyond the wire time while scanning: a servo answers within a
# millisecond or two, and most ids of a scan are missing, each costing one timeout.
SCAN_MARGIN_MS = 10.0
# How long a HerkuleX may take to boot after REBOOT before its new id must answer.
REBOOT_WAIT_S = 3.0
REBOOT_POLL_S = 0.05


async def _open(port: str, protocol: str, baud: int, margin: float) -> BusDriver:
    # No retries: a missing id costs one timeout, and most ids are missing.
    bus = SerialBus("scan", port, baud, timeout_margin=margin, retries=0)
    driver = DRIVERS[protocol](bus)
    await driver.start()
    if not bus.connected:
        await driver.close()
        raise BusError(bus.unavailable())
    return driver


async def _found(driver: BusDriver, protocol: str, ids: list[int]) -> list[dict[str, Any]]:
    """Who answers among `ids` (the protocol's shortest exchange), then each one's model.

    The few that answered are asked their model and position with a margin
    LATE_MARGIN_FACTOR times the scan's: a servo that answered late must not be lost.
    """
    answering = await driver.answering(ids)
    margin = driver.bus.timeout_margin
    driver.bus.timeout_margin = margin * LATE_MARGIN_FACTOR
    found = []
    try:
        for servo_id in answering:
            model_number = await driver.ping(servo_id)
            if model_number is None:
                continue  # answered once, then not: a flaky link, not a servo to name
            position = (await driver.read_positions([servo_id]))[servo_id]
            name = model_named(model_number, protocol) or (
                "maestro" if protocol == "maestro" else f"model {model_number}"
            )
            found.append({"id": servo_id, "model": name, "model_number": model_number,
                          "position": position})
    finally:
        driver.bus.timeout_margin = margin
    return found


async def scan(
    port: str, protocol: str, baud: int, ids: list[int], margin: float
) -> list[dict[str, Any]]:
    """Ping every id on one port; one row (id, model number, model) per servo that answers.

    Each id is asked once in the protocol's shortest exchange (HerkuleX: STAT); only
    those that answer are asked their model and position. Nothing moves.
    """
    driver = await _open(port, protocol, baud, margin)
    try:
        return await _found(driver, protocol, ids)
    finally:
        await driver.close()


def _listed(found: list[dict[str, Any]]) -> str:
    return ", ".join(f"{s['id']} ({s['model']})" for s in found) or "no servo"


async def set_id(
    port: str, baud: int, servo_id: int, new_id: int, margin: float
) -> dict[str, Any]:
    """Give the HerkuleX servo at `servo_id` the id `new_id`: EEP 6, read back, reboot, rescan.

    The whole bus is scanned first: BringUpError when nothing answers at `servo_id`,
    or when `new_id` is taken (both name what was found). Returns the id's change and
    the bus as scanned after the reboot.
    """
    low, high = DEFAULT_IDS["herkulex"]
    if not low <= new_id <= high or new_id == servo_id:
        raise BringUpError(f"the new id must be {low}-{high} and not {servo_id}, found {new_id}")
    driver = await _open(port, "herkulex", baud, margin)
    assert isinstance(driver, HerkulexDriver)
    everything = list(range(low, high + 1))
    try:
        before = await _found(driver, "herkulex", everything)
        ids = {s["id"]: s for s in before}
        if servo_id not in ids:
            raise BringUpError(
                f"no servo answers at id {servo_id} on {port} ({baud} baud); "
                f"found: {_listed(before)}"
            )
        if new_id in ids:
            taken = ids[new_id]
            raise BringUpError(
                f"id {new_id} is already on the bus ({taken['model']} at position "
                f"{taken['position']}): two servos with one id would answer together; "
                f"found: {_listed(before)}"
            )
        await driver.write_id(servo_id, new_id)
        written = (await driver.read_eep(servo_id, hx.Eep.ID, 1))[0]
        if written != new_id:
            raise BringUpError(
                f"servo {servo_id} holds id {written} in EEP 6 after the write of {new_id}: "
                "nothing rebooted; check the wiring and try again"
            )
        await driver.reboot(servo_id)
        clock = MonotonicClock()
        deadline = clock.now() + REBOOT_WAIT_S
        while not await driver.answers(new_id):
            if clock.now() >= deadline:
                raise BringUpError(
                    f"servo {servo_id} took id {new_id} in EEP but does not answer at it "
                    f"{REBOOT_WAIT_S:.0f} s after its reboot: power it off and on, then scan"
                )
            await clock.sleep(REBOOT_POLL_S)
        after = await _found(driver, "herkulex", everything)
    finally:
        await driver.close()
    if not any(s["id"] == new_id for s in after) or any(s["id"] == servo_id for s in after):
        raise BringUpError(
            f"after the reboot the bus has {_listed(after)}, expected id {new_id} "
            f"in place of {servo_id}"
        )
    return {"id": servo_id, "new_id": new_id, "eep_id": written, "found": after}


async def set_voltage_eep(config_path: str) -> list[dict[str, Any]]:
    """Write each HerkuleX bus's min/max_voltage_v into its servos' EEP (12, 13), read back.

    The engineer's explicit request: the daemon only ever writes RAM. With the limits
    in EEP a servo powers up inside them (no voltage bit at power-up). One row per
    configured joint of such a bus; BringUpError when the configuration has none.
    """
    config = load_config(config_path, poses=False)
    settings = config.servos
    if settings.backend != "real":
        raise BringUpError(f"{config_path}: servos.backend is {settings.backend!r}; set-voltage "
                           "writes the real servos' EEP")
    buses = [bus for bus in settings.buses if bus.voltage_limits is not None]
    if not buses:
        raise BringUpError(f"{config_path}: no HerkuleX bus has min_voltage_v and max_voltage_v")
    rows = []
    for bus in buses:
        limits = bus.voltage_limits
        assert limits is not None
        wanted = bytes(hx.raw_voltage(v) for v in limits)
        driver = driver_for(bus)
        assert isinstance(driver, HerkulexDriver)
        await driver.start()
        try:
            if not driver.bus.connected:
                raise BusError(driver.bus.unavailable())
            for joint in (j for j in settings.joints if j.bus == bus.name):
                await driver.write_voltage_limits([joint.id], *limits, eep=True)
                found = await driver.read_eep(joint.id, hx.Eep.MIN_VOLTAGE, 2)
                rows.append({
                    "joint": joint.name, "bus": bus.name, "id": joint.id,
                    "eep_min_voltage_v": round(hx.voltage_v(found[0]), 2),
                    "eep_max_voltage_v": round(hx.voltage_v(found[1]), 2),
                    "ok": found == wanted,
                })
        finally:
            await driver.close()
    return rows


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


