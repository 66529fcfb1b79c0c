"""The remotes at the robot: list the input devices, learn one, check both.

`kasparctl keyfob list` shows every event node sysfs knows (node, name, ids, USB
interface, battery). `kasparctl keyfob learn researcher|keyfob` opens the chosen node,
asks for each command's (or green's and red's) button, twice, so a button that
alternates keys (F5, then Esc) is learned as one; then writes the keys into kaspar.toml
(atomically, every comment and other line kept) and a udev rule that gives that one
node (vendor, product and interface) the stable name the configuration opens.
`kasparctl check` asks `device_rows` for the keyfob's and the researcher's rows: found,
by which node, its battery against the configured threshold, and with `--press` a key
pressed within the given seconds.
"""

from __future__ import annotations

import contextlib
import os
import select
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from hal.errors import HalError, KasparError
from hal.keyfob.devices import InputNode, input_nodes, node_of
from hal.keyfob.reader import EV_KEY, KEY_DOWN, EvdevDevice, Keyfob, open_evdev
from hal.keyfob.settings import (
    DEFAULT_DEVICE,
    DEFAULT_RESEARCHER_DEVICE,
    KeyfobSettings,
    ResearcherSettings,
)
from hal.servos.bus import open_failure
from kasparctl.bringup.engineer import write_atomically
from kasparctl.bringup.toml_patch import TextValue, set_text_keys
from kasparctl.config import Config, parse_config
from kasparctl.vocabulary import REQUIRED_COMMANDS, Command

RULES_DIR = "/etc/udev/rules.d"
# Keys a device sends around the one pressed: never a button of their own.
NOT_BUTTONS = frozenset(
    {69, 58, 70, 29, 97, 42, 54, 56, 100, 125, 126}
)  # NumLock CapsLock ScrollLock, Ctrl, Shift, Alt, Meta (left and right)
ROLES = ("researcher", "keyfob")


class RemoteError(KasparError):
    """A device that cannot be learned or checked; the message says why and what to do."""


@dataclass(frozen=True, slots=True)
class Row:
    """One row of `check` (kasparctl.bringup.readiness.Result has the same three fields)."""

    part: str
    ok: bool
    detail: str


# -- listing ------------------------------------------------------------------------


def device_list(sys_root: str = "/sys", input_dir: str = "/dev/input") -> list[str]:
    """One numbered line per event node, in the kernel's order."""
    nodes = input_nodes(sys_root)
    if not nodes:
        return [f"no input devices in {sys_root}/class/input"]
    return [f"{i:>2}. {node.describe(input_dir)}" for i, node in enumerate(nodes, 1)]


def choose(which: str, sys_root: str = "/sys") -> InputNode:
    """The node `which` names: its number in the list, "event9", or a path to it."""
    nodes = input_nodes(sys_root)
    if which.isdigit() and 1 <= int(which) <= len(nodes):
        return nodes[int(which) - 1]
    name = Path(os.path.realpath(which)).name if "/" in which else which
    for node in nodes:
        if node.node == name:
            return node
    raise RemoteError(
        f"no input device {which!r}: expected a number from 1 to {len(nodes)} or an event "
        "node (`kasparctl keyfob list` shows them)"
    )


# -- learning -----------------------------------------------------------------------


def what_to_learn(role: str) -> list[str]:
    """The buttons asked for, in order: the five commands, or green and red."""
    return [str(c) for c in Command] if role == "researcher" else ["green", "red"]


def key_downs(device: EvdevDevice, timeout: float) -> Iterator[int]:
    """Each key-down's code until `timeout` seconds pass without one (autorepeat and the
    keys in NOT_BUTTONS skipped)."""
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return
        ready, _, _ = select.select([device.fileno()], [], [], left)
        if not ready:
            return
        try:
            events = list(device.read())
        except BlockingIOError:
            continue
        for event in events:
            if event.type == EV_KEY and event.value == KEY_DOWN and event.code not in NOT_BUTTONS:
                yield event.code
                deadline = time.monotonic() + timeout


def learn_buttons(
    role: str, device: EvdevDevice, say: Callable[[str], None], timeout: float
) -> dict[str, list[int]]:
    """Ask for each button, twice; what each is -> its key codes (two for a button that
    alternates keys). RemoteError when a button the game needs is not pressed in time."""
    learned: dict[str, list[int]] = {}
    required = {str(c) for c in REQUIRED_COMMANDS} if role == "researcher" else {"green", "red"}
    for what in what_to_learn(role):
        taken = {code: other for other, codes in learned.items() for code in codes}
        later = "" if what in required else " (or wait to leave it out)"
        say(f"Press the button for {what!r}, then press it again{later}.")
        codes: list[int] = []
        for code in key_downs(device, timeout):
            if code in taken:
                say(f"That button is already {taken[code]!r}: press the one for {what!r}.")
                if codes:
                    break  # the first press stands alone
                continue
            codes.append(code)
            if len(codes) == 2:
                break
        if not codes:
            if what not in required:
                say(f"No button for {what!r}.")
                continue
            raise RemoteError(
                f"no key pressed for {what!r} within {timeout:g} s: a device with fewer "
                "buttons than commands needs a profile with holds (profile = "
                "'generic-keyfob', 'norwii' or 'kensington'; docs/keyfob-and-voice.md)"
            )
        # Pressed twice: the same key, or a button that alternates (F5, then Esc).
        learned[what] = sorted(set(codes), key=codes.index)
        say(f"{what}: {', '.join(key_name(code) for code in learned[what])}")
    return learned


