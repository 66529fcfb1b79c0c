"""The [servos] table: the example robots load, and every mistake is named by its key."""

from __future__ import annotations

from pathlib import Path

import pytest

from hal.errors import HalError, SettingsError, UnknownBus
from hal.servos.settings import JointSettings, ServoSettings
from kasparctl.config import ConfigError, load_config, parse_config

SYSTEMD = Path(__file__).resolve().parent.parent / "systemd"

BUS = """
[[servos.buses]]
name = "body"
port = "/dev/kaspar-body"
protocol = "dynamixel1"
baud = 57600
"""


def joint(name="elbow", bus="body", servo_id=1, model="ax-12a", extra=""):
    return f"""
[[servos.joints]]
name = "{name}"
bus = "{bus}"
id = {servo_id}
model = "{model}"
range_deg = [-30.0, 30.0]
{extra}
"""


def error_of(text: str) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "kaspar.toml")
    return str(caught.value)


def test_kaspar_1c_example_has_17_ax12_on_one_bus_at_57600():
    config = load_config(SYSTEMD / "kaspar-1c.toml")
    servos = config.servos
    assert servos.backend == "real"
    assert [(b.protocol, b.baud) for b in servos.buses] == [("dynamixel1", 57600)]
    assert len(servos.joints) == 17 and {j.model for j in servos.joints} == {"ax-12a"}
    assert sorted(j.id for j in servos.joints) == list(range(1, 18))
    assert {"left_arm", "right_arm", "head"} <= set(servos.groups)


def test_kaspar_3_example_has_a_herkulex_body_and_maestro_eyes():
    servos = load_config(SYSTEMD / "kaspar-3.toml").servos
    buses = {b.name: (b.protocol, b.baud) for b in servos.buses}
    assert buses == {"body": ("herkulex", 115200), "eyes": ("maestro", 115200)}
    body = [j for j in servos.joints if j.bus == "body"]
    eyes = [j for j in servos.joints if j.bus == "eyes"]
    assert len(body) == 16 and {j.model for j in body} == {"drs-0101"}
    assert len(eyes) == 6 and {j.model for j in eyes} == {"hs-82mg"}


@pytest.mark.parametrize("robot", ["kaspar-1c", "kaspar-3"])
def test_the_example_robots_poses_are_inside_their_ranges_and_make_the_faces(robot):
    config = load_config(SYSTEMD / f"{robot}.toml")
    assert config.poses_file == str(SYSTEMD / f"{robot}-poses.toml")
    assert config.game.happy_pose["smile"] > 0 > config.game.sad_pose["smile"]


def test_defaults_are_the_simulation_with_no_joints():
    servos = parse_config("", "kaspar.toml").servos
    assert servos.backend == "sim" and servos.joints == () and servos.safe_action == "hold"


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        (BUS + joint(bus="arms"), "servos", "joints[0] (elbow): bus 'arms' is not a configured bus"),
        (BUS + joint() + joint(name="wrist"), "servos", "id 1 on bus body is also elbow"),
        (BUS + joint() + joint(servo_id=2), "servos", "joint name 'elbow' is used twice"),
        (BUS + joint(extra="rest_deg = 40.0"), "servos.joints[0]", "rest_deg 40.0 is outside"),
        (BUS + joint(model="drs-0101"), "servos", "a drs-0101 does not speak dynamixel1"),
        (
            BUS + joint(extra="max_speed_dps = 0.0"),
            "servos.joints[0].max_speed_dps",
            "expected > 0 and <= 720 deg/s, found 0.0",
        ),
        (BUS + joint(servo_id=254), "servos.joints[0].id", "expected 0 to 253, found 254"),
        (
            BUS + joint(extra="rest_deg = nan"),
            "servos.joints[0].rest_deg",
            "expected a finite number, found nan",
        ),
        (
            BUS + joint().replace("[-30.0, 30.0]", "[-inf, 30.0]"),
            "servos.joints[0].range_deg[0]",
            "expected a finite number, found -inf",
        ),
        (
            BUS + joint().replace("[-30.0, 30.0]", "[30.0, -30.0]"),
            "servos.joints[0]",
            "joint 'elbow': range_deg must be [low, high] with low < high",
        ),
        (BUS + joint(extra="range_deg_x = 1"), "servos.joints[0].range_deg_x", "unknown key"),
        (
            BUS.replace("57600", "12345"),
            "servos.buses[0].baud",
            "expected one of 9600, 19200, 38400, 57600, 115200,",
        ),
        (BUS.replace('"body"', '" "'), "servos.buses[0].name", "expected a bus name, found an empty string"),
        (BUS + "retries = 11\n", "servos.buses[0].retries", "expected 0 to 10, found 11"),
        (
            BUS + "timeout_margin_ms = 0.0\n",
            "servos.buses[0].timeout_margin_ms",
            "expected > 0 and <= 1000 ms, found 0.0",
        ),
        ("[servos]\npoll_interval_s = 0.01\n", "servos.poll_interval_s", "expected 0.05 to 60 s, found 0.01"),
        ("[servos]\ncontrol_hz = 500.0\n", "servos.control_hz", "expected 1 to 200 Hz, found 500.0"),
        (BUS.replace("dynamixel1", "can"), "servos.buses[0].protocol", "expected one of"),
        (BUS + joint(extra="direction = 2"), "servos.joints[0].direction", "expected one of"),
        ("[servos]\nsafe_action = 'panic'\n", "servos.safe_action", "expected one of"),
        ("[servos]\nbackend = 'real'\n", "servos", "needs at least one joint"),
    ],
)
def test_mistakes_are_named_by_file_key_and_reason(text, key, message):
    error = error_of(text)
    assert error.startswith(f"kaspar.toml: {key}: "), error
    assert message in error


def test_a_range_beyond_what_the_servo_can_reach_is_refused():
    text = BUS + joint().replace("[-30.0, 30.0]", "[-30.0, 200.0]")
    assert "beyond what a ax-12a can reach" in error_of(text)


def test_a_bus_lookup_names_an_unknown_bus():
    servos = parse_config(BUS + joint(), "kaspar.toml").servos
    assert servos.bus("body").port == "/dev/kaspar-body"
    with pytest.raises(UnknownBus, match="unknown bus 'arms'") as caught:
        servos.bus("arms")
    assert isinstance(caught.value, HalError) and isinstance(caught.value, KeyError)


def test_settings_built_in_code_keep_their_rules_between_keys():
    # msgspec holds a key's own limits while decoding; the rules between keys are
    # __post_init__'s, so they hold for settings built in code as well.
    with pytest.raises(SettingsError, match="backend 'real' needs at least one joint") as caught:
        ServoSettings(backend="real")
    assert isinstance(caught.value, HalError) and isinstance(caught.value, ValueError)
    with pytest.raises(SettingsError, match=r"rest_deg 40\.0 is outside range_deg"):
        JointSettings(name="elbow", bus="body", id=1, model="ax-12a", range_deg=(-30.0, 30.0),
                      rest_deg=40.0)
