"""The [servos] table: the example robots load, and every mistake is named by its key."""

from __future__ import annotations

from pathlib import Path

import pytest

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
        (BUS + joint(extra="max_speed_dps = 0.0"), "servos.joints[0]", "max_speed_dps"),
        (BUS + joint(extra="range_deg_x = 1"), "servos.joints[0].range_deg_x", "unknown key"),
        (BUS.replace("57600", "12345"), "servos.buses[0]", "baud: expected one of"),
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
