"""The input devices the kernel has, read from sysfs: node, name, ids, interface, keys, battery.

/sys/class/input/eventN is a link into the device tree (.../usb1/1-2/1-2:1.0/
0003:046D:C52D.0001/input/input5/event5). From it: the event node's name (eventN, so
/dev/input/eventN), the input device's name and ids (inputM/name, inputM/id/*), the keys
it can send (inputM/capabilities/key, a bitmap), the USB interface it belongs to (the
first ancestor with bInterfaceNumber), and a battery where the kernel exposes one: a
power_supply beside an ancestor (Logitech hidpp puts hidpp_battery_N under the HID
device) whose scope is Device, with capacity (percent) or capacity_level (a word).

Everything is read from a root directory given by the caller, so tests build a fake
tree; the robot's is "/sys".
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

_EVENT = re.compile(r"event(\d+)")
# capacity_level words, as a percentage a threshold can be compared to (the kernel's
# POWER_SUPPLY_CAPACITY_LEVEL_* names; "Unknown" gives None).
_LEVELS = {"Critical": 5, "Low": 15, "Normal": 50, "High": 80, "Full": 100}


@dataclass(frozen=True, slots=True)
class Battery:
    """A device's battery as the kernel reports it."""

    supply: str  # the power_supply's name, hidpp_battery_0
    percent: int | None  # capacity, or capacity_level's word as a percentage
    level: str | None  # capacity_level when the kernel gives a word

    def describe(self) -> str:
        """"battery 40%" or "battery Low", as `check` prints it."""
        if self.level is not None and self.level != "Unknown":
            exact = f" ({self.percent}%)" if self.percent is not None else ""
            return f"battery {self.level}{exact}" if exact else f"battery {self.level}"
        if self.percent is not None:
            return f"battery {self.percent}%"
        return "battery level unknown"


@dataclass(frozen=True, slots=True)
class InputNode:
    """One event node and what sysfs says about it."""

    node: str  # "event5"
    name: str
    bus: int
    vendor: int
    product: int
    interface: int | None  # the USB interface number; None off USB (Bluetooth, built in)
    keys: frozenset[int]
    battery: Battery | None

    @property
    def number(self) -> int:
        """N of eventN: the order the kernel made the nodes in."""
        match = _EVENT.fullmatch(self.node)
        return int(match.group(1)) if match else -1

    def ids(self) -> str:
        """vendor:product as lsusb writes them (046d:c52d)."""
        return f"{self.vendor:04x}:{self.product:04x}"

    def describe(self, input_dir: str = "/dev/input") -> str:
        """One line: node, name, ids, interface, battery."""
        where = f" interface {self.interface}" if self.interface is not None else ""
        battery = f", {self.battery.describe()}" if self.battery else ""
        return f"{input_dir}/{self.node}  {self.name!r}  {self.ids()}{where}{battery}"


def input_nodes(sys_root: str = "/sys") -> list[InputNode]:
    """Every event node sysfs lists, in the kernel's order (event9 before event10)."""
    found = []
    directory = Path(sys_root, "class", "input")
    try:
        entries = list(directory.iterdir())
    except OSError:
        return []
    for entry in entries:
        if _EVENT.fullmatch(entry.name):
            node = _read_node(entry)
            if node is not None:
                found.append(node)
    return sorted(found, key=lambda node: node.number)


def node_of(path: str, sys_root: str = "/sys") -> InputNode | None:
    """The sysfs record of the event node `path` (a symlink is followed), or None."""
    name = Path(os.path.realpath(path)).name
    for node in input_nodes(sys_root):
        if node.node == name:
            return node
    return None


def _read_node(entry: Path) -> InputNode | None:
    event = Path(os.path.realpath(entry))
    device = event.parent  # inputM
    name = _text(device / "name")
    if name is None:
        return None
    return InputNode(
        node=entry.name,
        name=name,
        bus=_hex(device / "id" / "bustype"),
        vendor=_hex(device / "id" / "vendor"),
        product=_hex(device / "id" / "product"),
        interface=_interface(device),
        keys=_key_bits(_text(device / "capabilities" / "key") or ""),
        battery=_battery(device),
    )


def _interface(device: Path) -> int | None:
    for ancestor in device.parents:
        number = _text(ancestor / "bInterfaceNumber")
        if number is not None:
            try:
                return int(number, 16)
            except ValueError:
                return None
    return None


def _battery(device: Path) -> Battery | None:
    # Nearest first: the HID device above the input device holds hidpp's battery. A
    # supply of scope System is the computer's own battery, never the remote's.
    for ancestor in (device, *device.parents):
        supplies = ancestor / "power_supply"
        if not supplies.is_dir():
            continue
        for supply in sorted(supplies.iterdir()):
            if (_text(supply / "scope") or "Device") != "Device":
                continue
            capacity = _text(supply / "capacity")
            level = _text(supply / "capacity_level")
            percent = int(capacity) if capacity and capacity.isdigit() else None
            if percent is None and level is not None:
                percent = _LEVELS.get(level)
            if percent is not None or level is not None:
                return Battery(supply.name, percent, level)
    return None


def _key_bits(bitmap: str) -> frozenset[int]:
    # The kernel writes the bitmap as words, most significant first: "10000 0 ... 1e".
    words = bitmap.split()
    bits = set()
    width = 64 if sys.maxsize > 2**32 else 32  # the kernel's long, one word each
    for index, word in enumerate(reversed(words)):
        value = int(word, 16)
        base = index * width
        while value:
            low = value & -value
            bits.add(base + low.bit_length() - 1)
            value ^= low
    return frozenset(bits)


def key_bitmap(codes: set[int] | frozenset[int]) -> str:
    """The capabilities/key text the kernel would write for `codes` (64-bit words)."""
    if not codes:
        return "0"
    words = []
    for index in range(max(codes) // 64 + 1):
        low, high = index * 64, (index + 1) * 64
        word = sum(1 << (code - low) for code in codes if low <= code < high)
        words.append(f"{word:x}")
    return " ".join(reversed(words))


def _text(path: Path) -> str | None:
    try:
        return path.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return None


def _hex(path: Path) -> int:
    text = _text(path)
    try:
        return int(text, 16) if text else 0
    except ValueError:
        return 0


def battery_of(
    path: str | None,
    ids: tuple[int | None, int | None, int | None] = (None, None, None),
    sys_root: str = "/sys",
) -> Battery | None:
    """The battery of the node at `path` (a udev symlink followed), else of the first node
    with these (vendor, product, interface); None where the kernel reports none."""
    node = node_of(path, sys_root) if path else None
    vendor, product, interface = ids
    if node is None and vendor is not None:
        node = next(
            (
                n
                for n in input_nodes(sys_root)
                if n.vendor == vendor
                and (product is None or n.product == product)
                and (interface is None or n.interface == interface)
            ),
            None,
        )
    return node.battery if node is not None else None
