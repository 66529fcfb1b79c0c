"""Per-session settings: resolved session > profile > robot-wide, recorded in plan.json,
read back on resume, checked as strictly as the robot-wide keys; the robot's own name."""

from __future__ import annotations

import json
from pathlib import Path

import msgspec
import pytest

from kasparctl import __version__
from kasparctl.cli import main
from kasparctl.config import ConfigError, parse_config, resolve_session
from kasparctl.game.opening import open_new
from kasparctl.game.records import TrialRecord
from kasparctl.game.resume import reopen
from kasparctl.game.session import PLAN_FILE, Session, session_dirs

DEMO_CONFIG = Path(__file__).resolve().parents[1] / "kasparctl" / "sim" / "demo.toml"

THREE_LEVELS = """
language = "en"
[game]
correct_answers_to_learn = 2
reactions = "all"
speed_scale = 1.0
[voice]
rate = 150
[learner.profiles.slow]
alpha = 0.2
beta = 4.0
correct_answers_to_learn = 3
speed_scale = 0.5
uncertainty = "body"
[learner.profiles.slow.voice]
rate = 90
pitch = 30
[[sessions]]
group = "A"
profile = "slow"
toys = ["lion", "zebra", "monkey"]
reactions = "none"
[sessions.voice]
volume = 0.2
[[sessions]]
group = "B"
profile = "slow"
correct_answers_to_learn = 1
uncertainty = "spoken"
[[sessions]]
group = "C"
"""

CONTRACT_KEYS = {
    "variant", "toys", "locations", "correct_answers_to_learn", "max_trials_per_target",
    "script", "uncertainty", "prompt_after_s", "step_prompt_after_s", "reactions", "alive",
    "speed_scale", "language", "voice", "learner",
}  # fmt: skip


def test_a_session_value_beats_its_profile_s_which_beats_the_robot_wide_one() -> None:
    config = parse_config(THREE_LEVELS, "kaspar.toml")
    a, b, c = (resolve_session(config, plan) for plan in config.sessions)
    # The session's own values.
    assert a.game.toys == ("lion", "zebra", "monkey") and a.game.reactions == "none"
    assert a.voice.volume == 0.2 and b.game.correct_answers_to_learn == 1
    assert b.uncertainty == "spoken"
    # Its profile's, where the session says nothing.
    assert a.game.correct_answers_to_learn == 3 and a.speed_scale == 0.5
    assert (a.voice.rate, a.voice.pitch) == (90, 30) and a.uncertainty == "body"
    assert a.plan.uncertainty == "body" and a.plan.speak_uncertainty is False
    assert (a.learner.alpha, a.learner.beta) == (0.2, 4.0)
    # The robot-wide ones for a session of a profile that says nothing.
    assert c.game.correct_answers_to_learn == 2 and c.game.reactions == "all"
    assert c.game.toys == config.game.toys and c.voice == config.voice
    assert c.speed_scale == 1.0 and c.uncertainty == "spoken"


def test_a_session_in_another_language_speaks_with_that_language_s_voice() -> None:
    config = parse_config('[[sessions]]\ngroup = "A"\nlanguage = "de"', "kaspar.toml")
    settings = resolve_session(config, config.sessions[0])
    assert (settings.language, settings.voice.voice) == ("de", "de")
    named = parse_config(
        '[[sessions]]\ngroup = "A"\nlanguage = "de"\n[sessions.voice]\nvoice = "de+f3"', "k"
    )
    assert resolve_session(named, named.sessions[0]).voice.voice == "de+f3"


def test_plan_json_records_every_setting_the_robot_and_the_version(tmp_path: Path) -> None:
    config = parse_config(THREE_LEVELS + '\n[robot]\nname = "Robin"\n', "kaspar.toml")
    opened = open_new(tmp_path, config, config.sessions[0], seed=5)
    plan = json.loads((opened.session.directory / PLAN_FILE).read_text())
    assert set(plan["settings"]) >= CONTRACT_KEYS
    settings = plan["settings"]
    assert settings["toys"] == ["lion", "zebra", "monkey"]
    assert settings["correct_answers_to_learn"] == 3 and settings["reactions"] == "none"
    assert settings["speed_scale"] == 0.5 and settings["uncertainty"] == "body"
    assert settings["voice"] == {
        "engine": "espeak-ng", "voice": "en-gb", "rate": 90, "volume": 0.2, "pitch": 30,
    }  # fmt: skip
    assert settings["learner"]["profile"] == "slow" and settings["learner"]["alpha"] == 0.2
    assert plan["robot"] == {"id": config.robot(), "name": "Robin"}
    assert plan["kasparctl_version"] == __version__
    # The state the session starts from is the session's own game: three toys, three bags.
    assert len(opened.state.progress) == 3


