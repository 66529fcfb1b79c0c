"""Study design by simulation: the readings of the paper, replication, power, teacher models.

The vectorised study simulator is held to the scalar one; exclude_learned to the
game; the fit to the readings' known behaviour; power to its definition (two
identical arms reject at the test's level); teacher models to the children they
were fitted from.
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import msgspec
import numpy as np
import pytest
from research_cohort import Cohort, make_cohort

from kasparctl.cli import main
from kasparctl.config import SessionPlan
from kasparctl.learning.learner import LearnerParams
from kasparctl.learning.study_stats import summarise, summarise_table
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo, with_variant
from kasparctl.sim.fit import PAPER, fit, place, simulate_studies
from kasparctl.sim.power import Arm, incomplete_beta, power_curve, t_two_sided_p, welch
from kasparctl.sim.simulate import pilot_game, simulate_study
from kasparctl.sim.studies import concatenate, group_values, simulate_groups, study_values
from kasparctl.sim.teacher import (
    ChildTeacher,
    Teacher,
    TeacherError,
    TeacherModel,
    load_teacher,
    teacher_toml,
)

PAPER_LEARNER = LearnerParams()


@pytest.fixture(scope="module")
def cohort(tmp_path_factory: pytest.TempPathFactory) -> Cohort:
    return make_cohort(tmp_path_factory.mktemp("cohort"))


def vector_stats(groups: int, game, params, teacher, seed: int = 1):
    table = concatenate(list(simulate_groups(groups, game, params, teacher, np.random.default_rng(seed))))
    return table, summarise_table(table.problem_table())


# -- the vectorised study simulator and exclude_learned -----------------------------------


@pytest.mark.parametrize("rule", ["names", "always"])
@pytest.mark.parametrize("teacher", [Teacher(), Teacher(0.2, 0.1, 0.1)], ids=["honest", "noisy"])
def test_the_vectorised_groups_agree_with_the_scalar_simulator(rule: str, teacher: Teacher) -> None:
    game = pilot_game(exclude_learned_rule=rule)
    scalar = summarise(simulate_study(3000, game, PAPER_LEARNER, teacher, seed=2))
    _, vector = vector_stats(3000, game, PAPER_LEARNER, teacher)
    # 9,000 problems each: a few standard errors (noisy children make long, skewed problems).
    assert vector.trials_mean == pytest.approx(scalar.trials_mean, rel=0.03)
    assert vector.trials_sd == pytest.approx(scalar.trials_sd, rel=0.06)
    assert vector.first_guess_correct_rate == pytest.approx(scalar.first_guess_correct_rate, abs=0.025)
    assert vector.initial_entropy == pytest.approx(scalar.initial_entropy, abs=0.01)
    assert vector.problems_learned_wrong / 9000 == pytest.approx(scalar.problems_learned_wrong / 9000, abs=0.01)
    assert vector.entropy_by_trial[:4] == pytest.approx(scalar.entropy_by_trial[:4], abs=0.05)


def test_a_teacher_per_child_agrees_between_the_two_simulators() -> None:
    model = TeacherModel((ChildTeacher(p_wrong_green=0.4), ChildTeacher(), ChildTeacher(p_wrong_red=0.3)))
    game = pilot_game()
    scalar = summarise(simulate_study(3000, game, PAPER_LEARNER, model, seed=3))
    table, vector = vector_stats(3000, game, PAPER_LEARNER, model)
    assert vector.trials_mean == pytest.approx(scalar.trials_mean, abs=0.15)
    assert vector.problems_learned_wrong == pytest.approx(scalar.problems_learned_wrong, rel=0.2)
    # The first guess of every group is child 1's: only child 1 gives false greens.
    first = table.wrong_green[:, 0]
    assert first.sum() > 0


def test_elimination_in_the_pilot_offers_fewer_toys_to_later_locations() -> None:
    game = pilot_game(exclude_learned_rule="always")
    table, stats = vector_stats(2000, game, PAPER_LEARNER, Teacher())
    assert (table.candidates == np.array([6, 5, 4])).all()
    initial = table.initial_entropy.mean(axis=0)
    assert initial == pytest.approx([math.log2(6), math.log2(5), math.log2(4)])
    # The paper's own step-4 rule: 4.5, 4, 3.5 trials, so 4.0 on average (honest children).
    assert stats.trials_mean == pytest.approx(4.0, abs=0.06)
    _, kept = vector_stats(2000, pilot_game(), PAPER_LEARNER, Teacher())
    assert kept.trials_mean == pytest.approx(4.5, abs=0.08)


def test_the_game_itself_eliminates_in_the_pilot_when_configured(tmp_path: Path) -> None:
    config = with_variant(demo_config(), "pilot")
    config = msgspec.structs.replace(config, game=msgspec.structs.replace(config.game, exclude_learned_rule="always"))
    run_demo(config, DemoOptions(state_dir=tmp_path, seed=4, out=io.StringIO()), fast=True)
    (session,) = (tmp_path / "sessions").iterdir()
    records = [json.loads(line) for line in (session / "records.jsonl").read_text().splitlines()]
    first = {}
    for record in records:
        if record["kind"] == "trial":
            first.setdefault(record["target_index"], len(record["candidates"]))
    assert first == {0: 6, 1: 5, 2: 4}


def test_study_values_are_the_studies_own_figures() -> None:
    table, _ = vector_stats(64, pilot_game(), PAPER_LEARNER, Teacher())
    values = study_values(table, 16)
    assert len(values["trials_mean"]) == 4
    block = table.rows(16, 32)
    learned = block.trials[block.learned >= 0]
    assert values["trials_mean"][1] == pytest.approx(learned.mean())
    assert values["trials_sd"][1] == pytest.approx(learned.std(ddof=1))
    assert values["trials_total"][1] == block.trials.sum()


# -- fitting and replicate ----------------------------------------------------------------


def test_placing_a_figure() -> None:
    simulated = np.arange(1, 101, dtype=float)
    found = place("trials_mean", 50.0, simulated)
    assert found is not None
    assert found.percentile == pytest.approx(49.5)
    assert found.p == pytest.approx(1.0)
    rare = place("trials_mean", 0.0, simulated)
    assert rare is not None and rare.percentile == 0.0 and rare.p == pytest.approx(2 / 101)


def test_the_fit_of_the_readings_separates_them() -> None:
    """Elimination fits the pilot's trial numbers far better than the project's reading;
    no reading gives the final entropy of 0.73 with a single win-shift."""
    results = {}
    for name, rule in (("project", "names"), ("elimination", "always")):
        simulated = simulate_studies(3000, 16, pilot_game(exclude_learned_rule=rule), PAPER_LEARNER, Teacher(3 / 106), 1)
        results[name] = fit(name, PAPER, simulated, 16)
    assert results["elimination"].joint_trials_p > 0.3 > 0.05 > results["project"].joint_trials_p
    for result in results.values():
        assert result.entropy_with_win_shifts_p < 0.01
        placed = {p.figure: p for p in result.placed}
        assert placed["final_entropy_mean"].percentile > 99


def test_replicate_the_paper_with_each_reading_as_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replicate", "--paper", "--readings", "--studies", "500", "--seed", "2", "--json"]) == 0
    fits = json.loads(capsys.readouterr().out)
    names = [f["name"] for f in fits]
    assert names == ["project", "elimination", "optimistic Q0", "elimination, optimistic Q0", "red is no reward"]
    by_name = {f["name"]: f for f in fits}
    optimistic = {p["figure"]: p for p in by_name["optimistic Q0"]["figures"]}
    # The optimistic Q0 reproduces the final entropy, and with it far too many win-shifts.
    assert 10 < optimistic["final_entropy_mean"]["percentile"] < 90
    assert optimistic["win_shifts"]["p"] < 0.05


def test_replicate_a_recorded_cohort(cohort: Cohort, capsys: pytest.CaptureFixture[str]) -> None:
    spoken = [s for s in sorted((cohort.state_dir / "sessions").iterdir()) if json.loads((s / "plan.json").read_text())["condition"] == "paper/spoken"]
    arguments = ["replicate", *map(str, spoken), "--studies", "300", "--json"]
    assert main(arguments) == 0
    (result,) = json.loads(capsys.readouterr().out)
    assert result["groups_per_study"] == 4 and result["name"] == "paper/spoken"
    placed = {p["figure"]: p for p in result["figures"]}
    assert 0 <= placed["trials_mean"]["percentile"] <= 100
    # Both conditions at once are not one cohort.
    assert main(["replicate", "--state-dir", str(cohort.state_dir), "--studies", "300"]) == 1
    assert "a cohort is one condition" in capsys.readouterr().err


# -- power ----------------------------------------------------------------------------------


def test_student_t_and_the_incomplete_beta_against_tables() -> None:
    p = t_two_sided_p(np.array([2.228139, 1.959964, 12.706205, 0.0]), np.array([10.0, 1e7, 1.0, 4.0]))
    assert p == pytest.approx([0.05, 0.05, 0.05, 1.0], abs=1e-5)
    assert incomplete_beta(np.array([2.0]), np.array([3.0]), np.array([0.4])) == pytest.approx([0.5248])


def test_welch_against_a_hand_computation() -> None:
    a = np.array([[4.0, 5.0, 6.0, 5.0]])
    b = np.array([[7.0, 8.0, 6.0, 9.0, 8.0]])
    difference, p = welch(a, b)
    assert difference == pytest.approx([-2.6])
    # t = -2.6 / sqrt(0.6667/4 + 1.3/5) = -3.980, Welch df = 6.96: p = 0.0054 (R: t.test).
    assert p == pytest.approx([0.0054], abs=0.0002)


def test_identical_arms_reject_at_the_tests_level() -> None:
    arm = Arm("same", pilot_game(), PAPER_LEARNER, Teacher())
    points = power_curve((arm, arm), "trials_mean", groups=(8, 16), studies=1000, level=0.05, seed=1)
    for point in points:
        assert point.power == pytest.approx(0.05, abs=3 * point.mc_error + 0.005)
        assert point.mc_error == pytest.approx(math.sqrt(point.power * (1 - point.power) / 1000))


def test_power_grows_with_the_groups() -> None:
    arms = (
        Arm("paper", pilot_game(), PAPER_LEARNER, Teacher()),
        Arm("slow", pilot_game(), LearnerParams(alpha=0.2, beta=4.0), Teacher()),
    )
    points = power_curve(arms, "trials_mean", groups=(2, 4, 8), studies=400, seed=1)
    powers = [p.power for p in points]
    assert powers == sorted(powers) and powers[-1] > 0.9
    assert all(p.difference < -2 for p in points)  # the slow learner takes longer


def test_simulate_power_table_json_and_figure(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    figure = tmp_path / "power.png"
    arguments = ["simulate", "--power", "--compare", "p_wrong_green=0,0.4", "--measure", "wrong_feedback_rate"]
    arguments += ["--groups-per-arm", "2,4,8", "--studies", "200", "--seed", "3"]
    assert main([*arguments, "--figure", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "groups per arm" in out and "80 % power from" in out
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main([*arguments, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert [p["groups_per_arm"] for p in result["points"]] == [2, 4, 8]
    assert result["compare"] == {"name": "p_wrong_green", "a": "0", "b": "0.4"}


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--power"], "--power: expected --compare NAME=A,B"),
        (["--compare", "profile=paper,slow"], "--compare: only with --power"),
        (["--power", "--compare", "profile=paper,quick"], "--compare: profile: expected one of fast, paper, slow, found 'quick'"),
        (["--power", "--compare", "alpha=0.5,2"], "--compare: alpha: expected a number in (0, 1], found 2.0"),
        (["--power", "--compare", "profile=paper,slow", "--studies", "100000", "--groups-per-arm", "64"], "expected at most 5,000,000"),
    ],
)
def test_power_options_are_checked(arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", *arguments]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("kasparctl simulate: error: ") and message in line


def test_group_values_are_each_groups_own() -> None:
    table, _ = vector_stats(50, pilot_game(), PAPER_LEARNER, Teacher(0.3, 0.0, 0.0))
    values = group_values(table, "trials_mean")
    learned = table.learned >= 0
    assert values[7] == pytest.approx(table.trials[7][learned[7]].mean())
    wrong = group_values(table, "wrong_feedback_rate")
    answered = (table.wrong_guesses + table.right_guesses)[7].sum()
    assert wrong[7] == pytest.approx(table.wrong_green[7].sum() / answered)


# -- teacher models -------------------------------------------------------------------------


def test_a_fitted_teacher_recovers_the_childrens_rates(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Demo children with known rates: the fit finds them (within a few standard errors)."""
    state_dirs = []
    for seed in range(12):
        state = tmp_path / f"s{seed}"
        plan = SessionPlan(group=f"G{seed}")
        config = msgspec.structs.replace(demo_config(), sessions=(plan,))
        options = DemoOptions(state_dir=state, seed=seed, teacher=Teacher(0.3, 0.1, 0.3), out=io.StringIO())
        run_demo(config, options, fast=True)
        state_dirs += ["--state-dir", str(state)]
    out = tmp_path / "teacher.toml"
    assert main(["fit-teacher", *state_dirs, "--out", str(out)]) == 0
    model = load_teacher(str(out))
    assert len(model.children) == 3
    pooled = model.pooled()
    # The demo's children answer honestly after a prompt (30 % of questions), so the
    # rates a fit of every answer can recover are 0.3 and 0.1 of the other 70 %.
    assert pooled.p_wrong_green == pytest.approx(0.3 * 0.7, abs=0.06)
    assert pooled.p_wrong_red == pytest.approx(0.1 * 0.7, abs=0.05)
    assert pooled.p_no_answer == pytest.approx(0.3, abs=0.08)  # prompts: the demo's silence
    for child in model.children:
        assert child.answers > 50
        # The demo's children think 0.8 to 2.5 s, or answer after an 8 s prompt.
        assert 1.0 < (child.reaction_time_median or 0) < 4.0
    low, high = model.think_s()
    assert low < 1.6 < high
    # simulate and demo take it.
    capsys.readouterr()  # what the demos above printed
    assert main(["simulate", "--teacher", str(out), "--groups", "50", "--seed", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["teacher"] == str(out)
    assert main(["demo", "--fast", "--seed", "1", "--teacher", str(out), "--state-dir", str(tmp_path / "d")]) == 0


def test_a_teacher_file_round_trips_and_its_errors_are_named(tmp_path: Path) -> None:
    model = TeacherModel((ChildTeacher(0.1, 0.0, 0.0, 0.2, 1.5, 0.4, 30), ChildTeacher()), "hand-made")
    path = tmp_path / "t.toml"
    path.write_text(teacher_toml(model, "a comment"))
    assert load_teacher(str(path)) == model
    for text, message in [
        ("[[children]]\np_wrong_green = 2\n", "children[0].p_wrong_green: expected a probability in [0, 1], found 2"),
        ("[[children]]\np_wrong_gren = 0.1\n", "children[0].p_wrong_gren: unknown key"),
        ("[[children]]\nanswers = 1.5\n", "children[0].answers: expected an integer, found 1.5"),
        ("[[children]]\np_prompt = true\n", "children[0].p_prompt: expected a number, found True"),
        ("source = 'x'\n", "children: expected one or more [[children]] tables, found None"),
        ("children = [\n", "(syntax): not valid TOML"),
    ]:
        path.write_text(text)
        with pytest.raises(TeacherError) as caught:
            load_teacher(str(path))
        assert str(caught.value).startswith(f"{path}: {message}"), str(caught.value)
