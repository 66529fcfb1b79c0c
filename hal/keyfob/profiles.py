"""Device profiles: what a family of remotes really sends, and which command each button gives.

One TOML file per device family in hal/keyfob/remotes/ (docs/keyfob-and-voice.md lists
them, generated from these files). A profile names its buttons and the keys each one
sends: a button that alternates keys (the Logitech R400's start button sends F5, then Esc,
then F5) lists every key it sends, so any of them is that one button; a key a device sends
around others (a keypad's synthetic NumLock) is in `ignore`. Autorepeat (value 2) is never
a key change (hal.keyfob.reader drops it).

`[commands]` gives the researcher's commands as gestures of buttons: "press forward",
"long start" (held for the device's long press), "double back", "both" (the two buttons
that carry holds, held together). A device with fewer buttons than commands reaches
every command through holds and double presses, as game.commands does on one keyfob.
At most two buttons carry more than a press: they are the gesture recogniser's two
buttons (hal.keyfob.gestures), every other button is a command at its key-down.
`[answers]` says which button is the children's green and which their red, when the
device is used as the children's keyfob.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path

from hal.errors import SettingsError
from hal.keyfob.gestures import GREEN, RED, GestureKind, GestureNeeds

# A key name's evdev code (hal.keyfob.settings.key_code, passed in: settings imports this).
_Resolve = Callable[[str], int]
# The parser's error maker: key, expected, found.
_Fail = Callable[[str, str, object], SettingsError]

# The commands a profile may give (kasparctl.vocabulary.Command, which hal cannot import;
# tests/test_keyfob_profiles.py holds the two equal).
# The commands every profile must reach: a session is run with these alone.
SESSION_COMMANDS = ("next", "pause", "undo", "stop", "reopen")
# Every command a profile may give (kasparctl.vocabulary.Command; hal may not import it):
# choosing the group, marking it absent and a child away need keys a presenter lacks.
COMMANDS = (*SESSION_COMMANDS, "away", "choose", "absent")
# What a profile's gesture may be, before the button's name.
GESTURE_KINDS = {"press": GestureKind.PRESS, "long": GestureKind.LONG, "double": GestureKind.DOUBLE}
SLOTS = (GREEN, RED)
DIRECTORY = "remotes"


@dataclass(frozen=True, slots=True)
class Match:
    """How to find the device without a udev rule: its ids and the interface with its keys."""

    vendor: int | None = None
    product: int | None = None
    interface: int | None = None

    def describe(self) -> str:
        """046d:c52d interface 0, as the doc prints it."""
        if self.vendor is None:
            return "any"
        ids = f"{self.vendor:04x}:{self.product:04x}" if self.product is not None else (
            f"{self.vendor:04x}:*"
        )
        return ids + (f" interface {self.interface}" if self.interface is not None else "")


@dataclass(frozen=True, slots=True)
class ResearcherMap:
    """A profile as the researcher's device: what the reader maps, listens for, translates."""

    # Each key's code -> a slot ("green", "red": a button with holds) or a command name.
    key_map: dict[int, str]
    needs: GestureNeeds
    # (kind, slot) -> command, for the gestures of the slot buttons.
    gestures: dict[tuple[GestureKind, str], str]


