"""The surgical TOML editor: exactly the keys asked change, comments and layout stay."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from kasparctl.bringup.toml_patch import (
    TomlPatchError,
    format_value,
    set_joint_keys,
    set_table,
)

ROBOT = """\
# Kaspar 3 (comment at the top)
[servos]
backend = "real"        # keep me

[[servos.joints]]
name = "head_yaw"
bus = "body"
range_deg = [-60.0, 60.0]   # narrowed on 2026-11-02
rest_deg = 0.0
group = "head"

# the left arm, mirrored
[[servos.joints]]
name = "left_elbow"
bus = "body"
range_deg = [ -5.0, 90.0 ]
rest_deg = 5.0
direction = -1
group = "left_arm"
"""


def changed_lines(before: str, after: str) -> list[tuple[str, str]]:
    return [(a, b) for a, b in zip(before.splitlines(), after.splitlines(), strict=False) if a != b]


def test_only_the_named_joints_keys_change_and_comments_stay():
    after = set_joint_keys(ROBOT, "head_yaw", {"range_deg": (-45.25, 50.0), "rest_deg": 2.04})
    assert changed_lines(ROBOT, after) == [
        ("range_deg = [-60.0, 60.0]   # narrowed on 2026-11-02",
         "range_deg = [-45.2, 50.0]   # narrowed on 2026-11-02"),
        ("rest_deg = 0.0", "rest_deg = 2.0"),
    ]
    assert len(after.splitlines()) == len(ROBOT.splitlines())
    parsed = tomllib.loads(after)["servos"]["joints"]
    assert parsed[1] == tomllib.loads(ROBOT)["servos"]["joints"][1]


def test_a_missing_key_is_added_after_the_tables_last_key():
    after = set_joint_keys(ROBOT, "head_yaw", {"direction": -1})
    lines = after.splitlines()
    assert lines[lines.index('group = "head"') + 1] == "direction = -1"
    assert lines[lines.index("direction = -1") + 2] == "# the left arm, mirrored"
    assert tomllib.loads(after)["servos"]["joints"][0]["direction"] == -1


def test_a_key_can_be_removed():
    after = set_joint_keys(ROBOT, "left_elbow", {"direction": None, "rest_deg": 6.0})
    entry = tomllib.loads(after)["servos"]["joints"][1]
    assert "direction" not in entry and entry["rest_deg"] == 6.0


def test_unknown_joints_and_multi_line_values_are_refused_by_name():
    with pytest.raises(TomlPatchError, match=re.escape("no [[servos.joints]] table with name = 'tail'")):
        set_joint_keys(ROBOT, "tail", {"rest_deg": 1.0})
    spread = ROBOT.replace("range_deg = [-60.0, 60.0]", "range_deg = [\n  -60.0,\n  60.0,\n]")
    with pytest.raises(TomlPatchError, match="'range_deg' spans several lines"):
        set_joint_keys(spread, "head_yaw", {"range_deg": (-1.0, 1.0)})


def test_pose_tables_are_replaced_in_place_or_appended():
    poses = "# poses of Kaspar 3\n\n[happy]  # the big smile\nsmile = 20.0\nhead_pitch = -8.0\n"
    after = set_table(poses, "happy", {"smile": 25.0, "mouth_open": 5.0})
    assert after.startswith("# poses of Kaspar 3\n\n[happy]  # the big smile\nsmile = 25.0\n")
    assert tomllib.loads(after) == {"happy": {"smile": 25.0, "mouth_open": 5.0}}
    added = set_table(after, "sad", {"head_pitch": 15.0})
    assert added.startswith(after) and tomllib.loads(added)["sad"] == {"head_pitch": 15.0}
    assert tomllib.loads(set_table("", "rest", {"a": 0.0})) == {"rest": {"a": 0.0}}
    with pytest.raises(TomlPatchError, match="not a plain name"):
        set_table(poses, "big smile", {"smile": 1.0})


def test_the_example_robots_keep_every_comment_through_an_edit():
    root = Path(__file__).resolve().parent.parent
    text = (root / "systemd" / "kaspar-3.toml").read_text()
    after = set_joint_keys(text, "left_elbow", {"range_deg": (-3.0, 85.5), "rest_deg": 4.0})
    comments = [line for line in text.splitlines() if "#" in line]
    assert comments == [line for line in after.splitlines() if "#" in line]
    assert len(changed_lines(text, after)) == 2


@given(st.floats(-300, 300, allow_nan=False), st.floats(-300, 300, allow_nan=False))
def test_values_read_back_as_written(low, high):
    after = set_joint_keys(ROBOT, "left_elbow", {"range_deg": (low, high)})
    written = tomllib.loads(after)["servos"]["joints"][1]["range_deg"]
    assert written == [float(format_value(low)), float(format_value(high))]


def test_text_keys_are_set_in_place_and_a_dotted_table_is_appended() -> None:
    from kasparctl.bringup.toml_patch import set_text_keys

    text = '# robot\n[researcher]\n# the old remote\nname = "Old"  # by name\nhold_s = 3.0\n\n[voice]\nrate = 1\n'
    edited = set_text_keys(text, "researcher", {"name": None, "device": "/dev/input/x", "interface": 0})
    assert edited == (
        '# robot\n[researcher]\n# the old remote\nhold_s = 3.0\ndevice = "/dev/input/x"\n'
        'interface = 0\n\n[voice]\nrate = 1\n'
    )
    keyed = set_text_keys(edited, "researcher.keys", {"KEY_F5": "stop", "KEY_ESC": "stop"}, exact=True)
    assert keyed.endswith('\n[researcher.keys]\nKEY_F5 = "stop"\nKEY_ESC = "stop"\n')
    again = set_text_keys(keyed, "researcher.keys", {"KEY_A": "next"}, exact=True)
    assert again.endswith('\n[researcher.keys]\nKEY_A = "next"\n') and "KEY_F5" not in again


def test_a_text_value_the_patcher_could_not_edit_again_is_refused() -> None:
    from kasparctl.bringup.toml_patch import TomlPatchError, set_text_keys

    with pytest.raises(TomlPatchError, match="a '#' or a control character is not written"):
        set_text_keys("[keyfob]\n", "keyfob", {"name": "Remote #2"})
