"""Configurations `check` used to pass that failed in front of the children, and numbers
that stopped being numbers: each refused at load with the file, the key, what was
expected and what was found, for `check`, `run` and `demo` alike.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from kasparctl.cli import main
from kasparctl.config import ConfigError, load_config, parse_config
from kasparctl.learning.learner import LearnerError, LearnerParams, update

REPO = Path(__file__).resolve().parents[1]
DEMO = (REPO / "kasparctl" / "sim" / "demo.toml").read_text(encoding="utf-8")
EXAMPLE = REPO / "systemd" / "kaspar.toml"


def error_of(text: str | bytes, playable: bool = True, tmp_path: Path | None = None) -> str:
    """The one line `load_config` refuses the text with (as check, run and demo load it)."""
    assert tmp_path is not None
    path = tmp_path / "kaspar.toml"
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    with pytest.raises(ConfigError) as caught:
        load_config(path, playable=playable)
    return str(caught.value).removeprefix(f"{path}: ")


SIM_SERVOS = "[servos]\nbackend = 'sim'\n"
HAPPY = "happy_pose = { smile = 20.0, head_pitch = -8.0 }"

REFUSED = {
    # A pointing arm that is no group of joints: step 2 failed with KeyError 'right_arm'.
    "pointing_group": (
        DEMO.replace('pointing_group = "right_arm"', 'pointing_group = "tail"'),
        "game.pointing_group: expected a group of the configured joints (head, face, right_arm, "
        "eyes), found 'tail': step 2 teaches with it",
    ),
    "no_servos_at_all": (
        "[game]\ntoys = ['lion', 'zebra']\n",
        "game.pointing_group: expected a group of the configured joints (none: no joints are "
        "configured in [servos]), found 'right_arm': step 2 teaches with it",
    ),
    "happy_pose_unknown_joint": (
        DEMO.replace(HAPPY, "happy_pose = { grin = 20.0 }"),
        "game.happy_pose.grin: not a configured joint (joints: head_yaw, head_pitch, smile, "
        "right_shoulder_pitch, right_shoulder_roll, right_elbow, head_roll, mouth_open, "
        "left_eyelid, right_eyelid, left_eye_yaw, right_eye_yaw, left_eye_pitch, right_eye_pitch, eyes_yaw, eyes_pitch, eyelids)",
    ),
    "sad_pose_nan": (
        DEMO.replace("sad_pose = { head_pitch = 15.0 }", "sad_pose = { head_pitch = nan }"),
        "game.sad_pose.head_pitch: expected a finite number of degrees, found nan",
    ),
    "happy_pose_out_of_range": (
        DEMO.replace(HAPPY, "happy_pose = { smile = 90.0 }"),
        "game.happy_pose.smile: pose 'happy_pose' puts joint 'smile' at 90.0 deg, outside its "
        "safe range [0.0, 40.0]",
    ),
    "max_temperature_nan": (
        DEMO.replace("control_hz = 5.0", "control_hz = 5.0\nmax_temperature_c = nan"),
        "servos.max_temperature_c: expected 20 to 120 C, found nan",
    ),
    "max_temperature_inf": (
        DEMO.replace("control_hz = 5.0", "control_hz = 5.0\nmax_temperature_c = inf"),
        "servos.max_temperature_c: expected 20 to 120 C, found inf",
    ),
    "max_temperature_huge": (
        DEMO.replace("control_hz = 5.0", "control_hz = 5.0\nmax_temperature_c = 1e9"),
        "servos.max_temperature_c: expected 20 to 120 C, found 1000000000.0",
    ),
    "max_temperature_negative": (
        DEMO.replace("control_hz = 5.0", "control_hz = 5.0\nmax_temperature_c = -5.0"),
        "servos.max_temperature_c: expected 20 to 120 C, found -5.0",
    ),
    "group_code_too_long": (
        DEMO.replace('group = "demo"', f'group = "{"x" * 240}"'),
        "sessions[0].group: expected at most 64 characters, found 240: 'xxxxxxxxxxxxxxxxxxxxxxxx'...",
    ),
    "child_name_with_a_newline": (
        DEMO.replace('speak_uncertainty = true', 'speak_uncertainty = true\nchildren = ["Sam\\nAlex"]'),
        "sessions[0].children[0]: expected printable text, found 'Sam\\nAlex' (a control character)",
    ),
    "toy_name_too_long": (
        DEMO.replace('"crocodile"', '"' + "crocodile" * 5 + '"'),
        "game.toys[5]: expected at most 40 characters, found 45: 'crocodilecrocodilecrocod'...",
    ),
    "reward_1e308": (
        DEMO + "\n[learner.profiles.paper]\nreward_green = 1e308\n",
        "learner.profiles.paper.reward_green: expected a number from -1e+06 to 1e+06, found 1e+308",
    ),
    "reward_minus_1e308": (
        DEMO + "\n[learner.profiles.paper]\nreward_red = -1e308\n",
        "learner.profiles.paper.reward_red: expected a number from -1e+06 to 1e+06, found -1e+308",
    ),
    "initial_q_huge": (
        DEMO + "\n[learner.profiles.paper]\ninitial_q = 1e300\n",
        "learner.profiles.paper.initial_q: expected a number from -1e+06 to 1e+06, found 1e+300",
    ),
    "negative_seed": (
        DEMO.replace('pointing_group = "right_arm"', 'pointing_group = "right_arm"\nseed = -5'),
        "game.seed: expected 0 to 9223372036854775807, found -5",
    ),
    "absurd_trials": (
        DEMO.replace('pointing_group = "right_arm"', 'pointing_group = "right_arm"\nmax_trials_per_target = 1000000000'),
        "game.max_trials_per_target: expected 1 to 1000, found 1000000000",
    ),
}


@pytest.mark.parametrize("case", REFUSED)
def test_a_configuration_that_would_fail_in_front_of_the_children_is_refused_at_load(
    case: str, tmp_path: Path
) -> None:
    text, expected = REFUSED[case]
    assert error_of(text, tmp_path=tmp_path) == expected


@pytest.mark.parametrize("case", ["pointing_group", "happy_pose_unknown_joint", "group_code_too_long"])
def test_check_refuses_it_too_with_exit_1(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "kaspar.toml"
    path.write_text(REFUSED[case][0])
    assert main(["check", "--config", str(path), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err == f"error: {path}: {REFUSED[case][1]}\n"


def test_a_byte_that_is_not_utf8_is_refused_naming_the_file_line_and_byte(tmp_path: Path) -> None:
    """It became "li\ufffdn" before, said aloud by Kaspar and kept in the records."""
    text = DEMO.replace('"lion"', '"li\xffn"').encode("latin-1")
    offset = text.index(b"\xff")
    line = text.count(b"\n", 0, offset) + 1
    column = offset - text.rfind(b"\n", 0, offset)
    assert error_of(text, tmp_path=tmp_path) == (
        f"(file): expected UTF-8 text, found byte 0xff at line {line}, column {column} "
        f"(byte offset {offset}): save the file as UTF-8"
    )


def test_a_poses_file_that_is_not_utf8_is_refused_naming_it(tmp_path: Path) -> None:
    (tmp_path / "poses.toml").write_bytes(b"[happy]\nsmile = 10.0 # \xe9\n")
    path = tmp_path / "kaspar.toml"
    path.write_text('poses_file = "poses.toml"\n' + DEMO.replace(HAPPY, ""))
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert str(caught.value).startswith(f"{tmp_path / 'poses.toml'}: (file): expected UTF-8 text, found byte 0xe9 at line 2")


def test_the_shipped_example_configuration_is_a_whole_robot(tmp_path: Path) -> None:
    config = load_config(EXAMPLE, playable=True)
    assert config.servos.backend == "real" and len(config.servos.joints) == 22
    assert config.game.pointing_group in config.servos.groups
    assert {bus.port for bus in config.servos.buses} == {"/dev/kaspar-body", "/dev/kaspar-eyes"}


def test_run_refuses_a_configuration_that_does_not_say_its_servos(tmp_path: Path) -> None:
    """Without a [servos] table the robot's servos were silently simulated."""
    path = tmp_path / "kaspar.toml"
    text = DEMO.replace("[servos]\nbackend = \"sim\"\n", "[servos]\n")
    path.write_text(text)
    result = subprocess.run(
        [sys.executable, "-m", "kasparctl", "run", "--config", str(path),
         "--state-dir", str(tmp_path / "state")],
        capture_output=True, text=True, timeout=30,
    )  # fmt: skip
    assert result.returncode == 1
    assert result.stderr == (
        f"error: {path}: servos.backend: no [servos] table with its backend: on the robot the "
        "servos would be simulated without a word; say backend = 'real' with the robot's buses "
        "and joints (systemd/kaspar-3.toml), or backend = 'sim', or run `kasparctl run --sim`\n"
    )
    assert not (tmp_path / "state").exists()


