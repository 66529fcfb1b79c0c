"""The simulator: the learning rule, the teacher, the statistics, both paths and the command."""

from __future__ import annotations

import contextlib
import io
import json
import math

import msgspec
import numpy as np
import pytest

from kasparctl import cli
from kasparctl.game.problem import ProblemError, TargetProgress
from kasparctl.learning.learner import LearnerParams
from kasparctl.learning.study_stats import (
    ProblemRecord,
    ProblemTable,
    TrialRecord,
    summarise,
    summarise_table,
    tabulate,
)
from kasparctl.sim.simulate import pilot_game, simulate_group, simulate_study
from kasparctl.sim.sweep import PilotShape, simulate_pilot_problems, sweep
from kasparctl.sim.teacher import Teacher, TeacherError

PAPER = LearnerParams()
HONEST = Teacher()
LOG2_6 = math.log2(6)

# --- the learning rule -----------------------------------------------------------------


def test_two_greens_in_a_row_for_the_same_label_learn_it():
    progress = TargetProgress(correct_answers_to_learn=2, max_trials=30)
    assert not progress.record(4, False)
    assert not progress.record(1, True)
    assert progress.record(1, True)
    assert progress.learned == 1 and progress.done and not progress.given_up
    assert progress.trials == 3


@pytest.mark.parametrize(
    "interruption",
    [(1, False), (2, True), (1, None)],
    ids=["red", "green for another label", "no answer"],
)
def test_the_streak_must_be_unbroken(interruption):
    progress = TargetProgress(correct_answers_to_learn=2, max_trials=30)
    progress.record(1, True)
    progress.record(*interruption)
    assert not progress.record(1, True)
    assert progress.learned is None
    assert progress.record(1, True)
    assert progress.trials == 4


def test_an_unanswered_guess_counts_as_a_trial():
    progress = TargetProgress(correct_answers_to_learn=1, max_trials=2)
    progress.record(0, None)
    assert progress.trials == 1 and not progress.done


def test_a_target_is_given_up_after_the_maximum_and_takes_no_more_guesses():
    progress = TargetProgress(correct_answers_to_learn=2, max_trials=3)
    for label in (0, 1, 2):
        progress.record(label, True)
    assert progress.done and progress.given_up and progress.learned is None
    with pytest.raises(ProblemError):
        progress.record(0, True)


def test_learning_limits_are_checked():
    with pytest.raises(ProblemError):
        TargetProgress(correct_answers_to_learn=0)
    with pytest.raises(ProblemError):
        TargetProgress(correct_answers_to_learn=3, max_trials=2)


# --- the teacher -----------------------------------------------------------------------


def test_honest_teacher_answers_truthfully_and_draws_nothing():
    rng = np.random.default_rng(0)
    before = rng.bit_generator.state
    assert HONEST.answer(True, rng) is True
    assert HONEST.answer(False, rng) is False
    assert rng.bit_generator.state == before


def test_certain_mistakes_and_silence():
    rng = np.random.default_rng(0)
    assert Teacher(p_wrong_green=1.0).answer(False, rng) is True
    assert Teacher(p_wrong_green=1.0).answer(True, rng) is True
    assert Teacher(p_wrong_red=1.0).answer(True, rng) is False
    assert Teacher(p_no_answer=1.0).answer(True, rng) is None


def test_teacher_mistake_rates_follow_their_probabilities():
    teacher = Teacher(p_wrong_green=0.2, p_wrong_red=0.05, p_no_answer=0.1)
    rng = np.random.default_rng(1234)
    wrong = [teacher.answer(False, rng) for _ in range(20000)]
    right = [teacher.answer(True, rng) for _ in range(20000)]
    assert wrong.count(None) / 20000 == pytest.approx(0.1, abs=0.02)
    assert wrong.count(True) / 20000 == pytest.approx(0.9 * 0.2, abs=0.02)
    assert right.count(False) / 20000 == pytest.approx(0.9 * 0.05, abs=0.01)


@pytest.mark.parametrize("key", ["p_wrong_green", "p_wrong_red", "p_no_answer"])
@pytest.mark.parametrize("value", [-0.1, 1.5, math.nan])
def test_teacher_probabilities_are_checked(key, value):
    with pytest.raises(TeacherError) as caught:
        Teacher(**{key: value})
    assert caught.value.key == key


# --- statistics over plain records -----------------------------------------------------


