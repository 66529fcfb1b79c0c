"""Each device profile fed its real event sequences through evdev's parsing (a pipe device).

Per profile: every button, the alternating keys of one button, autorepeat while held,
the hwdb's codes, a keypad's synthetic NumLock; the Logitech receiver's two nodes with
one name (the keys' node found by name and by its ids, never the other); the doc's
tables generated from the data files.
"""

from __future__ import annotations

import asyncio
import re
from pathlib import Path

import pytest
from evdev import ecodes
from evdev_pipe import ManualClock, PipeBank, PipeInputDevice
from sysfs_tree import add_node

from hal.errors import SettingsError
from hal.keyfob import profiles
from hal.keyfob.gestures import ANSWERS_ONLY, Gesture, GestureKind
from hal.keyfob.reader import Keyfob
from hal.keyfob.settings import KeyfobSettings, ResearcherSettings
from kasparctl.vocabulary import Command

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "keyfob-and-voice.md"
K = ecodes.ecodes

# (what the researcher does, the keys it sends as (key, value, seconds after the
# previous), how long the clock then moves, the commands that must come of it).
Step = tuple[str, list[tuple[str, int, float]], float, list[str]]


def tap(key: str) -> list[tuple[str, int, float]]:
    return [(key, 1, 0.0), (key, 0, 0.12)]


def double(key: str) -> list[tuple[str, int, float]]:
    return [(key, 1, 0.0), (key, 0, 0.1), (key, 1, 0.15), (key, 0, 0.1)]


def held(key: str) -> list[tuple[str, int, float]]:
    # The first autorepeat after 250 ms, then every 33 ms (the kernel's defaults).
    return [(key, 1, 0.0), (key, 2, 0.25), *[(key, 2, 0.033)] * 8]


TWO_BUTTONS = lambda forward, back: [  # noqa: E731
    ("forward", tap(forward), 1.0, ["next"]),
    ("back", tap(back), 1.0, ["pause"]),
    ("back twice", double(back), 1.0, ["undo"]),
    ("back held, autorepeating", held(back), 1.1, ["stop"]),
    ("released", [(back, 0, 0.5)], 1.0, []),
    ("forward held, autorepeating", held(forward), 1.1, ["reopen"]),
    ("released", [(forward, 0, 0.5)], 1.0, []),
]

SCENARIOS: dict[str, list[Step]] = {
    "logitech-r400": [
        ("forward", tap("KEY_PAGEDOWN"), 1.0, ["next"]),
        ("back", tap("KEY_PAGEUP"), 1.0, ["pause"]),
        ("blank", tap("KEY_DOT"), 1.0, ["undo"]),
        ("start, sending F5", tap("KEY_F5"), 1.0, ["reopen"]),
        ("start again, now sending Esc", tap("KEY_ESC"), 1.0, ["reopen"]),
        ("start held (Esc), autorepeating", held("KEY_ESC"), 1.1, ["stop"]),
        ("released", [("KEY_ESC", 0, 0.4)], 1.0, []),
        ("with the hwdb: start", tap("KEY_PRESENTATION"), 1.0, ["reopen"]),
        ("with the hwdb: start held", held("KEY_PRESENTATION"), 1.1, ["stop"]),
        ("released", [("KEY_PRESENTATION", 0, 0.4)], 1.0, []),
        ("with the hwdb: blank", tap("KEY_DISPLAYTOGGLE"), 1.0, ["undo"]),
    ],
    "kensington": TWO_BUTTONS("KEY_PAGEDOWN", "KEY_PAGEUP"),
    "satechi-sp600": [
        ("forward", tap("KEY_PAGEDOWN"), 1.0, ["next"]),
        ("back", tap("KEY_PAGEUP"), 1.0, ["pause"]),
        ("pause button ('b')", tap("KEY_B"), 1.0, ["undo"]),
        ("start (F5)", tap("KEY_F5"), 1.0, ["reopen"]),
        ("start (Esc)", tap("KEY_ESC"), 1.0, ["reopen"]),
        ("start held", held("KEY_F5"), 1.1, ["stop"]),
        ("released", [("KEY_F5", 0, 0.4)], 1.0, []),
        ("arrows", tap("KEY_LEFT") + tap("KEY_RIGHT") + tap("KEY_UP"), 1.0, []),
        ("Alt+Tab", [("KEY_LEFTALT", 1, 0), ("KEY_TAB", 1, 0.05), ("KEY_TAB", 0, 0.05),
                     ("KEY_LEFTALT", 0, 0.05)], 1.0, []),
    ],
    "norwii": TWO_BUTTONS("KEY_DOWN", "KEY_UP"),
    "generic-keyfob": TWO_BUTTONS("KEY_PAGEDOWN", "KEY_PAGEUP"),
    "numeric-keypad": [
        ("enter, wrapped in NumLock",
         [("KEY_NUMLOCK", 1, 0), ("KEY_NUMLOCK", 0, 0.01), ("KEY_KPENTER", 1, 0.01),
          ("KEY_KPENTER", 0, 0.1), ("KEY_NUMLOCK", 1, 0.01), ("KEY_NUMLOCK", 0, 0.01)],
         0.5, ["next"]),
        ("0 on the keypad", tap("KEY_KP0"), 1.0, ["pause"]),
        ("0 as a top-row digit", tap("KEY_0"), 1.0, ["pause"]),
        ("0 held, autorepeating", [*held("KEY_KP0"), ("KEY_KP0", 0, 0.1)], 1.1, ["pause"]),
        ("dot", tap("KEY_KPDOT"), 1.0, ["undo"]),
        ("minus", tap("KEY_KPMINUS"), 1.0, ["stop"]),
        ("plus", tap("KEY_KPPLUS"), 1.0, ["reopen"]),
    ],
    "foot-pedal": [
        ("middle", tap("KEY_F15"), 1.0, ["next"]),
        ("left", tap("KEY_F14"), 1.0, ["pause"]),
        ("left held", held("KEY_F14"), 1.1, ["stop"]),
        ("released", [("KEY_F14", 0, 0.3)], 1.0, []),
        ("right", tap("KEY_F16"), 1.0, ["undo"]),
        ("right held", held("KEY_F16"), 1.1, ["reopen"]),
        ("released", [("KEY_F16", 0, 0.3)], 1.0, []),
    ],
}