def test_check_says_when_no_servo_backend_is_given(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "kaspar.toml"
    text = DEMO.replace("[servos]\nbackend = \"sim\"\n", "[servos]\n")
    path.write_text(text + "\n[keyfob]\nbackend = 'sim'\n[voice]\nbackend = 'sim'\n")
    assert main(["check", "--config", str(path), "--quiet"]) == 1
    assert "servos         FAIL  no [servos] table with its backend" in capsys.readouterr().out


def test_the_learner_refuses_a_q_value_that_is_not_a_number() -> None:
    """Rewards of 1e308 put null (inf) into the recorded Q values before: with the rewards
    bounded Q stays finite (a weighted mean of Q and r), and a table that is not (a
    damaged one) is refused rather than recorded."""
    params = LearnerParams()
    largest = np.full((1, 2), np.finfo(np.float64).max)
    assert math.isfinite(update(largest, 0, 0, 1e6, params)[0, 0])
    with pytest.raises(LearnerError, match="not a finite number"):
        update(np.array([[np.inf, 0.0]]), 0, 0, 1.0, params)
    with pytest.raises(LearnerError, match="not a finite number"):
        update(np.zeros((1, 2)), 0, 0, 1e308 * 10, params)


@pytest.mark.parametrize(
    ("field", "value"), [("reward_green", 1e308), ("reward_red", -1e308), ("initial_q", 1e7), ("beta", 1e7)]
)
def test_learner_parameters_beyond_their_limits_are_refused(field: str, value: float) -> None:
    with pytest.raises(LearnerError) as caught:
        LearnerParams(**{field: value})
    assert caught.value.key == field


def test_an_inline_config_parsed_from_text_holds_the_same_rules() -> None:
    with pytest.raises(ConfigError, match=r"game\.happy_pose\.grin: not a configured joint"):
        parse_config(DEMO.replace(HAPPY, "happy_pose = { grin = 20.0 }"), "kaspar.toml")
