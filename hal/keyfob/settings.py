"""Settings of the keyfob (the `[keyfob]` table of kaspar.toml) and of the researcher's
input (the `[researcher]` table).

Key codes are evdev names ("KEY_PAGEDOWN") or numbers; `evtest` shows what a
keyfob sends. Timings are in seconds. Which gestures each button has is the
game's decision (hal.keyfob.gestures.GestureNeeds), not the configuration's: the
same keyfob serves games that need fewer gestures, and fewer gestures mean
faster presses.

The children's keyfob carries green and red. The researcher's commands come
from a device of their own by default (a keypad, a presenter remote, a second
keyfob with enough keys: `[researcher]`, read by a second reader), or from the
extra keys of the children's keypad, or, on a robot with one keyfob only, from
holds on the children's keyfob that children do not make by accident.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal, Protocol

import msgspec

from hal.errors import SettingsError
from hal.keyfob import profiles
from hal.keyfob.gestures import GestureKind, GestureNeeds

DEFAULT_DEVICE = "/dev/input/kaspar-keyfob"
# The researcher's own device, as systemd/99-kaspar-keyfob.rules may name it.
DEFAULT_RESEARCHER_DEVICE = "/dev/input/kaspar-researcher"

_KEY_NAME = re.compile(r"(KEY|BTN)_[A-Z0-9_]+")


def key_code(key: str | int) -> int:
    """The evdev code of a key name ("KEY_PAGEDOWN") or number (1 to 767).

    Off Linux, where evdev is missing, a well-formed name gives -1: the robot
    resolves it. Raises SettingsError (a ValueError) for anything else.
    """
    if isinstance(key, int):
        if not 0 < key < 0x300:
            raise SettingsError(f"expected a key code between 1 and 767, found {key}")
        return key
    if not _KEY_NAME.fullmatch(key):
        raise SettingsError(
            f"expected a key name such as 'KEY_PAGEDOWN' or a number, found {key!r}"
        )
    try:
        from evdev import ecodes
    except ImportError:  # not Linux: the name's form was checked, the robot resolves it
        return -1
    code = ecodes.ecodes.get(key)
    if code is None:
        raise SettingsError(f"expected a key name known to evdev, found {key!r}")
    return int(code)


# A path to open; the service runs from /, so it must not depend on the working directory.
DevicePath = Annotated[
    str, msgspec.Meta(pattern="^/", extra={"expected": "an absolute device path"})
]
# The device's name as `evtest` lists it.
DeviceName = Annotated[str, msgspec.Meta(pattern=r"\S", extra={"expected": "a device name"})]
# A USB vendor or product id as lsusb writes it: four hex digits.
UsbId = Annotated[
    str,
    msgspec.Meta(pattern="^[0-9a-fA-F]{4}$", extra={"expected": "four hex digits such as '046d'"}),
]
# The USB interface whose event node carries the keys (bInterfaceNumber).
Interface = Annotated[int, msgspec.Meta(ge=0, le=255)]
# A device profile's name (hal/keyfob/remotes/<name>.toml).
ProfileName = Annotated[
    str, msgspec.Meta(pattern=r"^[a-z0-9][a-z0-9-]*$", extra={"expected": "a profile's name"})
]
# Below this battery level (percent) `check` and the service warn.
BatteryPercent = Annotated[int, msgspec.Meta(ge=0, le=100, extra={"unit": "%"})]
# A keyfob timing in seconds.
Seconds = Annotated[float, msgspec.Meta(gt=0, le=10, extra={"unit": "s"})]
# A researcher command's name: not one of the buttons' own names.
CommandName = Annotated[
    str,
    msgspec.Meta(
        pattern=r"^(?!(green|red|both)\Z)[a-z][a-z0-9_-]*\Z",
        extra={"expected": "a name like 'pause'"},
    ),
]


class SeatSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """One seat of `[[keyfob.children]]`: a keyfob of its own for the child sitting there.

    `child` is the child's place in the group's turn order (1: a plan's first child), so
    the seats stay as they are from group to group. The keyfob is opened like [keyfob]'s,
    by `device` or `name` (exactly one), with [keyfob]'s keys and timings.
    """

    child: Annotated[int, msgspec.Meta(ge=1, le=6, extra={"expected": "a child's place, 1 to 6"})]
    device: DevicePath | None = None
    name: DeviceName | None = None

    def __post_init__(self) -> None:
        """Exactly one of device and name. Raises SettingsError (a ValueError)."""
        if (self.device is None) == (self.name is None):
            raise SettingsError("set device or name (exactly one) for each seat")

    @property
    def where(self) -> str:
        """The device as the records name it: its path, or its name."""
        return self.device or self.name or ""


class KeyfobSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """The keyfob device, its key map and the gesture timings.

    A key's own limits are on its field (msgspec.Meta, held while decoding);
    __post_init__ holds the rules between keys and the key names, which only
    evdev can resolve.
    """

    # "sim": the scripted or terminal keyfob of hal.keyfob.sim.
    backend: Literal["real", "sim"] = "real"
    # Open by path (a udev symlink, /dev/input/by-id/...) or by the device's
    # name as `evtest` lists it; at most one of the two. Neither: DEFAULT_DEVICE.
    device: DevicePath | None = None
    name: DeviceName | None = None
    # Or, with neither, found by its USB ids (and interface) when DEFAULT_DEVICE is missing;
    # by default the profile's.
    vendor: UsbId | None = None
    product: UsbId | None = None
    interface: Interface | None = None
    # Take the keys for ourselves, so a keyfob that types PAGEDOWN moves nothing else.
    grab: bool = True
    # The device family (hal/keyfob/remotes/, docs/keyfob-and-voice.md): which keys are
    # green and red, which alternate, which mean nothing. green and red, when given,
    # replace the profile's.
    profile: ProfileName = "generic-keyfob"
    green: str | int | None = None
    red: str | int | None = None
    # Extra keys of a bigger keypad: key -> researcher command name ("pause", "undo"...).
    commands: dict[str, CommandName] = {}
    # Held this long, a press becomes a long press, delivered when the time is reached.
    long_press: Seconds = 1.0
    # A second press starting within this time of the first one's release is a double press.
    double_press: Seconds = 0.4
    # A release followed by a press within this time is contact bounce, not two presses.
    bounce: Seconds = 0.03
    # Green and red count as held together when the second goes down within this
    # time of the first; they must then be held together for long_press.
    both_window: Seconds = 0.3
    # After the device node returns, how long to keep retrying while udev
    # applies its group and mode.
    reopen_grace: Annotated[float, msgspec.Meta(gt=0, le=60, extra={"unit": "s"})] = 5.0
    # A battery the kernel reports below this is warned of (`check`).
    battery_warn_percent: BatteryPercent = 20
    # One keyfob per child ([[keyfob.children]]): each a seat; none, one shared keyfob.
    children: tuple[SeatSettings, ...] = ()

    def __post_init__(self) -> None:
        """Device and name exclude each other, keys resolve and differ, timings are ordered.

        Raises SettingsError (a ValueError) naming the key.
        """
        if self.device is not None and self.name is not None:
            raise SettingsError("set device or name, not both")
        _profile("profile", self.profile)
        codes = {"green": _code("green", self.green_key), "red": _code("red", self.red_key)}
        for key in self.commands:
            codes[f"commands.{key}"] = _code(f"commands.{key}", _number_or_name(key))
        seen: dict[int, str] = {}
        for where, code in codes.items():
            if code in seen and code != -1:
                raise SettingsError(f"{where} uses the same key as {seen[code]}")
            seen[code] = where
        if not self.bounce < self.double_press < self.long_press:
            raise SettingsError(
                "expected bounce < double_press < long_press, found "
                f"{self.bounce} / {self.double_press} / {self.long_press}"
            )
        if self.both_window >= self.long_press:
            raise SettingsError(f"both_window: expected < long_press, found {self.both_window}")

    def seat(self, index: int) -> KeyfobSettings:
        """The settings seat `index`'s keyfob is opened with: this table's, its device."""
        seat = self.children[index]
        return msgspec.structs.replace(self, device=seat.device, name=seat.name, children=())

    @property
    def device_path(self) -> str | None:
        """The path to open, or None when the device is found by name."""
        if self.name is not None:
            return None
        return self.device or DEFAULT_DEVICE

    @property
    def green_key(self) -> str | int:
        """The green key given, or the first key of the profile's green button."""
        return self.green if self.green is not None else _answer_key(self.profile, "green")

    @property
    def red_key(self) -> str | int:
        """The red key given, or the first key of the profile's red button."""
        return self.red if self.red is not None else _answer_key(self.profile, "red")

    def key_map(self) -> dict[int, str]:
        """Each mapped key's evdev code -> its button ("green", "red") or command name.

        Without green and red given, every key of the profile's green and red buttons
        (a keypad's digit and its top-row twin). Raises SettingsError for a key evdev does
        not know (checked at decoding too).
        """
        if self.green is None and self.red is None:
            chosen = profiles.profile(self.profile)
            mapping = chosen.answer_map(key_code)
        else:
            mapping = {key_code(self.green_key): "green", key_code(self.red_key): "red"}
        for key, command in self.commands.items():
            mapping[key_code(_number_or_name(key))] = command
        return mapping

    def commands_given(self) -> dict[str, str]:
        """The extra keys' commands: `commands`, over the profile's (without green and red
        given) presses of its other buttons."""
        given: dict[str, str] = {}
        if self.green is None and self.red is None:
            chosen = profiles.profile(self.profile)
            answers = set(chosen.answers.values())
            for gesture, command in chosen.commands.items():
                kind, _, button = gesture.partition(" ")
                if kind == "press" and button not in answers:
                    given[chosen.buttons[button][0]] = command
        return {**given, **self.commands}

    def ignored_codes(self) -> set[int]:
        """Keys the profile's device sends that mean nothing (synthetic NumLock)."""
        return profiles.profile(self.profile).ignored_codes(key_code)

    def gesture_commands(self) -> dict[tuple[GestureKind, str], str]:
        """None on the children's keyfob: its gestures are the game's to read."""
        return {}

    def match(self) -> profiles.Match:
        """The USB ids (and interface) to find the device by when no path is given."""
        return _match(self.vendor, self.product, self.interface, self.profile)


def _code(field: str, key: str | int) -> int:
    try:
        return key_code(key)
    except SettingsError as error:
        raise SettingsError(f"{field}: {error}") from None


def _profile(field: str, name: str) -> profiles.Profile:
    try:
        return profiles.profile(name)
    except SettingsError as error:
        raise SettingsError(f"{field}: {error}") from None


def _answer_key(name: str, slot: str) -> str:
    chosen = profiles.profile(name)
    button = chosen.answers.get(slot)
    if button is None:
        raise SettingsError(f"profile {name!r} has no {slot} button: give {slot} = a key")
    return chosen.buttons[button][0]


def _match(
    vendor: str | None, product: str | None, interface: int | None, profile: str
) -> profiles.Match:
    if vendor is None and product is None:
        found = profiles.profile(profile).match
        if interface is None:
            return found
        return profiles.Match(found.vendor, found.product, interface)
    return profiles.Match(
        int(vendor, 16) if vendor else None, int(product, 16) if product else None, interface
    )


def _number_or_name(key: str) -> str | int:
    # TOML table keys are strings; "30" means the code 30.
    return int(key) if key.isdigit() else key


class InputDeviceSettings(Protocol):
    """What the evdev reader (hal.keyfob.reader.Keyfob) reads of a device's settings."""

    @property
    def device_path(self) -> str | None:
        """The node to open, or None to find the device by `name`."""
        ...

    @property
    def name(self) -> str | None:
        """The device's name as `evtest` lists it, when found by name."""
        ...

    @property
    def grab(self) -> bool:
        """Take the device's keys for ourselves (EVIOCGRAB)."""
        ...

    @property
    def reopen_grace(self) -> float:
        """Seconds to keep retrying a node udev has not finished."""
        ...

    @property
    def long_press(self) -> float:
        """The recogniser's long press, in seconds."""
        ...

    @property
    def double_press(self) -> float:
        """The recogniser's double-press window, in seconds."""
        ...

    @property
    def bounce(self) -> float:
        """The recogniser's contact-bounce gap, in seconds."""
        ...

    @property
    def both_window(self) -> float:
        """The recogniser's chord window, in seconds."""
        ...

    def key_map(self) -> dict[int, str]:
        """Each mapped key's evdev code -> its button or command name."""
        ...

    def ignored_codes(self) -> set[int]:
        """Keys that mean nothing, never logged as unmapped."""
        ...

    def gesture_commands(self) -> dict[tuple[GestureKind, str], str]:
        """A researcher device's gestures -> commands; empty: gestures go out as they are."""
        ...

    def match(self) -> profiles.Match:
        """The USB ids (and interface) to find the device by when its path is missing."""
        ...


# Where the researcher's commands come from (the `source` of [researcher]).
ResearcherSource = Literal["device", "keypad", "keyfob"]
# A researcher's hold on the children's keyfob: longer than any child's press.
Hold = Annotated[float, msgspec.Meta(ge=2.0, le=10.0, extra={"unit": "s"})]


class ResearcherSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Where the researcher's commands come from, and that device's keys.

    source "device" (the default): a keypad or remote of the researcher's own, opened
    by `device` or `name` like the keyfob, each key in `keys` one command given at its
    press; the children's keyfob then carries only their answers. "keypad": the extra
    keys of the children's keypad ([keyfob.commands]). "keyfob": the children's keyfob
    alone, where a researcher's gesture is a hold of `hold_s` (game.commands: long
    green, long red, both) begun while Kaspar is asking the children nothing.
    """

    source: ResearcherSource = "device"
    # "sim": a simulated device (tests, the demo, `kasparctl run --sim`).
    backend: Literal["real", "sim"] = "real"
    device: DevicePath | None = None
    name: DeviceName | None = None
    vendor: UsbId | None = None
    product: UsbId | None = None
    interface: Interface | None = None
    grab: bool = True
    # The device family (hal/keyfob/remotes/, docs/keyfob-and-voice.md): its buttons and
    # which command each press or hold gives. The default is the most common presenter.
    profile: ProfileName = "logitech-r400"
    # Key (evdev name or number) -> command, each at its press; given, these replace the
    # profile's commands (`kasparctl keyfob learn` writes them).
    keys: dict[str, CommandName] = {}
    hold_s: Hold = 3.0
    reopen_grace: Annotated[float, msgspec.Meta(gt=0, le=60, extra={"unit": "s"})] = 5.0
    battery_warn_percent: BatteryPercent = 20

    def __post_init__(self) -> None:
        """Device and name exclude each other; every key resolves, each once.

        Raises SettingsError (a ValueError) naming the key.
        """
        if self.device is not None and self.name is not None:
            raise SettingsError("set device or name, not both")
        _profile("profile", self.profile)
        seen: dict[int, str] = {}
        for key in self.keys:
            code = _code(f"keys.{key}", _number_or_name(key))
            if code in seen and code != -1:
                raise SettingsError(f"keys.{key} is the same key as keys.{seen[code]}")
            seen[code] = key

    @property
    def device_path(self) -> str | None:
        """The path to open, or None when the device is found by name."""
        if self.name is not None:
            return None
        return self.device or DEFAULT_RESEARCHER_DEVICE

    def key_map(self) -> dict[int, str]:
        """Each key's evdev code -> its command name, or the recogniser's button ("green",
        "red") of a profile's button that carries holds."""
        if self.keys:
            return {key_code(_number_or_name(k)): command for k, command in self.keys.items()}
        return profiles.profile(self.profile).researcher_map(key_code).key_map

    def gesture_needs(self) -> GestureNeeds:
        """What the profile's buttons with holds listen for."""
        if self.keys:
            return GestureNeeds(both=False)
        return profiles.profile(self.profile).researcher_map(key_code).needs

    def gesture_commands(self) -> dict[tuple[GestureKind, str], str]:
        """The profile's holds and presses of its two gesture buttons -> commands."""
        if self.keys:
            return {}
        return profiles.profile(self.profile).researcher_map(key_code).gestures

    def ignored_codes(self) -> set[int]:
        """Keys the profile's device sends that mean nothing (Alt of Alt+Tab, NumLock)."""
        return profiles.profile(self.profile).ignored_codes(key_code)

    def commands_given(self) -> dict[str, str]:
        """Each key (`keys`) or the profile's gesture ("long start") -> its command."""
        if self.keys:
            return dict(self.keys)
        return dict(profiles.profile(self.profile).commands)

    def command_names(self) -> list[str]:
        """The commands this device gives, sorted (a simulated device offers these)."""
        return sorted(set(self.commands_given().values()))

    def match(self) -> profiles.Match:
        """The USB ids (and interface) to find the device by when its path is missing."""
        return _match(self.vendor, self.product, self.interface, self.profile)

    # A keypad's keys are commands given at their press: the recogniser's timings only
    # matter for gestures it never sees there, so they are the keyfob's defaults.
    @property
    def long_press(self) -> float:
        """The keyfob's default long press (unused: every key is a command at its press)."""
        return 1.0

    @property
    def double_press(self) -> float:
        """The keyfob's default double-press window (unused here)."""
        return 0.4

    @property
    def bounce(self) -> float:
        """The keyfob's default bounce gap: a key released and pressed within it is held."""
        return 0.03

    @property
    def both_window(self) -> float:
        """The keyfob's default chord window (unused here)."""
        return 0.3