def test_a_resume_plays_the_recorded_settings_whatever_the_file_says_now(
    tmp_path: Path,
) -> None:
    config = parse_config(THREE_LEVELS, "kaspar.toml")
    opened = open_new(tmp_path, config, config.sessions[0], seed=5)
    opened.session.close()
    # The file changed since: six toys for everyone, 2 greens, another voice.
    changed = parse_config('[game]\ncorrect_answers_to_learn = 2\n[[sessions]]\ngroup = "A"', "k")
    resumable = reopen(opened.session.directory, changed.game, changed.profile)
    try:
        settings = resumable.settings(changed)
        assert settings.game.toys == ("lion", "zebra", "monkey")
        assert settings.game.correct_answers_to_learn == 3
        assert (settings.voice.rate, settings.voice.volume) == (90, 0.2)
        assert settings.uncertainty == "body" and settings.speed_scale == 0.5
        assert settings.block() == resolve_session(config, config.sessions[0]).block()
    finally:
        resumable.session.close()


def test_a_session_recorded_before_settings_resumes_as_it_did(tmp_path: Path) -> None:
    config = parse_config(THREE_LEVELS, "kaspar.toml")
    plan = config.sessions[2]
    opened = open_new(tmp_path, config, plan, seed=5)
    opened.session.close()
    path = opened.session.directory / PLAN_FILE
    old = json.loads(path.read_text())
    for key in ("settings", "kasparctl_version"):
        del old[key]
    old["robot"] = "robot-0123456789ab"  # as plan.json had it: the id alone
    path.write_text(json.dumps(old))
    resumable = reopen(opened.session.directory, config.game, config.profile)
    try:
        settings = resumable.settings(config)
        assert settings.game == config.game and settings.voice == config.voice
        assert settings.robot_id == "robot-0123456789ab"
    finally:
        resumable.session.close()


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            '[[sessions]]\ngroup = "A"\ncorrect_answers_to_learn = 5\nmax_trials_per_target = 3',
            "kaspar.toml: sessions[0].max_trials_per_target: expected max_trials_per_target (3)"
            " >= correct_answers_to_learn (5)",
        ),
        (
            '[[sessions]]\ngroup = "A"\ntoys = ["lion", "lion"]',
            "kaspar.toml: sessions[0].toys: expected distinct names, found 'lion' more than once",
        ),
        (
            '[[sessions]]\ngroup = "A"\nreactions = "some"',
            "kaspar.toml: sessions[0].reactions: expected one of 'paper', 'all', 'none', "
            "found 'some'",
        ),
        (
            '[[sessions]]\ngroup = "A"\n[sessions.voice]\nrate = 20',
            "kaspar.toml: sessions[0].voice.rate: expected 80 to 450 words per minute, found 20",
        ),
        (
            '[[sessions]]\ngroup = "A"\nspeed_scale = 2',
            "kaspar.toml: sessions[0].speed_scale: expected 0.1 to 1, found 2",
        ),
        (
            "[learner.profiles.x]\ncorrect_answers_to_learn = 0",
            "kaspar.toml: learner.profiles.x.correct_answers_to_learn: expected >= 1, found 0",
        ),
        (
            '[[sessions]]\ngroup = "A"\nanswer_key = ["lion", "zebra", "monkey"]\n'
            'toys = ["lion", "zebra"]',
            "kaspar.toml: sessions[0].answer_key: expected 2 toys (one per target",
        ),
        (
            '[[sessions]]\ngroup = "A"\nlocations = ["box"]',
            "kaspar.toml: sessions[0].locations: only the pilot variant uses locations",
        ),
        ('[robot]\nname = ""', "kaspar.toml: robot.name: expected a name, found an empty string"),
        (
            '[[sessions]]\ngroup = "A"\nlanguage = "de"\ntoys = ["lion", "teddyx"]',
            "kaspar.toml: sessions[0].toys: expected the 'de' words for toy 'teddyx'",
        ),
    ],
)
def test_per_session_values_are_checked_with_file_key_expected_and_found(
    text: str, expected: str
) -> None:
    with pytest.raises(ConfigError) as raised:
        parse_config(text, "kaspar.toml")
    assert str(raised.value).startswith(expected), str(raised.value)