# The children's keyfob: each profile's green and red, from every key of the button.
ANSWERS: dict[str, list[tuple[list[tuple[str, int, float]], str]]] = {
    "logitech-r400": [(tap("KEY_PAGEDOWN"), "green"), (tap("KEY_PAGEUP"), "red")],
    "kensington": [(tap("KEY_PAGEDOWN"), "green"), (held("KEY_PAGEUP"), "red")],
    "satechi-sp600": [(tap("KEY_PAGEDOWN"), "green"), (tap("KEY_PAGEUP"), "red")],
    "norwii": [(tap("KEY_DOWN"), "green"), (tap("KEY_UP"), "red")],
    "generic-keyfob": [(tap("KEY_PAGEDOWN"), "green"), (tap("KEY_PAGEUP"), "red")],
    "numeric-keypad": [
        ([("KEY_NUMLOCK", 1, 0), ("KEY_NUMLOCK", 0, 0.01), *tap("KEY_KP1")], "green"),
        (tap("KEY_1"), "green"),
        (tap("KEY_KP3"), "red"),
    ],
    "foot-pedal": [(tap("KEY_F16"), "green"), (tap("KEY_F14"), "red")],
}


@pytest.fixture
def bank(tmp_path: Path):
    (tmp_path / "dev").mkdir()
    bank = PipeBank(tmp_path / "dev")
    yield bank
    bank.dispose()


def write(device: PipeInputDevice, keys: list[tuple[str, int, float]]) -> None:
    device.events(*[(K[key], value, gap) for key, value, gap in keys])


async def drain(keyfob: Keyfob, quiet: float = 0.15) -> list[Gesture]:
    out = []
    while True:
        try:
            event = await asyncio.wait_for(keyfob.next_event(), quiet)
        except TimeoutError:
            return out
        assert isinstance(event, Gesture), event
        out.append(event)


async def play(device, keyfob, clock, keys, advance) -> list[Gesture]:
    """Each key change when its time comes: the clock moves by its gap, then the kernel
    writes it (stamped by the pipe's own clock), then the reader reads it."""
    for key, value, gap in keys:
        await clock.advance(gap)
        device.events((K[key], value, gap))
        await asyncio.sleep(0.01)
    await clock.advance(advance)
    return await drain(keyfob)


def test_every_profile_is_tested_and_reaches_every_command():
    assert set(profiles.names()) == set(SCENARIOS) == set(ANSWERS)
    assert set(Command) == set(profiles.COMMANDS)
    for name in profiles.names():
        given = set(profiles.profile(name).commands.values())
        assert set(profiles.SESSION_COMMANDS) <= given <= set(Command), name


@pytest.mark.parametrize("name", sorted(SCENARIOS))
async def test_the_researchers_device_gives_each_command(bank, name):
    device = bank.plug("kaspar-researcher")
    clock = ManualClock()
    settings = ResearcherSettings(profile=name, device=device.path)
    keyfob = Keyfob(settings, clock, role="researcher", needs=settings.gesture_needs(),
                    opener=bank.open, input_dir=str(bank.directory))  # fmt: skip
    await keyfob.start()
    try:
        for what, keys, advance, expected in SCENARIOS[name]:
            gestures = await play(device, keyfob, clock, keys, advance)
            assert [g.kind for g in gestures] == [GestureKind.COMMAND] * len(gestures), what
            assert [g.button for g in gestures] == expected, f"{name}: {what}"
    finally:
        await keyfob.close()


