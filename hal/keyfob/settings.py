"""Settings of the keyfob (the `[keyfob]` table of kaspar.toml).

Key codes are evdev names ("KEY_PAGEDOWN") or numbers; `evtest` shows what a
keyfob sends. Timings are in seconds. Which gestures each button has is the
game's decision (hal.keyfob.gestures.GestureNeeds), not the configuration's: the
same keyfob serves games that need fewer gestures, and fewer gestures mean
faster presses.
"""

from __future__ import annotations

import re
from typing import Literal

import msgspec

DEFAULT_DEVICE = "/dev/input/kaspar-keyfob"

_KEY_NAME = re.compile(r"(KEY|BTN)_[A-Z0-9_]+")
_COMMAND_NAME = re.compile(r"[a-z][a-z0-9_-]*")


def key_code(key: str | int) -> int:
    """The evdev code of a key name or number; ValueError when there is none."""
    if isinstance(key, int):
        if not 0 < key < 0x300:
            raise ValueError(f"expected a key code between 1 and 767, found {key}")
        return key
    if not _KEY_NAME.fullmatch(key):
        raise ValueError(f"expected a key name such as 'KEY_PAGEDOWN' or a number, found {key!r}")
    try:
        from evdev import ecodes
    except ImportError:  # not Linux: the name's form was checked, the robot resolves it
        return -1
    code = ecodes.ecodes.get(key)
    if code is None:
        raise ValueError(f"expected a key name known to evdev, found {key!r}")
    return int(code)


class KeyfobSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """The keyfob device, its key map and the gesture timings."""

    # "sim": the scripted or terminal keyfob of hal.keyfob.sim.
    backend: Literal["real", "sim"] = "real"
    # Open by path (a udev symlink, /dev/input/by-id/...) or by the device's
    # name as `evtest` lists it; at most one of the two. Neither: DEFAULT_DEVICE.
    device: str | None = None
    name: str | None = None
    # Take the keys for ourselves, so a keyfob that types PAGEDOWN moves nothing else.
    grab: bool = True
    green: str | int = "KEY_PAGEDOWN"
    red: str | int = "KEY_PAGEUP"
    # Extra keys of a bigger keypad: key -> researcher command name ("pause", "undo"...).
    commands: dict[str, str] = {}
    # Held this long, a press becomes a long press, delivered when the time is reached.
    long_press: float = 1.0
    # A second press starting within this time of the first one's release is a double press.
    double_press: float = 0.4
    # A release followed by a press within this time is contact bounce, not two presses.
    bounce: float = 0.03
    # Green and red count as held together when the second goes down within this
    # time of the first; they must then be held together for long_press.
    both_window: float = 0.3
    # After the device node returns, how long to keep retrying while udev
    # applies its group and mode.
    reopen_grace: float = 5.0

    def __post_init__(self) -> None:
        if self.device is not None and self.name is not None:
            raise ValueError("set device or name, not both")
        if self.device is not None and not self.device.startswith("/"):
            raise ValueError(f"expected an absolute device path, found {self.device!r}")
        if self.name is not None and not self.name.strip():
            raise ValueError("expected a device name, found an empty string")
        codes = {"green": _code("green", self.green), "red": _code("red", self.red)}
        for key, command in self.commands.items():
            if not _COMMAND_NAME.fullmatch(command) or command in ("green", "red", "both"):
                raise ValueError(f"commands: expected a name like 'pause', found {command!r}")
            codes[f"commands.{key}"] = _code(f"commands.{key}", _number_or_name(key))
        seen: dict[int, str] = {}
        for where, code in codes.items():
            if code in seen and code != -1:
                raise ValueError(f"{where} uses the same key as {seen[code]}")
            seen[code] = where
        for field in ("long_press", "double_press", "bounce", "both_window"):
            value = getattr(self, field)
            if not 0 < value <= 10:
                raise ValueError(f"{field}: expected seconds between 0 and 10, found {value}")
        if not 0 < self.reopen_grace <= 60:
            raise ValueError(f"reopen_grace: expected 0 to 60 seconds, found {self.reopen_grace}")
        if not self.bounce < self.double_press < self.long_press:
            raise ValueError(
                "expected bounce < double_press < long_press, found "
                f"{self.bounce} / {self.double_press} / {self.long_press}"
            )
        if self.both_window >= self.long_press:
            raise ValueError(f"both_window: expected < long_press, found {self.both_window}")

    @property
    def device_path(self) -> str | None:
        """The path to open, or None when the device is found by name."""
        if self.name is not None:
            return None
        return self.device or DEFAULT_DEVICE

    def key_map(self) -> dict[int, str]:
        """evdev code -> button ("green", "red") or researcher command name."""
        mapping = {key_code(self.green): "green", key_code(self.red): "red"}
        for key, command in self.commands.items():
            mapping[key_code(_number_or_name(key))] = command
        return mapping


def _code(field: str, key: str | int) -> int:
    try:
        return key_code(key)
    except ValueError as error:
        raise ValueError(f"{field}: {error}") from None


def _number_or_name(key: str) -> str | int:
    # TOML table keys are strings; "30" means the code 30.
    return int(key) if key.isdigit() else key