def _problem(choices, feedback, correct, learned, answer=3, entropy_after=0.01):
    entropies = [2.5 - 0.5 * i for i in range(len(choices))]
    trials = tuple(
        TrialRecord(c, f, e, ok)
        for c, f, e, ok in zip(choices, feedback, entropies, correct, strict=True)
    )
    return ProblemRecord(0, 0, answer, trials, learned, (0.0,) * 6, entropy_after)


def test_statistics_of_hand_made_problems():
    problems = [
        # red then the same toy again (perseverative), red, green, a different toy (win-shift)...
        _problem(
            [1, 1, 3, 2, 3, 3],
            [False, False, True, False, True, True],
            [False, False, True, False, True, True],
            learned=3,
        ),
        _problem([3, 3], [True, True], [True, True], learned=3),
        # given up: not in trials to learn, nor in the final entropies
        _problem([0, 4, 5], [False, False, False], [False, False, False], learned=None),
    ]
    stats = summarise(problems)
    assert stats.problems == 3 and stats.problems_learned == 2 and stats.problems_given_up == 1
    assert stats.trials_total == 11
    assert (stats.trials_mean, stats.trials_min, stats.trials_max) == (4.0, 2, 6)
    assert stats.trials_sd == pytest.approx(math.sqrt(8))
    assert (stats.first_guess_correct, stats.first_guess_correct_rate) == (1, pytest.approx(1 / 3))
    assert (stats.perseverative_errors, stats.win_shifts) == (1, 1)
    assert stats.perseverative_error_rate == pytest.approx(1 / 11)
    # Before the last guess: 2.5 - 0.5 * 5 = 0.0 and 2.5 - 0.5 * 1 = 2.0.
    assert stats.final_entropy_mean == pytest.approx(1.0)
    assert stats.final_entropy_after_mean == pytest.approx(0.01)
    assert stats.entropy_by_trial_n == [3, 3, 2, 1, 1, 1]
    assert stats.entropy_by_trial[:3] == pytest.approx([2.5, 2.0, 1.5])
    assert stats.initial_entropy == 2.5


def test_equal_initial_entropies_give_that_value_exactly():
    problems = [_problem([0, 0], [True, True], [True, True], 0) for _ in range(1001)]
    problems = [
        ProblemRecord(
            p.group,
            p.target,
            p.answer,
            tuple(TrialRecord(t.choice, t.feedback, LOG2_6, t.correct) for t in p.trials),
            p.learned,
            p.final_q,
            p.entropy_after,
        )
        for p in problems
    ]
    assert summarise(problems).initial_entropy == LOG2_6


def test_unknown_answers_give_no_first_guess_rate():
    problem = _problem([1, 1], [True, True], [None, None], learned=1, answer=None)
    stats = summarise([problem])
    assert stats.first_guess_correct_rate is None
    assert stats.problems_learned_wrong == 0


# --- the scalar simulator --------------------------------------------------------------


def _records_as_plain(records):
    return msgspec.to_builtins(records)


def test_one_seed_gives_identical_records():
    game = pilot_game()
    first = simulate_study(20, game, PAPER, Teacher(0.1, 0.05, 0.05), seed=42)
    again = simulate_study(20, game, PAPER, Teacher(0.1, 0.05, 0.05), seed=42)
    other = simulate_study(20, game, PAPER, Teacher(0.1, 0.05, 0.05), seed=43)
    assert _records_as_plain(first) == _records_as_plain(again)
    assert _records_as_plain(first) != _records_as_plain(other)


def test_a_group_does_not_depend_on_how_many_groups_run():
    few = simulate_study(3, pilot_game(), PAPER, HONEST, seed=5)
    many = simulate_study(50, pilot_game(), PAPER, HONEST, seed=5)
    assert _records_as_plain(many[: len(few)]) == _records_as_plain(few)


def test_pilot_problems_start_from_no_clue_and_learn_the_answer_with_an_honest_teacher():
    records = simulate_study(200, pilot_game(), PAPER, HONEST, seed=3)
    assert len(records) == 600
    for problem in records:
        assert problem.trials[0].entropy == pytest.approx(LOG2_6, abs=1e-12)
        assert problem.learned == problem.answer
        assert len(problem.trials) >= 2
        assert all(t.correct == (t.choice == problem.answer) for t in problem.trials)
        assert problem.trials[-1].feedback is True and problem.trials[-2].feedback is True
        assert max(problem.final_q) == problem.final_q[problem.answer]
    # Each location is its own problem: toys learned elsewhere stay candidates.
    by_group = {}
    for problem in records:
        by_group.setdefault(problem.group, []).append(problem)
    assert all(len({p.answer for p in group}) == 3 for group in by_group.values())