@pytest.mark.parametrize("name", sorted(ANSWERS))
async def test_the_childrens_keyfob_gives_green_and_red(bank, name):
    device = bank.plug("kaspar-keyfob")
    clock = ManualClock()
    keyfob = Keyfob(KeyfobSettings(profile=name, device=device.path), clock,
                    needs=ANSWERS_ONLY, opener=bank.open, input_dir=str(bank.directory))  # fmt: skip
    await keyfob.start()
    try:
        for keys, expected in ANSWERS[name]:
            if keys[-1][1] != 0:
                keys = [*keys, (keys[-1][0], 0, 0.1)]
            gestures = await play(device, keyfob, clock, keys, 0.5)
            assert [(g.kind, g.button) for g in gestures] == [(GestureKind.PRESS, expected)], keys
    finally:
        await keyfob.close()


R400_KEYS = {K[k] for k in ("KEY_PAGEDOWN", "KEY_PAGEUP", "KEY_F5", "KEY_ESC", "KEY_DOT")}
RECEIVER = "Logitech USB Receiver"


def two_nodes(tmp_path: Path, bank: PipeBank) -> tuple[PipeInputDevice, PipeInputDevice]:
    """The R400's receiver: event9 (interface 0, the keys) and event10 (interface 1, the
    consumer and system controls), one name; event10 sorts first as a string."""
    sys_root = tmp_path / "sys"
    add_node(sys_root, 9, RECEIVER, 0x046D, 0xC52D, interface=0, keys=R400_KEYS)
    add_node(sys_root, 10, RECEIVER, 0x046D, 0xC52D, interface=1,
             keys={K["KEY_VOLUMEUP"], K["KEY_SLEEP"]})  # fmt: skip
    return bank.plug("event9", RECEIVER), bank.plug("event10", RECEIVER)


@pytest.mark.parametrize("how", ["name", "ids"])
async def test_the_receivers_key_node_is_opened_never_the_other(tmp_path, bank, how):
    keys_node, other = two_nodes(tmp_path, bank)
    clock = ManualClock()
    if how == "name":
        settings = ResearcherSettings(name=RECEIVER)
    else:  # no rule made /dev/input/kaspar-researcher: the profile's ids and interface
        settings = ResearcherSettings(device=str(bank.directory / "kaspar-researcher"))
    keyfob = Keyfob(settings, clock, role="researcher", needs=settings.gesture_needs(),
                    opener=bank.open, input_dir=str(bank.directory),
                    sys_root=str(tmp_path / "sys"))  # fmt: skip
    await keyfob.start()
    try:
        assert bank.opened == [keys_node.path]
        # Both nodes send: only the keys' node is read.
        write(other, tap("KEY_PAGEDOWN"))
        write(keys_node, tap("KEY_PAGEUP"))
        gestures = await play(keys_node, keyfob, clock, tap("KEY_DOT"), 0.5)
        assert [g.button for g in gestures] == ["pause", "undo"]
    finally:
        await keyfob.close()


def test_a_profile_that_does_not_exist_names_the_choices():
    with pytest.raises(SettingsError, match=r"profile: expected one of the profiles .*logitech-r400.*found 'r400'"):
        ResearcherSettings(profile="r400")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('title = "x"\n[buttons]\na = ["KEY_A"]\n[commands]\n"hold a" = "next"',
         "commands.hold a: expected 'press', 'long' or 'double'"),
        ('title = "x"\n[buttons]\na = ["KEY_A"]\n[commands]\n"press a" = "dance"',
         "commands.press a: expected one of next, pause, undo, stop, reopen, away, choose, absent, found 'dance'"),
        ('title = "x"\n[buttons]\na = ["KEY_A"]\nb = ["KEY_B"]\nc = ["KEY_C"]\n[commands]\n'
         '"long a" = "next"\n"long b" = "stop"\n"long c" = "undo"',
         "commands: expected holds and double presses on at most two buttons"),
        ('title = "x"\n[buttons]\na = ["KEY_A"]\nb = ["KEY_A"]',
         "buttons.b: expected keys no other button sends, found 'KEY_A of a'"),
    ],
)  # fmt: skip
def test_a_wrong_profile_file_is_named_with_its_key(text, message):
    with pytest.raises(SettingsError, match=re.escape(f"x.toml: {message}")):
        profiles.parse("x", text, "x.toml")


def test_the_doc_shows_every_profiles_table_as_generated():
    text = DOC.read_text(encoding="utf-8")
    start = "<!-- profiles: generated by `python -m hal.keyfob.profiles` -->\n"
    end = "<!-- end of the profiles -->"
    assert start in text and end in text, "docs/keyfob-and-voice.md lacks the profile markers"
    shown = text.split(start, 1)[1].split(end, 1)[0]
    assert shown.strip() == profiles.key_tables().strip(), (
        "regenerate: python -m hal.keyfob.profiles, between the markers"
    )
