"""`kasparctl servos`: find servos on a bus, read every configured joint, calibrate by hand."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from typing import Any

from hal.servos.drivers import DRIVERS
from hal.servos.herkulex import FACTORY_ID
from hal.servos.settings import BAUD_RATES
from kasparctl.bringup.servos import (
    DEFAULT_IDS,
    SCAN_MARGIN_MS,
    format_battery,
    format_row,
    read_joints,
    scan,
    set_id,
    set_voltage_eep,
)
from kasparctl.commands.arguments import number, path, whole, whole_ranges
from kasparctl.log import configure_logging


def register(subparsers: Any) -> None:
    """Add the `servos` subcommand with its `scan`, `set-id`, `read` and `calibrate` actions."""
    parser = subparsers.add_parser("servos", help="scan a servo bus or read the configured joints")
    commands = parser.add_subparsers(dest="servos_command", metavar="ACTION", required=True)

    scan_parser = commands.add_parser("scan", help="list the servos answering on one port")
    scan_parser.add_argument("--port", required=True, type=path,
                             help="serial device, e.g. /dev/ttyUSB0")
    scan_parser.add_argument("--protocol", required=True, choices=sorted(DRIVERS))
    scan_parser.add_argument("--baud", type=whole(0, max(BAUD_RATES)), default=57600,
                             choices=BAUD_RATES,
                             metavar="BAUD")
    scan_parser.add_argument(
        "--ids", type=whole_ranges(0, 253, "ids"), default=None,
        help="ids (channels on a Maestro) to try, e.g. 1-20 or 1,3,5 (default: "
        + ", ".join(f"{k} {low}-{high}" for k, (low, high) in DEFAULT_IDS.items()) + ")",
    )
    scan_parser.add_argument(
        "--margin-ms",
        type=number(0, 1000, low_open=True, unit="ms"),  # as a bus's timeout_margin_ms
        default=SCAN_MARGIN_MS,
        help=f"reply time allowed beyond the wire time (default {SCAN_MARGIN_MS:g})",
    )
    scan_parser.add_argument(
        "--json", action="store_true", help="print a JSON list of {id, model, position}"
    )
    scan_parser.set_defaults(run=run_scan)

    set_id = commands.add_parser(
        "set-id", help="give a HerkuleX servo a new id (a factory-new one answers at 253)"
    )
    set_id.add_argument("--port", required=True, type=path, help="serial device of the bus")
    set_id.add_argument("--baud", type=whole(0, max(BAUD_RATES)), default=115200,
                        choices=BAUD_RATES, metavar="BAUD",
                        help="the servo's baud rate (default 115200, the factory's)")
    set_id.add_argument("--id", dest="servo_id", type=whole(0, 253), default=FACTORY_ID,
                        help=f"the servo's id now (default {FACTORY_ID}, a new servo's)")
    set_id.add_argument("--new-id", required=True, type=whole(0, 253),
                        help="the id it is to have (refused if a servo on the bus has it)")
    set_id.add_argument(
        "--margin-ms", type=number(0, 1000, low_open=True, unit="ms"), default=SCAN_MARGIN_MS,
        help=f"reply time allowed beyond the wire time (default {SCAN_MARGIN_MS:g})",
    )
    set_id.set_defaults(run=run_set_id)

    voltage = commands.add_parser(
        "set-voltage",
        help="write the HerkuleX buses' min/max_voltage_v into their servos' EEP (kept "
        "across power; the service itself writes RAM only)",
    )
    voltage.add_argument("--config", required=True, type=path, help="kaspar.toml")
    voltage.set_defaults(run=run_set_voltage)

    read = commands.add_parser(
        "read", help="print every configured joint: degrees, temperature, voltage, error bits"
    )
    read.add_argument("--config", required=True, type=path, help="kaspar.toml")
    read.add_argument("--json", action="store_true", help="print a JSON list, one object per joint")
    read.set_defaults(run=run_read)

    from kasparctl.commands import calibrate

    calibrate.register(commands)  # fmt: skip


def _quiet_logging(level: str = "warning") -> None:
    # stdout is the command's answer (maybe JSON for a script): the HAL's log goes to stderr.
    configure_logging(level, "console", stream=sys.stderr)


def run_scan(arguments: argparse.Namespace) -> int:
    """Print the servos answering on a port; exit 1 if none does or the port cannot be opened."""
    # Errors only: a port that cannot be opened is the one line of the failure, not also
    # the bus's warning that it will retry (a scan does not).
    _quiet_logging("error")
    low, high = DEFAULT_IDS[arguments.protocol]
    ids = arguments.ids or list(range(low, high + 1))
    margin = arguments.margin_ms / 1000
    found = asyncio.run(scan(arguments.port, arguments.protocol, arguments.baud, ids, margin))
    if arguments.json:
        print(json.dumps(found))
    elif not found:
        where = f"{arguments.port} ({arguments.protocol}, {arguments.baud} baud)"
        print(f"no servo answered on {where}")
    else:
        for servo in found:
            print(f"id {servo['id']:3d}  {servo['model']:<12} position {servo['position']}")
    return 0 if found else 1


def run_set_id(arguments: argparse.Namespace) -> int:
    """Give one HerkuleX servo its id, then print the bus as scanned after its reboot."""
    _quiet_logging("error")
    done = asyncio.run(set_id(arguments.port, arguments.baud, arguments.servo_id,
                              arguments.new_id, arguments.margin_ms / 1000))
    print(f"id {done['id']} -> {done['new_id']}: EEP 6 written and read back "
          f"({done['eep_id']}), servo rebooted; on the bus now:")
    for servo in done["found"]:
        print(f"id {servo['id']:3d}  {servo['model']:<12} position {servo['position']}")
    return 0


def run_set_voltage(arguments: argparse.Namespace) -> int:
    """Write the voltage limits to EEP; print what each servo holds now; exit 1 on a mismatch."""
    _quiet_logging()
    rows = asyncio.run(set_voltage_eep(arguments.config))
    for row in rows:
        verdict = "ok" if row["ok"] else "NOT WRITTEN"
        print(f"{row['joint']:<20} {row['bus']:<6} id {row['id']:3d}  EEP 12-13: "
              f"{row['eep_min_voltage_v']:.2f}-{row['eep_max_voltage_v']:.2f} V  {verdict}")
    return 0 if all(row["ok"] for row in rows) else 1


def run_read(arguments: argparse.Namespace) -> int:
    """Print every configured joint as it is now; exit 1 if any is faulty or impossible."""
    _quiet_logging()
    rows = asyncio.run(read_joints(arguments.config))
    if arguments.json:
        print(json.dumps(rows))
    else:
        for row in rows:
            print(format_row(row))
        battery = format_battery(rows)
        if battery is not None:
            print(battery)
    return 0 if all(row["status"] == "ok" for row in rows) else 1