def test_names_variant_drops_learned_names_and_stays_on_a_bag_until_learned():
    game = pilot_game(variant="names", locations=())
    for group in range(30):
        records = simulate_group(game, PAPER, HONEST, np.random.default_rng(group), group)
        assert [p.target for p in records] == list(range(6))
        assert sorted(p.answer for p in records) == list(range(6))
        learned_before: set[int] = set()
        for index, problem in enumerate(records):
            assert not {t.choice for t in problem.trials} & learned_before
            assert problem.trials[0].entropy == pytest.approx(math.log2(6 - index), abs=1e-12)
            learned_before.add(problem.learned)
        # The last bag has one name left: no doubt, two confirming greens.
        assert records[-1].trials[0].entropy == 0.0 and len(records[-1].trials) == 2


def test_pilot_replication_with_the_papers_learner():
    """Wide bands around what Eq. 1-3 imply: about 4.5 trials, first guess right 1 in 6."""
    stats = summarise(simulate_study(1500, pilot_game(), PAPER, HONEST, seed=2024))
    assert stats.problems == 4500 and stats.problems_given_up == 0
    assert 4.2 <= stats.trials_mean <= 4.9
    assert 1.4 <= stats.trials_sd <= 2.0
    assert stats.trials_min == 2
    assert 0.13 <= stats.first_guess_correct_rate <= 0.20
    assert stats.perseverative_error_rate < 0.01 and stats.win_shift_rate < 0.015
    assert stats.initial_entropy == LOG2_6
    assert stats.final_entropy_after_mean < stats.final_entropy_mean < 0.5
    # Entropy falls trial by trial over the first guesses, as in the paper's Fig. 2.
    assert all(
        a > b for a, b in zip(stats.entropy_by_trial[:6], stats.entropy_by_trial[1:6], strict=False)
    )


def test_a_slow_learner_needs_more_trials_and_errs_more():
    paper = summarise(simulate_study(500, pilot_game(), PAPER, HONEST, seed=9))
    slow = summarise(
        simulate_study(500, pilot_game(), LearnerParams(alpha=0.2, beta=4.0), HONEST, seed=9)
    )
    assert slow.trials_mean > paper.trials_mean + 2
    assert slow.perseverative_error_rate > paper.perseverative_error_rate
    assert slow.win_shift_rate > paper.win_shift_rate


def test_false_greens_can_teach_a_wrong_toy_and_silence_costs_trials():
    fooled = summarise(simulate_study(500, pilot_game(), PAPER, Teacher(p_wrong_green=0.5), seed=4))
    assert fooled.problems_learned_wrong > 0
    quiet = summarise(simulate_study(500, pilot_game(), PAPER, Teacher(p_no_answer=0.3), seed=4))
    honest = summarise(simulate_study(500, pilot_game(), PAPER, HONEST, seed=4))
    assert quiet.trials_mean > honest.trials_mean + 1


# --- the vectorised path agrees with the scalar path -----------------------------------

AGREEMENT_CASES = [
    (PAPER, HONEST),
    (PAPER, Teacher(0.3, 0.2, 0.2)),
    (LearnerParams(alpha=0.25, beta=3.0, gamma=0.5, initial_q=0.3), Teacher(0.1, 0.1, 0.1)),
]


@pytest.mark.parametrize(("params", "teacher"), AGREEMENT_CASES)
def test_a_single_row_reproduces_the_scalar_problem_exactly(params, teacher):
    one_location = pilot_game(locations=("shelf",))
    for seed in range(60):
        answer = seed % 6
        scalar = tabulate(
            simulate_group(
                one_location, params, teacher, np.random.default_rng(seed), answers=[answer]
            )
        )
        (vector,) = simulate_pilot_problems(
            np.array([params.alpha]),
            np.array([params.beta]),
            np.random.default_rng(seed),
            params,
            teacher,
            PilotShape(problems_per_group=1),
            answers=np.array([answer]),
        )
        for name in ProblemTable.__slots__:
            ours, theirs = getattr(scalar, name), getattr(vector, name)
            if name.startswith("entropy_"):
                theirs = theirs[: len(ours)]
            assert np.array_equal(ours, theirs), (seed, name)