def key_name(code: int) -> str:
    """evdev's name of a key code (the first of its aliases)."""
    from evdev import ecodes

    names = ecodes.KEY.get(code) or ecodes.BTN.get(code)
    if isinstance(names, list | tuple):
        return str(names[0])
    return str(names) if names else str(code)


def config_changes(
    role: str, node: InputNode, learned: dict[str, list[int]]
) -> list[tuple[str, dict[str, TextValue | None], bool]]:
    """The edits of kaspar.toml: (table, keys, exact) in order."""
    link = DEFAULT_RESEARCHER_DEVICE if role == "researcher" else DEFAULT_DEVICE
    usb = node.interface is not None
    device: dict[str, TextValue | None] = {
        "device": link,
        "name": None,
        "vendor": f"{node.vendor:04x}" if usb else None,
        "product": f"{node.product:04x}" if usb else None,
        "interface": node.interface if usb else None,
    }
    if role == "researcher":
        keys: dict[str, TextValue | None] = {
            key_name(code): command for command, codes in learned.items() for code in codes
        }
        return [("researcher", {**device, "keys": None}, False), ("researcher.keys", keys, True)]
    answers: dict[str, TextValue | None] = {
        slot: key_name(codes[0]) for slot, codes in learned.items()
    }
    return [("keyfob", {**device, **answers}, False)]


def udev_rule(role: str, node: InputNode) -> str:
    """The rule giving this one node the stable name the configuration opens."""
    link = "kaspar-researcher" if role == "researcher" else "kaspar-keyfob"
    if node.interface is not None:
        # ATTRS of one rule must all match on one device: the ids are the USB device's,
        # the interface the interface's; usb_id (60-persistent-input.rules) gives its
        # number as ENV{ID_USB_INTERFACE_NUM} on the event node.
        match = (
            f'ATTRS{{idVendor}}=="{node.vendor:04x}", ATTRS{{idProduct}}=="{node.product:04x}", '
            f'ENV{{ID_USB_INTERFACE_NUM}}=="{node.interface:02x}"'
        )
    else:
        match = f'ATTRS{{name}}=="{node.name}"'
    return (
        f"# Written by `kasparctl keyfob learn {role}` for {node.name!r} ({node.ids()}"
        f"{'' if node.interface is None else f', interface {node.interface}'}).\n"
        "# Apply: udevadm control --reload && udevadm trigger --subsystem-match=input\n"
        f'ACTION=="add|change", SUBSYSTEM=="input", KERNEL=="event*", {match}, '
        f'SYMLINK+="input/{link}", GROUP="input", MODE="0660", ENV{{LIBINPUT_IGNORE_DEVICE}}="1"\n'
    )


def rule_path(role: str, rules_dir: str = RULES_DIR) -> Path:
    """Where learn writes the rule (install.sh installs the same names)."""
    return Path(rules_dir, f"99-kaspar-{role}.rules")


def write_learned(
    config_path: str, role: str, node: InputNode, learned: dict[str, list[int]], rules_dir: str
) -> tuple[Path, Path]:
    """kaspar.toml edited (validated before it is written) and the rule written; both
    atomically. ConfigError if the edited configuration would not load."""
    path = Path(config_path)
    text = path.read_text(encoding="utf-8")
    for table, values, exact in config_changes(role, node, learned):
        text = set_text_keys(text, table, values, exact=exact)
    parse_config(text, str(path), path.parent, poses=False)
    write_atomically(path, text)
    rule = rule_path(role, rules_dir)
    if not rule.exists():
        rule.parent.mkdir(parents=True, exist_ok=True)
        rule.touch(mode=0o644)
    write_atomically(rule, udev_rule(role, node))
    return path, rule


