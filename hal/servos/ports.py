"""What a serial port is, as the kernel's sysfs says: its node, the USB device and interface.

`kasparctl check` names the device behind each bus with it, and the udev helper
(`kasparctl port-name`, kasparctl.bringup.ports) finds the Maestro board a tty
belongs to. Only files are read: /sys/class/tty/<node>/device leads, through the
USB interface (bInterfaceNumber, its driver), to the USB device (idVendor,
idProduct, manufacturer, product, serial). A `sysfs` root other than /sys is a
test's fake tree.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

SYSFS = Path("/sys")

# The adapters a Kaspar's buses use (vendor:product -> what it is).
KNOWN_ADAPTERS = {
    ("1ffb", "0089"): "Pololu Micro Maestro 6",
    ("1ffb", "008a"): "Pololu Mini Maestro 12",
    ("1ffb", "008b"): "Pololu Mini Maestro 18",
    ("1ffb", "008c"): "Pololu Mini Maestro 24",
    ("0403", "6001"): "FTDI FT232R (USB2Dynamixel and most USB-TTL cables)",
    ("0403", "6014"): "FTDI FT232H (ROBOTIS U2D2)",
    ("0403", "6015"): "FTDI FT231X",
    ("1a86", "7523"): "WCH CH340",
    ("1a86", "55d4"): "WCH CH9102",
    ("10c4", "ea60"): "Silicon Labs CP210x",
}
# A Maestro's two serial ports, by USB interface (Pololu's Maestro user's guide).
MAESTRO_INTERFACES = {"00": "Command Port", "02": "TTL Port"}
POLOLU = "1ffb"


@dataclass(frozen=True, slots=True)
class PortInfo:
    """A serial node and, when it is a USB adapter, what the adapter is."""

    path: str  # as configured, e.g. /dev/kaspar-body
    node: str | None  # the device it resolves to, e.g. /dev/ttyACM1 (None: no such node)
    vendor: str | None = None  # idVendor, 4 hex digits
    product: str | None = None  # idProduct
    interface: str | None = None  # bInterfaceNumber, 2 hex digits
    driver: str | None = None  # the kernel driver of the interface: cdc_acm, ftdi_sio, ...
    name: str | None = None  # the maker's product string, or ours from KNOWN_ADAPTERS
    serial: str | None = None
    usb_device: Path | None = None  # the USB device's sysfs directory

    @property
    def is_maestro(self) -> bool:
        """A Pololu Maestro's port (Command or TTL)."""
        return self.vendor == POLOLU

    def __str__(self) -> str:
        """"/dev/kaspar-body is /dev/ttyACM1: Pololu Mini Maestro 18 (1ffb:008b) interface 02
        (TTL Port), serial 00123456, driver cdc_acm"."""
        if self.node is None:
            return f"{self.path}: no such device"
        head = self.path if self.path == self.node else f"{self.path} is {self.node}"
        if self.vendor is None:
            return f"{head}: not a USB adapter (no sysfs USB device: a pseudo-terminal or a UART)"
        text = f"{head}: {self.name or 'USB serial'} ({self.vendor}:{self.product})"
        if self.interface is not None:
            role = MAESTRO_INTERFACES.get(self.interface) if self.is_maestro else None
            text += f" interface {self.interface}" + (f" ({role})" if role else "")
        if self.serial:
            text += f", serial {self.serial}"
        if self.driver:
            text += f", driver {self.driver}"
        return text


def _read(directory: Path, name: str) -> str | None:
    try:
        return (directory / name).read_text(encoding="utf-8", errors="replace").strip() or None
    except OSError:
        return None


def _up_to(start: Path, marker: str, stop: Path) -> Path | None:
    """The first directory from `start` upward (not above `stop`) holding the file `marker`."""
    for directory in (start, *start.parents):
        if directory == stop or stop not in directory.parents:
            return None
        if (directory / marker).is_file():
            return directory
    return None


def describe(path: str, sysfs: Path = SYSFS) -> PortInfo:
    """What the serial port at `path` is; a node that does not exist says so."""
    if not os.path.exists(path):
        return PortInfo(path, None)
    node = os.path.realpath(path)
    return describe_node(path, node, sysfs)


def describe_node(path: str, node: str, sysfs: Path = SYSFS) -> PortInfo:
    """What the tty `node` (a /dev path; its kernel name is its last part) is, from sysfs."""
    kernel_name = os.path.basename(node)
    device = sysfs / "class" / "tty" / kernel_name / "device"
    if not device.exists():
        return PortInfo(path, node)
    real = device.resolve()
    root = sysfs.resolve()
    interface = _up_to(real, "bInterfaceNumber", root)
    usb = _up_to(interface.parent if interface else real, "idVendor", root)
    if usb is None:
        return PortInfo(path, node)
    vendor, product = _read(usb, "idVendor"), _read(usb, "idProduct")
    driver = None
    if interface is not None and (interface / "driver").exists():
        driver = (interface / "driver").resolve().name
    known = KNOWN_ADAPTERS.get((vendor or "", product or ""))
    return PortInfo(
        path, node, vendor, product,
        _read(interface, "bInterfaceNumber") if interface else None,
        driver, known or _read(usb, "product"), _read(usb, "serial"), usb,
    )


def interface_tty(usb_device: Path, interface: str) -> str | None:
    """The kernel name of the tty on `interface` (e.g. "00") of a USB device, if it has one."""
    for candidate in sorted(usb_device.glob("*:*.*")):
        if _read(candidate, "bInterfaceNumber") != interface:
            continue
        for tty in sorted(candidate.glob("tty/*")) + sorted(candidate.glob("tty*")):
            if tty.name.startswith("tty") and tty.name != "tty":
                return tty.name
    return None
