"""The remotes' batteries at the service's start: a warning for STATUS= and the grown-up.

Where the kernel reports a battery (hal.keyfob.devices: a power_supply of scope Device,
as Logitech's hidpp gives one), a level below the device's `battery_warn_percent` is
said once: in STATUS= until the service stops, in the journal, and aloud to the grown-up
at the first game ("fault.remote_battery_low"). A device the kernel says nothing about is no
warning: most keyfobs never report a level.
"""

from __future__ import annotations

from hal.keyfob.devices import battery_of
from hal.keyfob.settings import KeyfobSettings, ResearcherSettings
from kasparctl.config import Config


def low_batteries(config: Config, sys_root: str = "/sys") -> str | None:
    """'keyfob battery 12% (below 20%) | researcher's remote battery Low (15%) ...' or None."""
    devices: list[tuple[str, KeyfobSettings | ResearcherSettings]] = [("keyfob", config.keyfob)]
    if config.researcher.source == "device":
        devices.append(("researcher's remote", config.researcher))
    low = []
    for part, settings in devices:
        if settings.backend != "real" or config.keyfob.backend != "real":
            continue
        match = settings.match()
        battery = battery_of(
            settings.device_path, (match.vendor, match.product, match.interface), sys_root
        )
        if battery is not None and battery.percent is not None and (
            battery.percent < settings.battery_warn_percent
        ):
            low.append(f"{part} {battery.describe()} (below {settings.battery_warn_percent}%)")
    return " | ".join(low) or None
