"""A fake sysfs: event nodes under a USB interface, with names, ids, key bitmaps, batteries.

Laid out as the kernel does for a USB HID device:
  devices/pci0000:00/0000:00:14.0/usb1/1-<port>/1-<port>:1.<interface>/
      0003:<VID>:<PID>.<n>/input/input<m>/event<k>
  class/input/event<k> -> ../../devices/.../event<k>
and a power_supply directory beside the HID device's input, as hidpp makes one.
"""

from __future__ import annotations

import os
from pathlib import Path

from hal.keyfob.devices import key_bitmap


def add_node(
    root: Path,
    event: int,
    name: str,
    vendor: int,
    product: int,
    *,
    interface: int | None = 0,
    keys: set[int] = frozenset(),  # type: ignore[assignment]
    port: int = 2,
    battery: dict[str, str] | None = None,
    battery_scope: str = "Device",
) -> Path:
    usb = root / "devices" / "pci0000:00" / "0000:00:14.0" / "usb1" / f"1-{port}"
    parent = usb
    if interface is not None:
        parent = usb / f"1-{port}:1.{interface}"
        parent.mkdir(parents=True, exist_ok=True)
        (parent / "bInterfaceNumber").write_text(f"{interface:02x}\n")
    hid = parent / f"0003:{vendor:04X}:{product:04X}.{event:04X}"
    device = hid / "input" / f"input{event + 100}"
    (device / "id").mkdir(parents=True, exist_ok=True)
    (device / "capabilities").mkdir(exist_ok=True)
    (device / "name").write_text(name + "\n")
    (device / "id" / "bustype").write_text("0003\n")
    (device / "id" / "vendor").write_text(f"{vendor:04x}\n")
    (device / "id" / "product").write_text(f"{product:04x}\n")
    (device / "capabilities" / "key").write_text(key_bitmap(set(keys)) + "\n")
    node = device / f"event{event}"
    node.mkdir()
    if battery is not None:
        supply = hid / "power_supply" / f"hidpp_battery_{event}"
        supply.mkdir(parents=True)
        (supply / "scope").write_text(battery_scope + "\n")
        for key, value in battery.items():
            (supply / key).write_text(value + "\n")
    links = root / "class" / "input"
    links.mkdir(parents=True, exist_ok=True)
    os.symlink(os.path.relpath(node, links), links / f"event{event}")
    return node