@dataclass(frozen=True, slots=True)
class Profile:
    """One device family, as its file gives it."""

    name: str  # the file's stem: "logitech-r400"
    title: str
    notes: str
    match: Match
    # Button -> the keys it sends (evdev names), in file order.
    buttons: dict[str, tuple[str, ...]]
    ignore: tuple[str, ...]
    # Gesture ("press forward", "long start", "both") -> command.
    commands: dict[str, str]
    # "green" / "red" -> button, for the children's keyfob.
    answers: dict[str, str] = field(default_factory=dict)

    def slots(self) -> dict[str, str]:
        """The buttons carrying more than a press -> the recogniser's button they become."""
        held: list[str] = []
        for gesture in self.commands:
            kind, button = _split(gesture)
            if kind is not GestureKind.PRESS and button is not None and button not in held:
                held.append(button)
        if any(gesture == "both" for gesture in self.commands):
            for button in self.buttons:
                if len(held) >= 2:
                    break
                if button not in held:
                    held.append(button)
        return dict(zip(held, SLOTS, strict=False))

    def researcher_map(self, key_code: _Resolve) -> ResearcherMap:
        """The profile as a researcher's device: every key mapped, alternates as one button."""
        slots = self.slots()
        key_map: dict[int, str] = {}
        gestures: dict[tuple[GestureKind, str], str] = {}
        kinds: dict[str, set[GestureKind]] = {GREEN: {GestureKind.PRESS}, RED: {GestureKind.PRESS}}
        plain: dict[str, str] = {}
        for gesture, command in self.commands.items():
            kind, button = _split(gesture)
            if button is None:  # both
                gestures[(GestureKind.BOTH, "both")] = command
                continue
            if button in slots:
                gestures[(kind, slots[button])] = command
                kinds[slots[button]].add(kind)
            else:
                plain[button] = command
        for button, keys in self.buttons.items():
            target = slots.get(button) or plain.get(button)
            if target is None:
                continue
            for key in keys:
                key_map[key_code(key)] = target
        needs = GestureNeeds(
            green=frozenset(kinds[GREEN]),
            red=frozenset(kinds[RED]),
            both=(GestureKind.BOTH, "both") in gestures,
        )
        return ResearcherMap(key_map, needs, gestures)

    def answer_map(self, key_code: _Resolve) -> dict[int, str]:
        """The profile as the children's keyfob: each key of green and red -> "green"/"red",
        and the other buttons' presses -> their command (a keypad's extra keys)."""
        mapping: dict[int, str] = {}
        for slot, button in self.answers.items():
            for key in self.buttons[button]:
                mapping[key_code(key)] = slot
        for gesture, command in self.commands.items():
            kind, pressed = _split(gesture)
            if kind is GestureKind.PRESS and pressed is not None and pressed not in (
                self.answers.values()
            ):
                for key in self.buttons[pressed]:
                    mapping.setdefault(key_code(key), command)
        return mapping

    def ignored_codes(self, key_code: _Resolve) -> set[int]:
        """Keys the device sends that mean nothing (synthetic NumLock, Alt of Alt+Tab)."""
        return {key_code(key) for key in self.ignore}


def _split(gesture: str) -> tuple[GestureKind, str | None]:
    if gesture == "both":
        return GestureKind.BOTH, None
    kind, _, button = gesture.partition(" ")
    return GESTURE_KINDS[kind], button


def names() -> list[str]:
    """Every profile in the package, by name."""
    folder = resources.files(__package__).joinpath(DIRECTORY)
    return sorted(
        Path(entry.name).stem for entry in folder.iterdir() if entry.name.endswith(".toml")
    )


@cache
def profile(name: str) -> Profile:
    """The profile `name` (a file of hal/keyfob/remotes/); SettingsError naming it if unknown
    or if its file is wrong."""
    if name not in names():
        raise SettingsError(f"expected one of the profiles {', '.join(names())}, found {name!r}")
    source = resources.files(__package__).joinpath(DIRECTORY, f"{name}.toml")
    return parse(name, source.read_text(encoding="utf-8"), f"hal/keyfob/{DIRECTORY}/{name}.toml")


