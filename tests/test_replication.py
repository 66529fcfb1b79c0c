"""The game on the simulated robot and the simulator agree on the study's statistics."""

from __future__ import annotations

import pytest

from kasparctl.learning.study_stats import summarise
from kasparctl.sim.demo import demo_config, with_variant
from kasparctl.sim.replicate import replicate
from kasparctl.sim.simulate import simulate_study
from kasparctl.sim.teacher import Teacher


@pytest.mark.parametrize("teacher", [Teacher(), Teacher(p_wrong_green=0.1, p_wrong_red=0.1)])
def test_demo_games_agree_with_the_simulator(teacher: Teacher) -> None:
    config = demo_config()
    config = with_variant(config, "pilot")
    games = replicate(config, games=80, first_seed=1000, teacher=teacher)
    simulated = summarise(
        simulate_study(4000, config.game, config.profile("paper"), teacher, seed=5)
    )
    assert games.problems == 240
    assert games.initial_entropy == pytest.approx(simulated.initial_entropy)
    # 240 problems against 12,000 (fixed seeds, so never flaky): tolerances of 3-4 standard errors.
    assert games.trials_mean == pytest.approx(simulated.trials_mean, abs=0.45)
    assert games.trials_sd == pytest.approx(simulated.trials_sd, abs=0.5)
    assert games.first_guess_correct_rate == pytest.approx(
        simulated.first_guess_correct_rate, abs=0.08
    )
    assert games.trials_min >= 2
    for game_entropy, sim_entropy in zip(
        games.entropy_by_trial[:4], simulated.entropy_by_trial[:4], strict=True
    ):
        assert game_entropy == pytest.approx(sim_entropy, abs=0.15)
