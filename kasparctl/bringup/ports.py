"""The stable names udev gives Kaspar 3's Maestro ports: which board a tty is, by channel 17.

Kaspar 3 has two Pololu Mini Maestro 18s (1ffb:008b, cdc_acm), each with two serial
ports: USB interface 00, the Command Port, and 02, the TTL Port (the Maestro's own
UART). The body board's TTL Port is the HerkuleX bus; its Command Port reads ten
touch sensors. The head board's Command Port drives the eyes and reads four touch
sensors. Nothing in USB tells the two boards apart: the robot's harness does, on
channel 17 (published kasparGUI/Config/portNamer.py: Get Position of channel 17
reads 127 or more on the head board, less on the body board).

udev cannot read a channel, so its rule runs `kasparctl port-name %k` (PROGRAM=),
which prints the names for that tty: it finds the board's Command Port in sysfs
(itself, or interface 00 of the same USB device for a TTL Port), asks it for
channel 17, and answers from NAMES. The two ports of a board are named in two
udev events that may run at once: a lock per board makes them take turns on the
Command Port. Why this, and not a serial number in the rules or a lookup in
kasparctl at start: docs/install.md, "The serial ports".
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import time
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any

from hal.errors import BusError, KasparError
from hal.servos.bus import SerialBus
from hal.servos.drivers import MaestroDriver
from hal.servos.ports import POLOLU, SYSFS, describe_node, interface_tty

COMMAND_PORT, TTL_PORT = "00", "02"
BOARD_CHANNEL = 17
HEAD_AT_LEAST = 127  # portNamer.py's HEADVAL: the head board reads channel 17 high
# The names of each port, by board and interface; the configuration uses /dev/<name>.
NAMES: dict[tuple[str, str], tuple[str, ...]] = {
    ("body", TTL_PORT): ("kaspar-body",),  # the HerkuleX bus
    ("body", COMMAND_PORT): ("kaspar-body-sensors",),
    ("head", COMMAND_PORT): ("kaspar-eyes", "kaspar-head-sensors"),
    ("head", TTL_PORT): ("kaspar-head-ttl",),
}
LOCK_DIR = Path("/run/lock")
# A TTL Port's event may come before its board's Command Port is in sysfs.
SIBLING_WAIT_S = 2.0
READ_MARGIN_S = 0.2  # a Command Port answers at once; the bus adds this to the wire time


class PortNameError(KasparError):
    """A tty that is not one of Kaspar 3's Maestro ports, or whose board could not be read."""


async def read_board(command_port: str) -> str:
    """"head" or "body": the board whose Command Port is `command_port`, by its channel 17."""
    bus = SerialBus("board", command_port, 115200, timeout_margin=READ_MARGIN_S, retries=1)
    driver = MaestroDriver(bus)
    await driver.start()
    try:
        if not bus.connected:
            raise PortNameError(f"cannot open {command_port}: {bus.unavailable()}")
        try:
            reading = (await driver.read_positions([BOARD_CHANNEL]))[BOARD_CHANNEL]
        except BusError as error:
            raise PortNameError(f"{command_port} did not answer Get Position: {error}") from None
    finally:
        await driver.close()
    return "head" if reading >= HEAD_AT_LEAST else "body"


@contextlib.contextmanager
def _board_lock(lock_dir: Path, board: str) -> Iterator[None]:
    lock_dir.mkdir(parents=True, exist_ok=True)
    with open(lock_dir / f"kaspar-maestro-{board}.lock", "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        yield


def port_names(
    device: str,
    sysfs: Path = SYSFS,
    dev: Path = Path("/dev"),
    lock_dir: Path = LOCK_DIR,
    board_of: Callable[[str], Coroutine[Any, Any, str]] = read_board,
) -> tuple[str, ...]:
    """The stable names of the tty `device` (a kernel name such as ttyACM1, or a /dev path).

    PortNameError when it is not a Maestro's Command or TTL Port, or the board's
    Command Port cannot be found or read.
    """
    kernel_name = Path(device).name
    info = describe_node(str(dev / kernel_name), str(dev / kernel_name), sysfs)
    if info.vendor != POLOLU or info.usb_device is None or info.interface not in (
        COMMAND_PORT, TTL_PORT
    ):
        raise PortNameError(f"{kernel_name} is not a Maestro's Command or TTL Port ({info})")
    command = kernel_name
    if info.interface == TTL_PORT:
        deadline = time.monotonic() + SIBLING_WAIT_S
        sibling = interface_tty(info.usb_device, COMMAND_PORT)
        while sibling is None and time.monotonic() < deadline:
            time.sleep(0.05)
            sibling = interface_tty(info.usb_device, COMMAND_PORT)
        if sibling is None:
            raise PortNameError(f"{kernel_name}: its board's Command Port (interface 00) "
                                f"is not in sysfs under {info.usb_device}")
        command = sibling
    with _board_lock(lock_dir, info.usb_device.name):
        board = asyncio.run(board_of(str(dev / command)))
    return NAMES[(board, info.interface)]