def parse(name: str, text: str, where: str) -> Profile:
    """A profile file's text into a Profile; SettingsError naming `where`, the key, what was
    expected and what was found."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SettingsError(f"{where}: not valid TOML: {error}") from None

    def fail(key: str, expected: str, found: object) -> SettingsError:
        return SettingsError(f"{where}: {key}: expected {expected}, found {found!r}")

    unknown = set(data) - {"title", "notes", "match", "buttons", "ignore", "commands", "answers"}
    if unknown:
        raise fail(", ".join(sorted(unknown)), "no such key", sorted(unknown))
    title = data.get("title")
    if not isinstance(title, str) or not title:
        raise fail("title", "the device family's name", title)
    buttons_data = data.get("buttons")
    if not isinstance(buttons_data, dict) or not buttons_data:
        raise fail("buttons", "a table of button = [keys]", buttons_data)
    buttons: dict[str, tuple[str, ...]] = {}
    for button, keys in buttons_data.items():
        if not isinstance(keys, list) or not keys or not all(isinstance(k, str) for k in keys):
            raise fail(f"buttons.{button}", "a list of key names", keys)
        buttons[button] = tuple(keys)
    ignore = data.get("ignore", [])
    if not isinstance(ignore, list) or not all(isinstance(k, str) for k in ignore):
        raise fail("ignore", "a list of key names", ignore)
    commands = _commands(data.get("commands", {}), buttons, fail)
    answers = data.get("answers", {})
    if not isinstance(answers, dict) or (answers and set(answers) != {GREEN, RED}):
        raise fail("answers", "green and red, each a button", answers)
    for slot, button in answers.items():
        if button not in buttons:
            raise fail(f"answers.{slot}", f"one of the buttons {', '.join(buttons)}", button)
    result = Profile(
        name=name,
        title=title,
        notes=str(data.get("notes", "")),
        match=_match(data.get("match", {}), fail),
        buttons=buttons,
        ignore=tuple(ignore),
        commands=commands,
        answers=dict(answers),
    )
    held = sorted({b for k, b in map(_split, commands) if k is not GestureKind.PRESS and b})
    if len(held) > 2:
        raise fail("commands", "holds and double presses on at most two buttons", held)
    seen: dict[str, str] = {}
    for button, keys in buttons.items():
        for key in keys:
            if key in seen:
                other = f"{key} of {seen[key]}"
                raise fail(f"buttons.{button}", "keys no other button sends", other)
            seen[key] = button
    return result


def _commands(
    data: object, buttons: Mapping[str, tuple[str, ...]], fail: _Fail
) -> dict[str, str]:
    if not isinstance(data, dict):
        raise fail("commands", "a table of gesture = command", data)
    commands: dict[str, str] = {}
    for gesture, command in data.items():
        if command not in COMMANDS:
            raise fail(f"commands.{gesture}", f"one of {', '.join(COMMANDS)}", command)
        if gesture != "both":
            kind, _, button = gesture.partition(" ")
            if kind not in GESTURE_KINDS or button not in buttons:
                raise fail(
                    f"commands.{gesture}",
                    f"'press', 'long' or 'double' and one of the buttons {', '.join(buttons)}",
                    gesture,
                )
        commands[gesture] = command
    return commands


def _match(data: object, fail: _Fail) -> Match:
    if not isinstance(data, dict):
        raise fail("match", "a table of vendor, product, interface", data)
    values: dict[str, int | None] = {}
    for key in ("vendor", "product"):
        text = data.get(key)
        if text is None:
            values[key] = None
            continue
        try:
            values[key] = int(str(text), 16)
        except ValueError:
            raise fail(f"match.{key}", "four hex digits such as '046d'", text) from None
    interface = data.get("interface")
    if interface is not None and (not isinstance(interface, int) or interface < 0):
        raise fail("match.interface", "the USB interface number", interface)
    return Match(values["vendor"], values["product"], interface)



_GESTURE_WORDS = {"press": "press", "long": "hold", "double": "double press"}


def key_table(chosen: Profile) -> str:
    """The profile as docs/keyfob-and-voice.md shows it: each button, its keys, its commands."""
    lines = [
        f"#### {chosen.title} (`profile = \"{chosen.name}\"`)",
        "",
        chosen.notes.strip(),
        "",
        (
            f"Found without a udev rule by its USB ids: {chosen.match.describe()}."
            if chosen.match.vendor is not None
            else "No fixed USB ids: found by a udev rule (or its name)."
        ),
        "",
        "| button | keys it sends | researcher's device | children's keyfob |",
        "|---|---|---|---|",
    ]
    answers = {button: slot for slot, button in chosen.answers.items()}
    for button, keys in chosen.buttons.items():
        given = []
        for gesture, command in chosen.commands.items():
            kind, _, named = gesture.partition(" ")
            if named == button:
                given.append(f"{_GESTURE_WORDS[kind]}: {command}")
        if "both" in chosen.commands and button in chosen.slots():
            given.append(f"both held: {chosen.commands['both']}")
        child = answers.get(button) or next(
            (c for g, c in chosen.commands.items() if g == f"press {button}"), ""
        )
        child_text = child if child in ("green", "red") else (
            f"{child} (keypad source)" if child else "-"
        )
        lines.append(
            f"| {button} | {', '.join(f'`{k}`' for k in keys)} | {'; '.join(given) or '-'} "
            f"| {child_text} |"
        )
    if chosen.ignore:
        lines += ["", "Ignored: " + ", ".join(f"`{key}`" for key in chosen.ignore) + "."]
    return "\n".join(lines)


def key_tables() -> str:
    """Every profile's table, in name order (the generated part of the doc)."""
    return "\n\n".join(key_table(profile(name)) for name in names()) + "\n"


if __name__ == "__main__":
    # python -m hal.keyfob.profiles > the tables to paste between the doc's markers
    print(key_tables(), end="")
