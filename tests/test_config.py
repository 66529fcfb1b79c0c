"""kaspar.toml: every error names the file, the key, what was expected and what was found."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import msgspec
import pytest

from kasparctl.cli import main
from kasparctl.config import Config, ConfigError, Name, load_config, parse_config
from kasparctl.config.explain import _Limits

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "systemd" / "kaspar.toml"


def error_of(text: str) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "kaspar.toml")
    return str(caught.value)


def test_defaults_are_the_papers_learner_and_six_toys() -> None:
    config = parse_config("", "kaspar.toml")
    params = config.profile()
    assert (params.alpha, params.beta, params.gamma) == (0.6, 8.0, 0.0)
    assert (params.reward_green, params.reward_red, params.initial_q) == (1.0, -1.0, 0.0)
    assert len(config.game.toys) == 6
    assert config.game.correct_answers_to_learn == 2
    assert config.game.targets == tuple(f"bag {n}" for n in range(1, 7))


def test_example_configuration_loads_with_its_plans() -> None:
    config = load_config(EXAMPLE)
    assert [plan.group for plan in config.sessions] == ["A1", "A2"]
    assert config.sessions[1].condition == "fast/silent"
    assert config.group_size(config.sessions[0]) == 3
    assert config.group_size(config.sessions[1]) == 2
    assert config.profile("fast").alpha == 0.9


def test_settings_are_frozen() -> None:
    config = Config()
    with pytest.raises(AttributeError):
        config.language = "fr"  # type: ignore[misc]


def test_relative_paths_are_relative_to_the_file(tmp_path: Path) -> None:
    path = tmp_path / "kaspar.toml"
    path.write_text('state_dir = "state"\nphrases_dir = "my-phrases"\n')
    config = load_config(path)
    assert config.state_dir == str(tmp_path / "state")
    assert config.phrases_dir == str(tmp_path / "my-phrases")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('[game]\nvariant = "maze"', "kaspar.toml: game.variant: expected one of 'names', 'pilot', found 'maze'"),
        ("[game]\ntoyz = []", "kaspar.toml: game.toyz: unknown key; expected one of: variant, toys,"),
        ("colour = 1", "kaspar.toml: colour: unknown key; expected one of: state_dir,"),
        ('[game]\nchildren_per_group = "3"', "kaspar.toml: game.children_per_group: expected int, found str"),
        ("[game]\nchildren_per_group = 9", "kaspar.toml: game.children_per_group: expected 1 to 6, found 9"),
        ('[game]\ntoys = ["lion"]', "kaspar.toml: game.toys: expected at least 2 names, found 1"),
        ('[game]\ntoys = ["lion", "lion"]', "kaspar.toml: game.toys: expected distinct names, found 'lion' more than once"),
        ('[game]\ntoys = ["lion", " "]', "kaspar.toml: game.toys[1]: expected a name, found an empty string"),
        ('[game]\ntoys = ["lion", 3]', "kaspar.toml: game.toys[1]: expected str, found int"),
        ('[game]\nvariant = "pilot"', "kaspar.toml: game.locations: expected at least 1 names, found 0"),
        ('[game]\nlocations = ["box"]', "kaspar.toml: game.locations: only the pilot variant uses locations"),
        ("[game]\ncorrect_answers_to_learn = 0", "kaspar.toml: game.correct_answers_to_learn: expected >= 1, found 0"),
        ("[game]\nmax_trials_per_target = 1", "kaspar.toml: game.max_trials_per_target: expected >= correct_answers_to_learn (2), found 1"),
        ("[learner.profiles.quick]\nalpha = 1.5", "kaspar.toml: learner.profiles.quick.alpha: expected a number in (0, 1], found 1.5"),
        ("[learner.profiles.quick]\nbeta = -1.0", "kaspar.toml: learner.profiles.quick.beta: expected a number from 0 to 1e+06, found -1.0"),
        ("[learner.profiles.quick]\ngamma = 1.0", "kaspar.toml: learner.profiles.quick.gamma: expected a number in [0, 1), found 1.0"),
        ("[learner.profiles.quick]\ninitial_q = nan", "kaspar.toml: learner.profiles.quick.initial_q: expected a finite number, found nan"),
        ("[learner.profiles.quick]\nalfa = 0.5", "kaspar.toml: learner.profiles.quick.alfa: unknown key; expected one of: alpha, beta,"),
        ('[learner]\ndefault_profile = "turbo"', "kaspar.toml: learner.default_profile: expected one of fast, paper, slow, found 'turbo'"),
        ('[logging]\nlevel = "loud"', "kaspar.toml: logging.level: expected one of 'debug', 'info', 'warning', 'error', found 'loud'"),
        ("[[sessions]]\nprofile = 'paper'", "kaspar.toml: sessions[0].group: required key is missing"),
        ("[[sessions]]\ngroup = ''", "kaspar.toml: sessions[0].group: expected a group code, found an empty string"),
        ("[[sessions]]\ngroup = 'A'\n[[sessions]]\ngroup = 'A'", "kaspar.toml: sessions[1].group: group code 'A' is planned twice"),
        ("[[sessions]]\ngroup = 'A'\nprofile = 'turbo'", "kaspar.toml: sessions[0].profile: expected one of fast, paper, slow, found 'turbo'"),
        ("[[sessions]]\ngroup = 'A'\nspeak_uncertainty = 'yes'", "kaspar.toml: sessions[0].speak_uncertainty: expected bool, found str"),
        ("[[sessions]]\ngroup = 'A'\ngroup_size = 7", "kaspar.toml: sessions[0].group_size: expected 1 to 6, found 7"),
        (
            "[[sessions]]\ngroup = 'A'\nchildren = ['a', 'b', 'c', 'd', 'e', 'f', 'g']",
            "kaspar.toml: sessions[0].children: expected at most 6 names, found 7",
        ),
        ("[[sessions]]\ngroup = 'A'\nchildren = ['Sam', 'Sam']", "kaspar.toml: sessions[0].children: expected distinct names, found 'Sam' more than once"),
        ("[[sessions]]\ngroup = 'A'\nchildren = ['Sam']\ngroup_size = 2", "kaspar.toml: sessions[0].group_size: expected 1 (one per name in children), found 2"),
        ("[[sessions]]\ngroup = 'A'\nanswer_key = ['lion']", "kaspar.toml: sessions[0].answer_key: expected 6 toys (one per target: bag 1,"),
        (
            "[[sessions]]\ngroup = 'A'\nanswer_key = ['lion', 'elephant', 'giraffe', 'monkey', 'zebra', 'snake']",
            "kaspar.toml: sessions[0].answer_key[5]: expected one of game.toys (lion, elephant, giraffe, monkey, zebra, crocodile), found 'snake'",
        ),
        ("[game\n", "kaspar.toml: (syntax): not valid TOML:"),
        ('[game.commands]\n"long blue" = "next"', "kaspar.toml: game.commands.long blue: expected a gesture, one of long green, long red, double green, double red, both"),
        ('[game.commands]\n"long green" = "dance"', "kaspar.toml: game.commands.long green: expected one of next, pause, undo, stop, reopen, away, choose, absent, found 'dance'"),
        ('[game]\ncommands = { "long green" = "next", "both" = "stop" }', "kaspar.toml: game.commands: expected a gesture for 'pause': a session cannot be run without it"),
        ('[game]\nvariant = "pilot"\nlocations = ["box", "shelf"]\n[game.poses.box]\nhead_yaw = 10.0', "kaspar.toml: game.poses: expected one pose per location (box, shelf), found box"),
        ("[game.poses.box]\nhead_yaw = 10.0", "kaspar.toml: game.poses: only the pilot variant has configured poses"),
        ("[game]\nprompt_after_s = []", "kaspar.toml: game.prompt_after_s: expected at least 1 delay, found 0"),
        ("[game]\nprompt_after_s = [8.0, 0.1]", "kaspar.toml: game.prompt_after_s[1]: expected 0.5 to 600 s, found 0.1"),
        ("[game]\nprompt_after_s = [nan]", "kaspar.toml: game.prompt_after_s[0]: expected 0.5 to 600 s, found nan"),
        ("[game]\nextra_press_gap_s = 20", "kaspar.toml: game.extra_press_gap_s: expected 0 to 10 s, found 20.0"),
        ("[game]\nextra_press_gap_s = inf", "kaspar.toml: game.extra_press_gap_s: expected 0 to 10 s, found inf"),
        ("[game]\nchildren_per_group = 0", "kaspar.toml: game.children_per_group: expected 1 to 6, found 0"),
        ('[game]\nlocations = ["box", ""]', "kaspar.toml: game.locations[1]: expected a name, found an empty string"),
        ("[[sessions]]\ngroup = 'A'\nchildren = ['Sam', '\t']", "kaspar.toml: sessions[0].children[1]: expected a name, found an empty string"),
        ("[[sessions]]\ngroup = 'A'\ngroup_size = 0", "kaspar.toml: sessions[0].group_size: expected 1 to 6, found 0"),
        ("[game]\nextra_press_gap_s = -1.0", "kaspar.toml: game.extra_press_gap_s: expected 0 to 10 s, found -1.0"),
    ],
)
def test_every_error_names_file_key_expected_and_found(text: str, expected: str) -> None:
    assert error_of(text).startswith(expected)


def test_error_carries_its_parts() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config("[game]\nchildren_per_group = 0", "robot.toml")
    assert (caught.value.source, caught.value.key) == ("robot.toml", "game.children_per_group")


def test_pilot_targets_are_its_locations() -> None:
    config = parse_config('[game]\nvariant = "pilot"\nlocations = ["box", "shelf", "basket"]', "k.toml")
    assert config.game.targets == ("box", "shelf", "basket")
    assert not config.game.exclude_learned


def test_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nowhere\.toml: \(file\): cannot read it: No such file"):
        load_config(tmp_path / "nowhere.toml")


def test_check_command_exit_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    simulated = tmp_path / "sim.toml"
    # The example robot (Kaspar 3's servos) simulated throughout.
    robot = EXAMPLE.read_text().replace('backend = "real"', 'backend = "sim"', 1)
    robot = robot.replace("[keyfob]\n", "[keyfob]\nbackend = 'sim'\n", 1)
    simulated.write_text(robot + "\n[voice]\nbackend = 'sim'\n")
    assert main(["check", "--config", str(simulated)]) == 0
    table = capsys.readouterr().out
    assert f"configuration  ok    {simulated} (2 planned sessions)" in table
    assert "keyfob         ok    simulated" in table
    bad = tmp_path / "bad.toml"
    bad.write_text("[game]\nvariant = 'maze'\n")
    assert main(["check", "--config", str(bad)]) == 1
    assert f"{bad}: game.variant: expected one of" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("meta", "range_words", "length_words"),
    [
        (msgspec.Meta(ge=1, le=6), "1 to 6", None),
        (msgspec.Meta(ge=0.0, le=10.0, extra={"unit": "s"}), "0 to 10 s", None),
        (msgspec.Meta(gt=0.0, le=1.0), "> 0 and <= 1", None),
        (msgspec.Meta(lt=0.25), "< 0.25", None),
        (msgspec.Meta(min_length=2, extra={"item": "name"}), None, "at least 2 names"),
        (msgspec.Meta(min_length=1, max_length=3), None, "1 to 3 items"),
        (msgspec.Meta(min_length=1, max_length=1, extra={"item": "delay"}), None, "exactly 1 delay"),
        (msgspec.Meta(max_length=1), None, "at most 1 item"),
    ],
)
def test_field_limits_are_worded_like_the_hand_written_messages(meta, range_words, length_words) -> None:
    limits = _Limits.of(Annotated[tuple[float, ...], meta])
    if range_words is not None:
        assert limits.value(pattern=False) == range_words
    if length_words is not None:
        assert limits.length() == length_words


def test_a_text_limit_without_words_names_its_pattern() -> None:
    limits = _Limits.of(Annotated[str, msgspec.Meta(pattern="^[a-z]+$", min_length=2)])
    assert limits.value(pattern=True) == "text matching '^[a-z]+$'"
    assert limits.length() == "at least 2 characters"


def test_nested_limits_merge_outermost_last() -> None:
    limits = _Limits.of(Annotated[Name, msgspec.Meta(min_length=3)])
    assert (limits.expected, limits.pattern, limits.min_length) == ("a name", r"\S", 3)