def learn(
    config_path: str,
    role: str,
    which: str,
    *,
    say: Callable[[str], None] = print,
    timeout: float = 20.0,
    sys_root: str = "/sys",
    input_dir: str = "/dev/input",
    rules_dir: str = RULES_DIR,
    opener: Callable[[str], EvdevDevice] = open_evdev,
) -> tuple[Path, Path]:
    """Learn the device `which` as `role` and write the configuration and its rule."""
    if role not in ROLES:
        raise RemoteError(f"expected researcher or keyfob, found {role!r}")
    node = choose(which, sys_root)
    say(f"Learning {node.describe(input_dir)} as the {role}'s device.")
    device = opener(f"{input_dir}/{node.node}")
    try:
        with contextlib.suppress(OSError):
            device.grab()  # its keys reach nothing else while they are learned
        learned = learn_buttons(role, device, say, timeout)
    finally:
        device.close()
    written = write_learned(config_path, role, node, learned, rules_dir)
    say(f"Wrote {written[0]} and {written[1]}.")
    say("Apply the rule: udevadm control --reload && udevadm trigger --subsystem-match=input")
    return written


# -- checking -----------------------------------------------------------------------


def device_rows(
    config: Config,
    press_within: float | None = None,
    *,
    sys_root: str = "/sys",
    input_dir: str = "/dev/input",
    opener: Callable[[str], EvdevDevice] = open_evdev,
    say: Callable[[str], None] = print,
) -> list[Row]:
    """The keyfob's rows and the researcher's device's: found, node, battery, a press."""
    rows = _device("keyfob", config.keyfob, press_within, sys_root, input_dir, opener, say)
    researcher = config.researcher
    if researcher.source != "device":
        where = "the keypad's extra keys" if researcher.source == "keypad" else (
            "holds on the children's keyfob"
        )
        return [*rows, Row("researcher", True, f"commands from {where} (source = "
                                              f"{researcher.source!r})")]  # fmt: skip
    if config.keyfob.backend == "sim":
        # hal.build simulates the researcher's device beside a simulated keyfob.
        return [*rows, Row("researcher", True, "simulated (keyfob.backend = 'sim')")]
    return rows + _device("researcher", researcher, press_within, sys_root, input_dir, opener, say)


def _device(
    part: str,
    settings: KeyfobSettings | ResearcherSettings,
    press_within: float | None,
    sys_root: str,
    input_dir: str,
    opener: Callable[[str], EvdevDevice],
    say: Callable[[str], None],
) -> list[Row]:
    if settings.backend != "real":
        return [Row(part, True, f"simulated ({part}.backend = 'sim')")]
    from hal.clock import MonotonicClock

    reader = Keyfob(settings, MonotonicClock(), role=part, opener=opener,
                    input_dir=input_dir, sys_root=sys_root)  # fmt: skip
    try:
        device = reader.locate()
    except (HalError, OSError) as error:
        cause = error if isinstance(error, OSError) else error.__cause__
        if isinstance(cause, OSError) and cause.filename:
            return [Row(part, False, f"cannot open {cause.filename}: {open_failure(cause)}")]
        return [Row(part, False, f"not found: {error}")]
    try:
        path = os.fsdecode(device.path)
        node = node_of(path, sys_root) or node_of(f"{input_dir}/{Path(path).name}", sys_root)
        where = f"{path} ({device.name})"
        real = os.path.realpath(path)
        if real != path:
            where = f"{path} -> {real} ({device.name})"
        if node is not None:
            where += f", {node.ids()}" + (
                f" interface {node.interface}" if node.interface is not None else ""
            )
        rows = [Row(part, True, where)]
        rows += _battery(part, node, settings.battery_warn_percent)
        if press_within is not None:
            rows.append(_press(part, device, _meanings(settings), press_within, say))
        return rows
    finally:
        device.close()


def _battery(part: str, node: InputNode | None, warn_below: int) -> list[Row]:
    if node is None or node.battery is None:
        return []
    battery = node.battery
    if battery.percent is not None and battery.percent < warn_below:
        return [Row(part, False, f"{battery.describe()}, below {warn_below}%: change or "
                                 "charge it before the session")]  # fmt: skip
    return [Row(part, True, battery.describe())]


def _meanings(settings: KeyfobSettings | ResearcherSettings) -> dict[int, str]:
    """Each key -> what it gives: "green", "next", or a held button's "reopen, hold: stop"."""
    words = {"press": "", "long": "hold: ", "double": "double: ", "both": "both: "}
    gestures = settings.gesture_commands()
    meanings = {}
    for code, button in settings.key_map().items():
        given = [f"{words[kind.value]}{command}" for (kind, slot), command in gestures.items()
                 if slot == button]  # fmt: skip
        meanings[code] = ", ".join(given) if given else button
    return meanings


def _press(
    part: str, device: EvdevDevice, key_map: dict[int, str], within: float,
    say: Callable[[str], None],
) -> Row:  # fmt: skip
    say(f"Press a button of the {part} within {within:g} s...")
    for code in key_downs(device, within):
        meaning = key_map.get(code)
        if meaning is not None:
            return Row(part, True, f"{key_name(code)} pressed: {meaning}")
        say(f"{key_name(code)} means nothing on the {part}: press another")
    return Row(part, False, f"no button pressed within {within:g} s")