@pytest.mark.parametrize(("params", "teacher"), AGREEMENT_CASES[:2])
def test_many_rows_give_the_scalar_statistics(params, teacher):
    scalar = summarise(simulate_study(2000, pilot_game(), params, teacher, seed=77))
    (vector,) = sweep([(params.alpha, params.beta)], 6000, seed=78, params=params, teacher=teacher)
    assert vector.problems == scalar.problems
    assert vector.trials_mean == pytest.approx(scalar.trials_mean, rel=0.05)
    assert vector.trials_sd == pytest.approx(scalar.trials_sd, rel=0.1)
    assert vector.first_guess_correct_rate == pytest.approx(
        scalar.first_guess_correct_rate, abs=0.03
    )
    assert vector.win_shift_rate == pytest.approx(scalar.win_shift_rate, abs=0.01)
    assert vector.final_entropy_mean == pytest.approx(scalar.final_entropy_mean, abs=0.05)
    assert vector.initial_entropy == scalar.initial_entropy
    n = 5
    assert vector.entropy_by_trial[:n] == pytest.approx(scalar.entropy_by_trial[:n], abs=0.05)


def test_sweep_rows_keep_their_own_parameters_whatever_the_chunking():
    settings = [(0.6, 8.0), (0.2, 4.0), (0.6, 8.0)]
    whole = sweep(settings, 3000, seed=1)
    assert whole[1].trials_mean > whole[0].trials_mean + 2
    assert whole[2].trials_mean == pytest.approx(whole[0].trials_mean, abs=0.2)
    values = np.repeat(np.array(settings), 3000, axis=0)
    setting = np.repeat(np.arange(3), 3000)
    chunked = [
        summarise_table(t)
        for t in simulate_pilot_problems(
            values[:, 0], values[:, 1], np.random.default_rng(1), setting=setting, chunk_rows=1000
        )
    ]
    for ours, theirs in zip(chunked, whole, strict=True):
        assert ours.problems == theirs.problems == 3000
        assert ours.trials_mean == pytest.approx(theirs.trials_mean, abs=0.3)


# --- the command -----------------------------------------------------------------------