def robot_file(tmp_path: Path, extra: str) -> Path:
    path = tmp_path / "robin.toml"
    path.write_text(DEMO_CONFIG.read_text(encoding="utf-8") + "\n" + extra, encoding="utf-8")
    return path


def test_the_demo_of_a_robot_file_names_itself_and_records_it(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    config = robot_file(tmp_path, '[robot]\nname = "Robin"\n')
    state = tmp_path / "state"
    arguments = ["demo", "--fast", "--seed", "4", "--config", str(config)]
    assert main([*arguments, "--state-dir", str(state)]) == 0
    out = capsys.readouterr().out
    assert "Robin: Hello. I am Robin. You are my teachers today." in out
    assert "I am Kaspar" not in out
    (directory,) = session_dirs(state)
    plan = json.loads((directory / PLAN_FILE).read_text())
    assert plan["robot"]["name"] == "Robin"


def test_the_game_plays_the_session_s_greens_to_learn_and_toys(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    text = DEMO_CONFIG.read_text(encoding="utf-8").replace(
        'speak_uncertainty = true',
        'speak_uncertainty = true\ncorrect_answers_to_learn = 1\ntoys = ["lion", "zebra", "frog"]',
    )
    config = tmp_path / "kaspar.toml"
    config.write_text(text, encoding="utf-8")
    state = tmp_path / "state"
    arguments = ["demo", "--fast", "--seed", "4", "--config", str(config)]
    assert main([*arguments, "--state-dir", str(state), "--p-wrong-green", "0"]) == 0
    capsys.readouterr()
    (directory,) = session_dirs(state)
    session, _ = Session.open(directory)
    try:
        trials = [r for r in session.records() if isinstance(r, TrialRecord)]
    finally:
        session.close()
    assert {trial.choice for trial in trials} <= {"lion", "zebra", "frog"}
    assert {trial.target_index for trial in trials} == {0, 1, 2}
    # One green is enough: no target is ever answered green twice.
    greens = [trial.target_index for trial in trials if trial.feedback == "green"]
    assert sorted(greens) == [0, 1, 2]


def test_demo_with_two_planned_sessions_plays_the_first_then_the_second(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    text = DEMO_CONFIG.read_text(encoding="utf-8").replace(
        '[[sessions]]\ngroup = "demo"',
        '[[sessions]]\ngroup = "G1"\n[[sessions]]\ngroup = "G1"\nnumber = 2\n'
        '[[sessions]]\ngroup = "demo"',
        1,
    )
    config = tmp_path / "kaspar.toml"
    config.write_text(text, encoding="utf-8")
    state = tmp_path / "state"
    arguments = ["demo", "--fast", "--seed", "4", "--config", str(config)]
    said = []
    for _ in range(4):
        assert main([*arguments, "--state-dir", str(state)]) == 0
        said.append(capsys.readouterr().out)
    plans = [json.loads((d / PLAN_FILE).read_text()) for d in session_dirs(state)]
    assert [(plan["group"], plan["number"]) for plan in plans] == [
        ("G1", 1), ("G1", 2), ("demo", 1), ("demo", 1),
    ]  # fmt: skip
    assert "(planned session 1 of 3: group G1, session 1)" in said[0]
    assert "(planned session 2 of 3: group G1, session 2)" in said[1]
    assert "every planned session has been played in this state directory; playing the " \
        "last again: group demo, session 1" in said[3]


def test_the_session_s_speed_scale_slows_every_joint(tmp_path: Path) -> None:
    import asyncio

    from hal.clock import LoopClock
    from hal.servos.sim import SimServos
    from kasparctl.config import load_config

    config = load_config(DEMO_CONFIG)
    joint = config.servos.joints[0]
    low, high = joint.range_deg
    target = (low + high) / 2 + (high - low) / 4

    async def move_time(scale: float) -> float:
        servos = SimServos(config.servos, LoopClock())
        await servos.start()
        for group in servos.groups:
            await servos.set_compliant(group, False)
        servos.scale_speeds(scale)
        begin = servos.clock.now()
        await servos.move({joint.name: target})
        taken = servos.clock.now() - begin
        await servos.close()
        return taken

    full, half = asyncio.run(move_time(1.0)), asyncio.run(move_time(0.5))
    assert half == pytest.approx(2 * full, rel=0.2)
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert({"group": "A", "speed_scale": 0}, type=type(config.sessions[0]))
