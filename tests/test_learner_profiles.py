"""Learners children can tell apart: the profiles' greens to learn, and `simulate --design`."""

from __future__ import annotations

import contextlib
import io
import json

import msgspec
import pytest

from kasparctl import cli
from kasparctl.config import BUILTIN_PROFILES, ConfigError, GameSettings, ProfileSettings
from kasparctl.config.loading import parse_config
from kasparctl.learning.learner import LearnerParams
from kasparctl.sim.design import Figures, figures
from kasparctl.sim.teacher import Teacher

NAMES = GameSettings(variant="names")


def _run(*arguments: str) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = cli.main(["simulate", *arguments])
    return code, out.getvalue()


def _figures(name: str, groups: int = 1500) -> Figures:
    profile = BUILTIN_PROFILES[name]
    return figures(profile.shaped(NAMES), profile.params(), Teacher(), groups, seed=3)


def test_fast_paper_and_slow_differ_by_several_guesses_per_names_game():
    fast, paper, slow = (_figures(name) for name in ("fast", "paper", "slow"))
    # A names game's sd is about 2.7 guesses: 4 guesses apart is what a group would notice.
    assert paper.guesses_per_game - fast.guesses_per_game > 4
    assert slow.guesses_per_game - paper.guesses_per_game > 4
    assert fast.trials_per_problem < paper.trials_per_problem < slow.trials_per_problem


def test_slow_is_no_more_erratic_than_the_paper_learner():
    paper, slow = _figures("paper", 3000), _figures("slow", 3000)
    # The old slow learner (alpha 0.2, beta 4) repeated a toy just answered red in 5 %
    # of its guesses; within the noise of 3000 games the new one is the paper's or better.
    assert slow.repeat_red_rate <= paper.repeat_red_rate * 1.5
    assert slow.leave_green_rate <= paper.leave_green_rate * 1.5
    old = figures(NAMES, LearnerParams(alpha=0.2, beta=4.0), Teacher(), 500, seed=3)
    assert old.repeat_red_rate > 10 * paper.repeat_red_rate


def test_a_profile_without_greens_keeps_the_game_s_and_one_with_them_replaces_them():
    game = GameSettings(correct_answers_to_learn=3)
    assert ProfileSettings().shaped(game).correct_answers_to_learn == 3
    assert ProfileSettings(correct_answers_to_learn=1).shaped(game).correct_answers_to_learn == 1
    # The learner itself is Eq. 1-3's parameters only.
    assert BUILTIN_PROFILES["fast"].params() == LearnerParams(alpha=0.9, beta=10.0)


def test_a_configured_profile_s_greens_are_read_and_checked():
    config = parse_config(
        "[learner.profiles.quick]\ncorrect_answers_to_learn = 1\nalpha = 0.7\n", "k.toml"
    )
    assert config.learner.all_profiles()["quick"].correct_answers_to_learn == 1
    with pytest.raises(ConfigError) as error:
        parse_config("[learner.profiles.quick]\ncorrect_answers_to_learn = 0\n", "k.toml")
    assert "learner.profiles.quick.correct_answers_to_learn" in str(error.value)
    with pytest.raises(ConfigError) as error:
        parse_config(
            "[game]\nmax_trials_per_target = 4\n"
            "[learner.profiles.stubborn]\ncorrect_answers_to_learn = 5\n",
            "k.toml",
        )
    assert str(error.value) == (
        "k.toml: learner.profiles.stubborn.correct_answers_to_learn: "
        "expected at most game.max_trials_per_target (4), found 5"
    )


def test_simulate_plays_the_profile_s_greens_and_says_so():
    code, out = _run("--profile", "fast", "--variant", "names", "--groups", "50", "--seed", "1",
                     "--json")  # fmt: skip
    assert code == 0
    result = json.loads(out)
    assert result["correct_answers_to_learn"] == 1
    assert result["trials_min"] == 1  # one green learns a name
    code, text = _run("--profile", "slow", "--variant", "names", "--groups", "20", "--seed", "1")
    assert "3 greens to learn" in text and "guesses per game:" in text


def test_compare_profiles_gives_each_arm_its_own_greens():
    code, out = _run("--power", "--compare", "profile=paper,fast", "--variant", "names",
                     "--groups-per-arm", "8", "--studies", "100", "--seed", "1", "--json")  # fmt: skip
    assert code == 0
    (point,) = json.loads(out)["points"]
    # One green to learn against two: a trial fewer per name, told apart by 8 groups a
    # side (the old fast learner, the paper's greens, differed by 0.06 trials).
    assert 0.8 < point["mean_difference"] < 1.3
    assert point["power"] > 0.8


@pytest.mark.parametrize(("target", "greens"), [(13.5, 1), (20.0, 2), (26.0, 3)])
def test_design_finds_the_greens_for_a_target_length(target, greens):
    code, out = _run("--design", str(target), "--variant", "names", "--design-groups", "300",
                     "--seed", "2", "--json")  # fmt: skip
    assert code == 0
    found = json.loads(out)
    assert found["profile"]["correct_answers_to_learn"] == greens
    assert abs(found["profile"]["guesses_per_game"] - target) < 1.5
    # What it proposes repeats a red no more than the paper's learner (its limit).
    assert found["profile"]["repeat_red_rate"] <= found["paper"]["repeat_red_rate"] + 0.005


def test_design_prints_a_profile_to_paste_and_its_figures():
    code, text = _run("--design", "14", "--variant", "names", "--design-groups", "200",
                      "--seed", "2")  # fmt: skip
    assert code == 0
    snippet = text[text.index("[learner.profiles.designed]"):].split("\n\n")[0]
    profile = msgspec.toml.decode(snippet.encode())["learner"]["profiles"]["designed"]
    assert ProfileSettings(**profile).correct_answers_to_learn == 1
    assert "guesses per game" in text and "repeats a red" in text


def test_design_refuses_what_it_cannot_combine_with(capsys):
    assert cli.main(["simulate", "--design", "20", "--power", "--compare", "profile=paper,slow"]) == 2
    assert "--design: cannot be combined with --power, --compare" in capsys.readouterr().err
    assert cli.main(["simulate", "--design", "0"]) == 2
    assert "--design: expected a number of guesses above 0, found 0.0" in capsys.readouterr().err