def _run(*argv: str) -> tuple[int, str, str]:
    """The simulate command through the real command line (its contract: exit codes, lines)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(["simulate", *argv])
        except SystemExit as stop:
            code = int(stop.code or 0)
    return code, out.getvalue(), err.getvalue()


REQUIRED_KEYS = {
    "problems",
    "trials_mean",
    "trials_sd",
    "trials_min",
    "trials_max",
    "first_guess_correct_rate",
    "perseverative_error_rate",
    "win_shift_rate",
    "initial_entropy",
    "final_entropy_mean",
    "entropy_by_trial",
}


def test_json_is_one_object_with_the_papers_statistics():
    code, out, err = _run("--groups", "40", "--seed", "1", "--json")
    assert code == 0, err
    result = json.loads(out)
    assert result.keys() >= REQUIRED_KEYS
    assert result["problems"] == 120
    assert result["initial_entropy"] == LOG2_6
    assert isinstance(result["entropy_by_trial"], list) and result["entropy_by_trial"][0] > 2.5
    assert (result["alpha"], result["beta"], result["seed"]) == (0.6, 8.0, 1)
    assert _run("--groups", "40", "--seed", "1", "--json")[1] == out


def test_through_the_real_command_line():
    code, out, _ = _run("--groups", "5", "--seed", "3", "--json")
    assert code == 0
    assert json.loads(out).keys() >= REQUIRED_KEYS


def test_table_shows_the_paper_beside_the_simulation():
    code, out, _ = _run("--groups", "16", "--seed", "1")
    assert code == 0
    assert "trials to learn" in out and "4.21 ± 1.46" in out and "2.585" in out


def test_profile_overrides_teacher_and_variant_reach_the_simulation():
    slow = json.loads(_run("--groups", "200", "--seed", "2", "--profile", "slow", "--json")[1])
    paper = json.loads(_run("--groups", "200", "--seed", "2", "--json")[1])
    assert slow["trials_mean"] > paper["trials_mean"]
    tuned = json.loads(
        _run("--groups", "5", "--seed", "2", "--profile", "slow", "--beta", "7", "--json")[1]
    )
    assert tuned["beta"] == 7.0 and tuned["alpha"] == slow["alpha"]
    fooled = json.loads(
        _run("--groups", "200", "--seed", "2", "--p-wrong-green", "0.5", "--json")[1]
    )
    assert fooled["problems_learned_wrong"] > 0
    names = json.loads(_run("--groups", "5", "--seed", "2", "--variant", "names", "--json")[1])
    assert names["problems"] == 30 and names["variant"] == "names"


def test_sweep_lists_each_setting():
    code, out, err = _run(
        "--groups",
        "50",
        "--seed",
        "1",
        "--sweep",
        "alpha=0.2:0.6:0.2",
        "--sweep",
        "beta=4:8:4",
        "--json",
    )
    assert code == 0, err
    rows = json.loads(out)
    assert [(r["alpha"], r["beta"]) for r in rows] == [
        (0.2, 4.0),
        (0.2, 8.0),
        (0.4, 4.0),
        (0.4, 8.0),
        (0.6, 4.0),
        (0.6, 8.0),
    ]
    assert all(r["problems"] == 150 and r["trials_mean"] >= 2 for r in rows)
    code, out, _ = _run("--groups", "50", "--seed", "1", "--sweep", "beta=1:3:1")
    assert code == 0 and "trials mean" in out and len(out.splitlines()) == 5


@pytest.mark.parametrize(
    ("argv", "option", "code"),
    [
        (["--groups", "0"], "--groups", 2),
        (["--groups", "many"], "--groups", 2),
        (["--p-wrong-green", "1.5"], "--p-wrong-green", 2),
        (["--alpha", "nan"], "--alpha", 2),
        (["--alpha", "2"], "--alpha", 2),
        (["--beta", "-1"], "--beta", 2),
        (["--profile", "quick"], "--profile", 2),
        (["--sweep", "gamma=0:1:0.1"], "--sweep", 2),
        (["--sweep", "alpha=0:1:0.1"], "--sweep", 2),
        (["--sweep", "beta=5:1:1"], "--sweep", 2),
        (["--sweep", "beta=1:5:1", "--sweep", "beta=2:3:1"], "--sweep", 2),
        (["--variant", "names", "--sweep", "beta=1:2:1"], "--sweep", 2),
    ],
)
def test_bad_values_name_the_option_and_what_was_expected(argv, option, code):
    returned, out, err = _run(*argv)
    assert returned == code
    assert out == ""
    (line,) = err.splitlines()
    assert line.startswith("kasparctl simulate: error: ") and option in line and "expected" in line


def test_config_file_gives_game_and_profiles(tmp_path):
    config = tmp_path / "kaspar.toml"
    config.write_text(
        '[game]\nvariant = "pilot"\nlocations = ["shelf", "box"]\nseed = 8\n'
        '[learner]\ndefault_profile = "eager"\n'
        "[learner.profiles.eager]\nalpha = 1.0\nbeta = 12.0\n"
    )
    result = json.loads(_run("--config", str(config), "--groups", "10", "--json")[1])
    assert result["problems"] == 20 and result["seed"] == 8
    assert (result["profile"], result["alpha"], result["beta"]) == ("eager", 1.0, 12.0)


def test_a_bad_config_file_is_reported_on_stderr(tmp_path):
    config = tmp_path / "kaspar.toml"
    config.write_text("[game]\nvariant = 'pilot'\nlocatoins = ['shelf']\n")
    code, out, err = _run("--config", str(config))
    assert code == 1 and out == ""
    assert err.startswith("error: ") and "locatoins" in err
    code, _, err = _run("--config", str(tmp_path / "missing.toml"))
    assert code == 1 and "missing.toml" in err


def test_the_first_guess_on_a_re_opened_target_follows_no_answer_as_the_records_read():
    """game.fold: a re-opened target's next guess follows nothing (no win-shift from the
    green that taught the wrong name); the simulator counts as the report does."""
    game = pilot_game()
    teacher = Teacher(p_wrong_green=0.3, p_wrong_red=0.05)
    rng = np.random.default_rng(11)
    reopened_problems = 0
    for group in range(200):
        for problem in simulate_group(game, PAPER, teacher, rng, group, recover=True):
            explicit = [i for i, t in enumerate(problem.trials) if t.win_shift is not None]
            assert len(explicit) == problem.reopened
            for index in explicit:
                trial, before = problem.trials[index], problem.trials[index - 1]
                assert (trial.perseverative, trial.win_shift) == (False, False)
                assert before.feedback is True  # the green that taught the name re-opened
            reopened_problems += problem.reopened > 0
    assert reopened_problems > 10
