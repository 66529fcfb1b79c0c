"""Poses by demonstration: `kasparctl pose record/play/list`, and the poses file in the config."""

from __future__ import annotations

import itertools
import json
import time
import tomllib

import pytest
from bringup_fixtures import robot
from emulators.herkulex import HerkulexEmulator
from servo_fixtures import soon

from hal.servos import herkulex as hx
from kasparctl.cli import main
from kasparctl.config import ConfigError, load_config

PILOT = 'variant = "pilot"\nlocations = ["shelf", "box"]'


def test_a_pose_recorded_by_hand_is_saved_listed_and_played(tmp_path, capsys):
    path = robot(tmp_path, poses="# our poses\n\n[sad]  # chin down\nsmile = -10.0\n")
    assert main(["pose", "record", "happy", "--config", str(path), "--group", "face",
                 "--seconds", "0.2", "--sim-hand", "smile=15", "--sim-hand", "mouth_open=5",
                 "--json"]) == 0
    saved = json.loads(capsys.readouterr().out)["joints"]
    # Where the servos report the hand put them: 0.325 degree steps, to 0.1 degree.
    assert saved == pytest.approx({"smile": 15.0, "mouth_open": 5.0}, abs=0.2)
    text = (tmp_path / "poses.toml").read_text()
    assert text.startswith("# our poses\n\n[sad]  # chin down\nsmile = -10.0\n")  # kept
    assert tomllib.loads(text)["happy"] == saved
    config = load_config(path)
    assert config.game.happy_pose == saved
    assert config.game.sad_pose == {"smile": -10.0}
    assert main(["pose", "list", "--config", str(path), "--json"]) == 0
    listed = {row["pose"]: row for row in json.loads(capsys.readouterr().out)}
    assert listed["happy"]["role"] == "game: happy face" and listed["sad"]["problem"] is None
    assert main(["pose", "play", "happy", "--config", str(path), "--json"]) == 0
    reached = json.loads(capsys.readouterr().out)["reached"]
    assert reached == pytest.approx(saved, abs=0.4)


def test_a_pose_outside_a_joints_range_is_refused_and_nothing_is_written(tmp_path, capsys):
    path = robot(tmp_path, poses="[sad]\nsmile = -10.0\n")
    before = (tmp_path / "poses.toml").read_text()
    assert main(["pose", "record", "happy", "--config", str(path), "--joints", "smile",
                 "--seconds", "0.1", "--sim-hand", "smile=30"]) == 1
    error = capsys.readouterr().err
    assert "pose 'happy' puts joint 'smile' at 29.9 deg, outside its safe range [-20.0" in error
    assert (tmp_path / "poses.toml").read_text() == before


def test_poses_and_the_joints_ranges_are_checked_when_the_config_loads(tmp_path):
    path = robot(tmp_path, poses="[happy]\nsmile = 25.0\n")
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    assert caught.value.source == str(tmp_path / "poses.toml")
    assert caught.value.key == "happy.smile"
    assert "outside its safe range [-20.0, 20.0]" in caught.value.message
    (tmp_path / "poses.toml").write_text("[happy]\ntail = 5.0\n")
    with pytest.raises(ConfigError, match=r"happy\.tail: not a configured joint"):
        load_config(path)
    (tmp_path / "poses.toml").write_text("[happy]\nsmile = 'wide'\n")
    with pytest.raises(ConfigError, match=r"happy\.smile: expected a finite number of degrees"):
        load_config(path)


def test_the_pilots_locations_and_the_rest_come_from_the_poses_file(tmp_path):
    poses = ("[shelf]\nleft_elbow = 60.0\n[box]\nleft_elbow = 30.0\n"
             "[rest]\nleft_elbow = 10.0\nsmile = 2.0\n")
    config = load_config(robot(tmp_path, game=PILOT, poses=poses))
    assert config.game.poses == {"shelf": {"left_elbow": 60.0}, "box": {"left_elbow": 30.0}}
    rests = {j.name: j.rest_deg for j in config.servos.joints}
    assert rests == {"left_elbow": 10.0, "smile": 2.0, "mouth_open": 0.0}


def test_a_pilot_with_only_some_locations_posed_is_refused_naming_them(tmp_path):
    path = robot(tmp_path, game=PILOT, poses="[shelf]\nleft_elbow = 60.0\n")
    with pytest.raises(ConfigError, match="no pose for pilot location 'box'"):
        load_config(path)


def test_a_pose_given_both_inline_and_in_the_poses_file_is_refused(tmp_path):
    game = 'variant = "names"\nhappy_pose = { smile = 10.0 }'
    path = robot(tmp_path, game=game, poses="[happy]\nsmile = 15.0\n")
    with pytest.raises(ConfigError, match=r"game\.happy_pose: also given as pose 'happy'"):
        load_config(path)


def test_playing_an_unknown_pose_names_the_recorded_ones(tmp_path, capsys):
    path = robot(tmp_path, poses="[sad]\nsmile = -10.0\n")
    assert main(["pose", "play", "wink", "--config", str(path)]) == 1
    assert "no pose 'wink'" in capsys.readouterr().err


def test_pose_commands_need_a_poses_file_in_the_config(tmp_path, capsys):
    path = robot(tmp_path)
    path.write_text(path.read_text().replace('poses_file = "poses.toml"\n', ""))
    assert main(["pose", "list", "--config", str(path)]) == 1
    assert "poses_file is not set" in capsys.readouterr().err


def test_a_pose_recorded_and_played_on_the_emulated_bus_stays_within_range_and_speed(
    tmp_path, capsys
):
    # Recorded: the hand puts the elbow at raw 700 (61.1 deg) while it is limp.
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[5, 6, 10],
                          positions={5: 512, 6: 512, 10: 527}) as emulator:
        emulator.hand(10, lambda now: 700)
        path = robot(tmp_path, backend="real", port=str(emulator.path))
        assert main(["pose", "record", "point", "--config", str(path), "--group", "left_arm",
                     "--seconds", "0.3", "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["joints"] == {"left_elbow": 61.1}
        assert soon(lambda: emulator.torque_on(10))  # held where it was posed
        emulator.hand(10, None)
        # Back to rest by hand, then played.
        emulator.set_present(10, 527)
        emulator.received.clear()
        began = time.monotonic()
        assert main(["pose", "play", "point", "--config", str(path), "--json"]) == 0
        took = time.monotonic() - began
        assert json.loads(capsys.readouterr().out)["reached"]["left_elbow"] == pytest.approx(
            61.1, abs=0.7)
        goals = [
            (request.data[0], hx.u16(request.data, 1))
            for request in (hx.decode_packet(p) for p in emulator.received)
            if request.command == hx.Command.S_JOG
        ]
    degrees = [(raw - 512) * 0.325 for _playtime, raw in goals]
    assert all(-5.0 - 0.33 <= d <= 90.0 + 0.33 for d in degrees)  # inside the range
    step = 1 / 50
    assert all(abs(b - a) <= 60.0 * step + 0.33 for a, b in itertools.pairwise(degrees))  # 60 deg/s
    assert took >= (61.1 - 4.9) / 60.0  # no faster than the limit allows
