"""The interaction's configuration: where the researcher's commands come from, the script,
numbered sessions, the listening pose, the pilot's location phrases. Every error names
the file, the key, what was expected and what was found."""

from __future__ import annotations

import pytest
from bringup_fixtures import robot

from hal.build import build
from hal.clock import LoopClock
from hal.keyfob.reader import Keyfob
from hal.keyfob.settings import DEFAULT_RESEARCHER_DEVICE, ResearcherSettings
from hal.keyfob.sim import SimKeyfob
from kasparctl.config import ConfigError, load_config, parse_config


def error_of(text: str) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "kaspar.toml")
    return str(caught.value)


def test_by_default_the_researcher_has_a_device_of_their_own_and_the_paper_script() -> None:
    config = parse_config("", "kaspar.toml")
    assert config.researcher.source == "device"
    assert config.researcher.device_path == DEFAULT_RESEARCHER_DEVICE
    assert config.researcher.profile == "logitech-r400"
    assert config.researcher.command_names() == ["next", "pause", "reopen", "stop", "undo"]
    assert config.researcher.hold_s == 3.0
    # The holds on the children's keyfob (one keyfob, or the device away): no double.
    assert config.game.commands == {"long green": "next", "long red": "pause", "both": "stop"}
    assert config.game.script == "paper"
    plan = parse_config("[[sessions]]\ngroup = 'A'", "k.toml").sessions[0]
    assert (plan.number, plan.script, config.script(plan)) == (1, None, "paper")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "[researcher.keys]\nKEY_F1 = 'dance'",
            "kaspar.toml: researcher.keys.KEY_F1: expected one of next, pause, undo, stop, reopen, away, choose, absent, found 'dance'",
        ),
        (
            "[researcher]\nkeys = { KEY_F1 = 'next', KEY_F2 = 'stop' }",
            "kaspar.toml: researcher.keys: expected a key for 'pause' (researcher.source = 'device'): "
            "a session cannot be run without it",
        ),
        (
            "[researcher]\nsource = 'keypad'",
            "kaspar.toml: keyfob.commands: expected a key for 'next' (researcher.source = 'keypad'): "
            "a session cannot be run without it",
        ),
        (
            "[researcher]\nsource = 'phone'",
            "kaspar.toml: researcher.source: expected one of 'device', 'keypad', 'keyfob', found 'phone'",
        ),
        ("[researcher]\nhold_s = 1", "kaspar.toml: researcher.hold_s: expected 2 to 10 s, found 1.0"),
        (
            '[game.commands]\n"long green" = "next"\n"long red" = "pause"\n"both" = "stop"\n"double red" = "undo"',
            "kaspar.toml: game.commands.double red: expected long green, long red or both: a double "
            "press is what children do, so it is an answer, never a command",
        ),
        ("[game]\nscript = 'fancy'", "kaspar.toml: game.script: expected one of 'paper', 'varied', found 'fancy'"),
        (
            "[[sessions]]\ngroup = 'A'\nscript = 'fancy'",
            "kaspar.toml: sessions[0].script: expected one of 'paper', 'varied', found 'fancy'",
        ),
        ("[[sessions]]\ngroup = 'A'\nnumber = 0", "kaspar.toml: sessions[0].number: expected 1 to 99, found 0"),
        (
            "[[sessions]]\ngroup = 'A'\n[[sessions]]\ngroup = 'A'\nnumber = 1",
            "kaspar.toml: sessions[1].group: group code 'A' is planned twice as session 1",
        ),
        (
            '[game]\nvariant = "pilot"\nlocations = ["box", "shelf"]\nlocation_phrases = { sofa = "on the sofa" }',
            "kaspar.toml: game.location_phrases.sofa: expected one of game.locations (box, shelf), found 'sofa'",
        ),
        ("[game]\npose_check_deg = -1", "kaspar.toml: game.pose_check_deg: expected 0 to 360 deg, found -1.0"),
        ("[game]\nstep_prompt_after_s = 1", "kaspar.toml: game.step_prompt_after_s: expected 5 to 3600 s, found 1.0"),
    ],
)
def test_every_error_names_file_key_expected_and_found(text: str, expected: str) -> None:
    assert error_of(text).startswith(expected)


def test_a_researcher_key_given_twice_is_named() -> None:
    message = error_of("[researcher.keys]\nKEY_PAGEDOWN = 'next'\n109 = 'pause'\nKEY_ESC = 'stop'")
    assert "researcher" in message and "keys.109 is the same key as keys.KEY_PAGEDOWN" in message


def test_a_group_asks_for_one_more_session() -> None:
    config = parse_config(
        "[[sessions]]\ngroup = 'A'\n[[sessions]]\ngroup = 'A'\nnumber = 2\nscript = 'varied'",
        "k.toml",
    )
    assert [(p.group, p.number) for p in config.sessions] == [("A", 1), ("A", 2)]
    assert config.script(config.sessions[1]) == "varied"


def test_the_listening_pose_comes_from_the_poses_file(tmp_path) -> None:
    path = robot(tmp_path, poses="[listening]\nsmile = 5.0\n")
    assert load_config(path).game.listening_pose == {"smile": 5.0}


def test_the_hardware_bundle_has_the_researchers_device_when_they_have_one() -> None:
    config = parse_config("[servos]\nbackend = 'sim'\n", "k.toml")
    clock = LoopClock()
    real = build(config.servos, config.keyfob, config.voice, clock, researcher=config.researcher)
    assert isinstance(real.researcher, Keyfob)
    one_keyfob = ResearcherSettings(source="keyfob")
    alone = build(config.servos, config.keyfob, config.voice, clock, researcher=one_keyfob)
    assert alone.researcher is None
    sim = build(config.servos, config.keyfob, config.voice, clock, sim=True)
    assert isinstance(sim.researcher, SimKeyfob)
