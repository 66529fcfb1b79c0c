"""`kasparctl keyfob list/learn` and check's device rows, on a fake sysfs and pipe devices.

The interactive learning is fed through evdev's real parsing: each prompt the room says
makes the "researcher" press (the test writes input_event records into the pipe behind
the node it opened).
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

import pytest
from evdev import ecodes
from evdev_pipe import PipeBank
from sysfs_tree import add_node

from hal.keyfob.devices import input_nodes
from hal.keyfob.settings import KeyfobSettings, ResearcherSettings
from kasparctl.bringup import remotes
from kasparctl.config import parse_config

K = ecodes.ecodes
RECEIVER = "Logitech USB Receiver"
R400_KEYS = {K[k] for k in ("KEY_PAGEDOWN", "KEY_PAGEUP", "KEY_F5", "KEY_ESC", "KEY_DOT")}
CONFIG = """\
# The robot in room 2.
language = "en"

[researcher]
# The old remote, by name.
name = "Old remote"  # replaced by learn
hold_s = 3.0

[voice]
backend = "sim"
"""


@pytest.fixture
def rig(tmp_path: Path):
    sys_root = tmp_path / "sys"
    add_node(sys_root, 3, "AT Translated Set 2 keyboard", 0x0001, 0x0001, interface=None,
             keys={K["KEY_A"]})  # fmt: skip
    add_node(sys_root, 9, RECEIVER, 0x046D, 0xC52D, interface=0, keys=R400_KEYS,
             battery={"capacity_level": "Normal"})  # fmt: skip
    add_node(sys_root, 10, RECEIVER, 0x046D, 0xC52D, interface=1, keys={K["KEY_VOLUMEUP"]})
    (tmp_path / "dev").mkdir()
    bank = PipeBank(tmp_path / "dev")
    for event, name in ((3, "AT Translated Set 2 keyboard"), (9, RECEIVER), (10, RECEIVER)):
        bank.plug(f"event{event}", name)
    yield tmp_path, sys_root, bank
    bank.dispose()


def press(device, *keys: str) -> None:
    for key in keys:
        device.events((K[key], 1, 0.1), (K[key], 0, 0.1))


def test_the_list_shows_each_node_with_its_ids_interface_and_battery(rig):
    _, sys_root, _ = rig
    lines = remotes.device_list(str(sys_root))
    assert lines == [
        " 1. /dev/input/event3  'AT Translated Set 2 keyboard'  0001:0001",
        " 2. /dev/input/event9  'Logitech USB Receiver'  046d:c52d interface 0, battery Normal (50%)",
        " 3. /dev/input/event10  'Logitech USB Receiver'  046d:c52d interface 1",
    ]


def test_a_battery_of_scope_system_is_not_the_remotes(tmp_path):
    add_node(tmp_path, 4, "Remote", 0x1234, 0x5678, battery={"capacity": "80"},
             battery_scope="System")  # fmt: skip
    add_node(tmp_path, 5, "Other", 0x1234, 0x5679, port=3, battery={"capacity": "12"})
    first, second = input_nodes(str(tmp_path))
    assert first.battery is None
    assert second.battery is not None and second.battery.percent == 12


def learn(rig, role: str, answers: dict[str, list[str]], timeout: float = 0.3):
    tmp_path, sys_root, bank = rig
    config = tmp_path / "kaspar.toml"
    config.write_text(CONFIG)
    device = bank.devices[str(bank.directory / "event9")]
    said: list[str] = []

    def say(line: str) -> None:
        said.append(line)
        for what, keys in answers.items():
            if line.startswith(f"Press the button for {what!r}") or (line.startswith(
                "That button is already") and what == "again"):
                press(device, *keys)

    written = remotes.learn(
        str(config), role, "2", say=say, timeout=timeout, sys_root=str(sys_root),
        input_dir=str(bank.directory), rules_dir=str(tmp_path / "rules"), opener=bank.open,
    )  # fmt: skip
    return config, written, said


def test_learning_the_researchers_presenter_writes_its_keys_and_its_rule(rig):
    config, (_path, rule), said = learn(rig, "researcher", {
        "next": ["KEY_PAGEDOWN", "KEY_PAGEDOWN"],
        "pause": ["KEY_PAGEDOWN", "KEY_PAGEUP", "KEY_PAGEUP"],  # first the button of next
        "undo": ["KEY_DOT", "KEY_DOT"],
        "stop": ["KEY_F5", "KEY_ESC"],  # the start button alternates
        # reopen: nothing pressed, left out
    })  # fmt: skip
    assert "That button is already 'next': press the one for 'pause'." in said
    assert "stop: KEY_F5, KEY_ESC" in said and "No button for 'reopen'." in said
    text = config.read_text()
    # Every comment and other line kept; the name replaced by the node's stable path.
    assert text.startswith("# The robot in room 2.\nlanguage = \"en\"\n\n[researcher]\n# The old remote")
    assert "hold_s = 3.0" in text and "Old remote" not in text
    data = tomllib.loads(text)
    assert data["researcher"] == {
        "hold_s": 3.0, "device": "/dev/input/kaspar-researcher",
        "vendor": "046d", "product": "c52d", "interface": 0,
        "keys": {"KEY_PAGEDOWN": "next", "KEY_PAGEUP": "pause", "KEY_DOT": "undo",
                 "KEY_F5": "stop", "KEY_ESC": "stop"},
    }  # fmt: skip
    researcher = parse_config(text, "kaspar.toml").researcher
    assert researcher.key_map()[K["KEY_ESC"]] == researcher.key_map()[K["KEY_F5"]] == "stop"
    assert rule == rig[0] / "rules" / "99-kaspar-researcher.rules"
    (line,) = [text for text in rule.read_text().splitlines() if not text.startswith("#")]
    assert line == (
        'ACTION=="add|change", SUBSYSTEM=="input", KERNEL=="event*", ATTRS{idVendor}=="046d", '
        'ATTRS{idProduct}=="c52d", ENV{ID_USB_INTERFACE_NUM}=="00", '
        'SYMLINK+="input/kaspar-researcher", GROUP="input", MODE="0660", '
        'ENV{LIBINPUT_IGNORE_DEVICE}="1"'
    )
    assert oct(rule.stat().st_mode & 0o777) == "0o644"


def test_learning_the_childrens_keyfob(rig):
    config, _, _ = learn(rig, "keyfob", {"green": ["KEY_PAGEDOWN"] * 2, "red": ["KEY_PAGEUP"] * 2})
    keyfob = parse_config(config.read_text(), "kaspar.toml").keyfob
    assert keyfob.device == "/dev/input/kaspar-keyfob" and keyfob.interface == 0
    assert keyfob.key_map() == {K["KEY_PAGEDOWN"]: "green", K["KEY_PAGEUP"]: "red"}


def test_a_button_the_game_needs_not_pressed_stops_learning_and_writes_nothing(rig):
    with pytest.raises(remotes.RemoteError, match=r"no key pressed for 'pause' within 0\.3 s"):
        learn(rig, "researcher", {"next": ["KEY_PAGEDOWN"] * 2})
    assert (rig[0] / "kaspar.toml").read_text() == CONFIG
    assert not (rig[0] / "rules").exists()


def test_a_device_that_is_not_there_is_named(rig):
    with pytest.raises(remotes.RemoteError, match="no input device 'event99': expected a number from 1 to 3"):
        remotes.choose("event99", str(rig[1]))


# -- check ---------------------------------------------------------------------------


def checked(rig, text: str, press_within=None, pressed: tuple[str, ...] = ()):
    _tmp_path, sys_root, bank = rig
    for key in pressed:
        press(bank.devices[str(bank.directory / "event9")], key)
    config = parse_config(text.replace("DEV", str(bank.directory)), "kaspar.toml")
    return remotes.device_rows(config, press_within, sys_root=str(sys_root),
                               input_dir=str(bank.directory), opener=bank.open, say=lambda _: None)  # fmt: skip


KEYFOB_AND_RECEIVER = """
[keyfob]
device = "DEV/event3"
green = "KEY_A"
red = "KEY_B"
[researcher]
device = "DEV/kaspar-researcher"
"""


def test_check_finds_the_researchers_receiver_by_its_ids_when_no_rule_made_the_path(rig):
    rows = checked(rig, KEYFOB_AND_RECEIVER)
    assert [(r.part, r.ok) for r in rows] == [("keyfob", True), ("researcher", True), ("researcher", True)]
    assert rows[1].detail == f"{rig[2].directory}/event9 ({RECEIVER}), 046d:c52d interface 0"
    assert rows[2].detail == "battery Normal (50%)"


def test_check_asks_for_a_press_and_names_the_key(rig):
    bank = rig[2]
    press(bank.devices[str(bank.directory / "event3")], "KEY_B")
    rows = checked(rig, KEYFOB_AND_RECEIVER, press_within=1.0, pressed=("KEY_VOLUMEUP", "KEY_F5"))
    assert [(r.part, r.ok, r.detail) for r in rows if "pressed" in r.detail] == [
        ("keyfob", True, "KEY_B pressed: red"),
        ("researcher", True, "KEY_F5 pressed: reopen, hold: stop"),
    ]


def test_check_with_no_press_fails_the_row(rig):
    rows = checked(rig, KEYFOB_AND_RECEIVER, press_within=1.0)
    assert [(r.part, r.ok, r.detail) for r in rows if "pressed" in r.detail] == [
        ("keyfob", False, "no button pressed within 1 s"),
        ("researcher", False, "no button pressed within 1 s"),
    ]


def test_a_low_battery_fails_the_check_with_its_level(rig, tmp_path):
    _tmp, sys_root, _bank = rig
    supply = next((sys_root / "devices").rglob("hidpp_battery_9"))
    (supply / "capacity").write_text("12\n")
    rows = checked(rig, KEYFOB_AND_RECEIVER + "battery_warn_percent = 15\n")
    assert (rows[-1].part, rows[-1].ok, rows[-1].detail) == (
        "researcher", False,
        "battery Normal (12%), below 15%: change or charge it before the session",
    )  # fmt: skip


def test_the_default_researcher_needs_no_configuration(rig):
    rows = checked(rig, '[keyfob]\ndevice = "DEV/event3"\n')
    assert rows[1].ok and "event9" in rows[1].detail


def test_a_missing_device_is_a_failed_row(rig):
    rows = checked(rig, '[keyfob]\ndevice = "DEV/kaspar-keyfob"\n[researcher]\ndevice = "DEV/nothing"\nvendor = "ffff"\n')
    assert [(r.part, r.ok) for r in rows] == [("keyfob", False), ("researcher", False)]
    assert "kaspar-keyfob" in rows[0].detail and "nothing" in rows[1].detail


def test_settings_by_default():
    assert ResearcherSettings().profile == "logitech-r400"
    assert KeyfobSettings().profile == "generic-keyfob"
    assert os.path.basename(remotes.rule_path("researcher")) == "99-kaspar-researcher.rules"


# -- the service's battery warning ---------------------------------------------------


def test_the_service_warns_of_a_battery_below_its_level(rig):
    from kasparctl.service.batteries import low_batteries

    _tmp, sys_root, bank = rig
    os.symlink("event9", bank.directory / "kaspar-researcher")  # as the udev rule makes it
    supply = next((sys_root / "devices").rglob("hidpp_battery_9"))
    text = f'[keyfob]\ndevice = "{bank.directory}/event3"\n[researcher]\ndevice = "{bank.directory}/kaspar-researcher"\n'
    assert low_batteries(parse_config(text, "k.toml"), str(sys_root)) is None  # Normal, 50%
    (supply / "capacity_level").write_text("Low\n")
    assert low_batteries(parse_config(text, "k.toml"), str(sys_root)) == (
        "researcher's remote battery Low (15%) (below 20%)"
    )
    # No rule made the path: the receiver found by the profile's ids.
    os.unlink(bank.directory / "kaspar-researcher")
    assert low_batteries(parse_config(text, "k.toml"), str(sys_root)) is not None
    simulated = text.replace("[keyfob]\n", "[keyfob]\nbackend = 'sim'\n")
    assert low_batteries(parse_config(simulated, "k.toml"), str(sys_root)) is None


# -- the shipped rules ---------------------------------------------------------------

REPO = Path(__file__).resolve().parents[1]


def rule_lines(name: str) -> list[str]:
    text = (REPO / "systemd" / name).read_text().replace("\\\n", "")
    return [line for line in text.splitlines() if line.strip() and not line.startswith("#")]


@pytest.mark.parametrize(("name", "link"), [("99-kaspar-keyfob.rules", "kaspar-keyfob"),
                                            ("99-kaspar-researcher.rules", "kaspar-researcher")])  # fmt: skip
def test_each_shipped_input_rule_names_one_node(name, link):
    (line,) = rule_lines(name)
    assert 'KERNEL=="event*"' in line and f'SYMLINK+="input/{link}"' in line
    # One node of a device with several interfaces: the interface is matched too.
    assert 'ENV{ID_USB_INTERFACE_NUM}=="' in line, line


def test_the_researchers_rule_is_the_default_profiles_device():
    from hal.keyfob.profiles import profile

    match = profile(ResearcherSettings().profile).match
    (line,) = rule_lines("99-kaspar-researcher.rules")
    assert f'ATTRS{{idVendor}}=="{match.vendor:04x}"' in line
    assert f'ATTRS{{idProduct}}=="{match.product:04x}"' in line
    assert f'ENV{{ID_USB_INTERFACE_NUM}}=="{match.interface:02x}"' in line
    assert ResearcherSettings().device_path == "/dev/input/kaspar-researcher"


def test_install_sh_installs_both_input_rules():
    script = (REPO / "systemd" / "install.sh").read_text()
    (rules,) = [line for line in script.splitlines() if line.startswith("RULES=(")]
    assert "99-kaspar-keyfob.rules" in rules and "99-kaspar-researcher.rules" in rules
