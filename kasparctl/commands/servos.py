"""`kasparctl servos`: find servos on a bus, read every configured joint, calibrate by hand."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from typing import Any

from hal.clock import MonotonicClock
from hal.errors import BusError
from hal.servos.api import JointStatus
from hal.servos.bus import SerialBus
from hal.servos.drivers import DRIVERS
from hal.servos.joints import Joints
from hal.servos.settings import BAUD_RATES, JointSettings, model_named
from hal.servos.sim import SimServos
from kasparctl.commands.arguments import number
from kasparctl.config import ConfigError, load_config
from kasparctl.log import configure_logging

DEFAULT_IDS = {"dynamixel1": "1-30", "dynamixel2": "1-30", "herkulex": "0-30", "maestro": "0-11"}


def register(subparsers: Any) -> None:
    """Add the `servos` subcommand with its `scan` and `read` actions."""
    parser = subparsers.add_parser("servos", help="scan a servo bus or read the configured joints")
    commands = parser.add_subparsers(dest="servos_command", metavar="ACTION", required=True)

    scan = commands.add_parser("scan", help="list the servos answering on one port")
    scan.add_argument("--port", required=True, help="serial device, e.g. /dev/ttyUSB0")
    scan.add_argument("--protocol", required=True, choices=sorted(DRIVERS))
    scan.add_argument("--baud", type=int, default=57600, choices=BAUD_RATES, metavar="BAUD")
    scan.add_argument(
        "--ids",
        type=parse_ids,
        default=None,
        help="ids (channels on a Maestro) to try, e.g. 1-20 or 1,3,5 (default: "
        + ", ".join(f"{k} {v}" for k, v in DEFAULT_IDS.items())
        + ")",
    )
    scan.add_argument(
        "--margin-ms",
        type=number(0, 1000, low_open=True, unit="ms"),  # as a bus's timeout_margin_ms
        default=20.0,
        help="reply time allowed beyond the wire time (default 20)",
    )
    scan.add_argument(
        "--json", action="store_true", help="print a JSON list of {id, model, position}"
    )
    scan.set_defaults(run=run_scan)

    read = commands.add_parser(
        "read", help="print every configured joint: degrees, temperature, voltage, error bits"
    )
    read.add_argument("--config", required=True, help="kaspar.toml")
    read.add_argument("--json", action="store_true", help="print a JSON list, one object per joint")
    read.set_defaults(run=run_read)

    from kasparctl.commands import calibrate

    calibrate.register(commands)


def parse_ids(text: str) -> list[int]:
    """Servo ids from '1-5,9' (ranges and single ids, comma-separated)."""
    ids: list[int] = []
    try:
        for part in text.split(","):
            low, _, high = part.strip().partition("-")
            ids.extend(range(int(low), int(high or low) + 1))
    except ValueError:
        message = f"expected ids like 1-20 or 1,3,5, found {text!r}"
        raise argparse.ArgumentTypeError(message) from None
    if not ids or min(ids) < 0 or max(ids) > 253:
        raise argparse.ArgumentTypeError(f"ids must be within 0-253, found {text!r}")
    return sorted(set(ids))


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


def _quiet_logging() -> None:
    # stdout is the command's answer (maybe JSON for a script): the HAL's log goes to stderr.
    configure_logging("warning", "console", stream=sys.stderr)


def run_scan(arguments: argparse.Namespace) -> int:
    """Print the servos answering on a port; exit 1 if the port cannot be opened."""
    _quiet_logging()
    ids = arguments.ids or parse_ids(DEFAULT_IDS[arguments.protocol])
    try:
        margin = arguments.margin_ms / 1000
        found = asyncio.run(scan(arguments.port, arguments.protocol, arguments.baud, ids, margin))
    except BusError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if arguments.json:
        print(json.dumps(found))
    elif not found:
        where = f"{arguments.port} ({arguments.protocol}, {arguments.baud} baud)"
        print(f"no servo answered on {where}")
    else:
        for servo in found:
            print(f"id {servo['id']:3d}  {servo['model']:<12} position {servo['position']}")
    return 0 if found else 1


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
    return [status_row(s, by_name[s.joint]) for s in statuses]


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
        "problems": problems,
        "status": "ok" if status.healthy else "; ".join(problems),
    }


def format_row(row: dict[str, Any]) -> str:
    """One joint as a line of text: a reading the servo cannot give is marked with '!'."""
    impossible = " ".join(row["problems"])
    position = "   --  " if row["position_deg"] is None else f"{row['position_deg']:7.1f}"
    if row["raw_position"] is not None and "position reading" in impossible:
        position = f"!{row['raw_position']:>6}"
    temperature = "" if row["temperature_c"] is None else f"{row['temperature_c']:.0f} C"
    if temperature and "temperature" in impossible:
        temperature = "!" + temperature
    voltage = "" if row["voltage_v"] is None else f"{row['voltage_v']:.1f} V"
    if voltage and "voltage" in impossible:
        voltage = "!" + voltage
    return (
        f"{row['joint']:<20} {row['bus']:<6} id {row['id']:3d} {position} deg "
        f"{temperature:>6} {voltage:>7}  {row['status']}"
    )


def run_read(arguments: argparse.Namespace) -> int:
    """Print every configured joint as it is now; exit 1 if any is faulty or impossible."""
    _quiet_logging()
    try:
        rows = asyncio.run(read_joints(arguments.config))
    except ConfigError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if arguments.json:
        print(json.dumps(rows))
    else:
        for row in rows:
            print(format_row(row))
    return 0 if all(row["status"] == "ok" for row in rows) else 1
