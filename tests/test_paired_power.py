"""`simulate --power --paired`: each group plays both arms, analysed as the report does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from kasparctl.cli import main
from kasparctl.commands import paired_power
from kasparctl.learning.learner import LearnerParams
from kasparctl.research.inference import compare
from kasparctl.sim.paired import paired_power as simulate_paired
from kasparctl.sim.paired import paired_t
from kasparctl.sim.power import Arm, PowerError
from kasparctl.sim.request import Design, Request
from kasparctl.sim.simulate import pilot_game
from kasparctl.sim.teacher import Teacher

PAPER = Arm("paper", pilot_game(), LearnerParams(), Teacher())
SLOW = Arm("slow", pilot_game(), LearnerParams(alpha=0.2, beta=4.0), Teacher())


def _t_only(num_a, den_a, num_b, den_b, groups, first):  # type: ignore[no-untyped-def]
    return [float(p) for p in paired_t(num_a, den_a, num_b, den_b)]


def test_the_paired_t_test_against_a_hand_computation() -> None:
    # Differences 1, 2, 3, 2: mean 2, sd 0.8165, t = 4.899 on 3 df: p = 0.0163 (R: t.test paired).
    ones = np.ones((4, 1))
    a = np.array([[6.0], [7.0], [9.0], [6.0]])
    b = np.array([[5.0], [5.0], [6.0], [4.0]])
    assert paired_t(a, ones, b, ones) == pytest.approx([0.0163], abs=0.0002)


def test_each_study_is_analysed_as_the_report_would_analyse_it_alone() -> None:
    seen: list[tuple[np.ndarray, list[float | None]]] = []
    request = Request(power=True, compare=("profile", ("paper", "slow")), seed=4,
                      design=Design("trials_mean", (6,), 5, 0.05))  # fmt: skip

    real_compare = paired_power.compare

    def spy(*args, **kwargs):  # type: ignore[no-untyped-def]
        contrasts = real_compare(*args, **kwargs)
        seen.append((args[3], [c.p for c in contrasts]))
        return contrasts

    paired_power.compare = spy  # type: ignore[assignment]
    try:
        result = paired_power.answer(request, 0.0)
    finally:
        paired_power.compare = real_compare  # type: ignore[assignment]
    assert [p.groups for p in result.points] == [6] and result.points[0].a_first == 3
    (((num_a, den_a), (num_b, den_b)), ps), _null = seen
    groups = [f"group {i + 1:03d}" for i in range(6)]
    first = {g: "a" if i % 2 == 0 else "b" for i, g in enumerate(groups)}
    for study in range(5):
        column = slice(study, study + 1)
        (alone,) = compare("compare profile", ("profile paper", "profile slow"), ["trials_mean"],
                           ((num_a[:, column], den_a[:, column]), (num_b[:, column], den_b[:, column])),
                           "group", paired_power.REPLICATES, 4, (groups, groups), first)  # fmt: skip
        # The report's own paired analysis of that study alone gives the same p.
        assert alone.paired and alone.shared == 6 and alone.a_first == 3
        assert alone.p == ps[study]


def test_identical_conditions_are_rejected_at_the_tests_level_by_the_paired_t() -> None:
    points = simulate_paired((PAPER, PAPER), "trials_mean", (8, 16), 1000, 0.05, 2, _t_only)
    for point in points:
        # The power of "no difference" is the null rate, twice over (arm A against A again).
        assert point.power == pytest.approx(0.05, abs=3 * point.mc_error + 0.005)
        assert point.null_rate == pytest.approx(0.05, abs=0.025)
        assert abs(point.difference) < 0.2


def test_power_grows_with_the_groups_and_an_order_effect_costs_power_not_bias() -> None:
    plain = simulate_paired((PAPER, SLOW), "trials_mean", (4, 6, 8), 400, 0.05, 1, _t_only)
    powers = [p.power for p in plain]
    assert powers == sorted(powers) and powers[-1] > 0.9
    assert all(-4.0 < p.difference < -3.0 for p in plain)  # slow takes ~3.5 trials longer
    ordered = simulate_paired((PAPER, SLOW), "trials_mean", (4, 6, 8), 400, 0.05, 1, _t_only,
                              order_effect=3.0)  # fmt: skip
    # Counterbalanced, a second session 3 trials slower leaves the difference where it was
    # (half the groups' A and half their B carry it) and widens its spread.
    for before, after in zip(plain, ordered, strict=True):
        assert after.difference == pytest.approx(before.difference, abs=0.1)
        assert after.power < before.power


def test_a_design_below_the_reports_minimum_is_refused() -> None:
    with pytest.raises(PowerError, match="--groups-per-arm: expected numbers >= 4 with --paired"):
        simulate_paired((PAPER, SLOW), "trials_mean", (2, 8), 10, 0.05, 1, _t_only)


def test_simulate_paired_table_json_and_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    figure = tmp_path / "paired.svg"
    arguments = ["simulate", "--power", "--paired", "--compare", "profile=paper,slow",
                 "--groups-per-arm", "4,8", "--studies", "100", "--seed", "3"]  # fmt: skip
    assert main([*arguments, "--figure", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "each group in both" in out and "null rejected" in out and "paired t-test" in out
    assert b"<svg" in figure.read_bytes()[:400]
    assert main([*arguments, "--order-effect", "0.5", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["design"] == "paired" and result["order_effect"] == 0.5
    assert [p["groups"] for p in result["points"]] == [4, 8]
    assert [p["a_first"] for p in result["points"]] == [2, 4]


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--paired"], "--paired: only with --power"),
        (["--power", "--compare", "profile=paper,slow", "--order-effect", "1"],
         "--order-effect: only with --paired"),
        (["--power", "--paired", "--compare", "profile=paper,slow", "--groups-per-arm", "2,4"],
         "--groups-per-arm: expected numbers >= 4 with --paired"),
        (["--power", "--paired", "--compare", "profile=paper,slow", "--studies", "100000",
          "--groups-per-arm", "64"], "expected at most 5,000,000"),
    ],
)
def test_paired_options_are_checked(
    arguments: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["simulate", *arguments]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("kasparctl simulate: error: ") and message in line


def test_studies_are_analysed_a_block_at_a_time_with_the_same_result(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from kasparctl.sim import paired

    calls: list[int] = []

    def counted(num_a, den_a, num_b, den_b, groups, first):  # type: ignore[no-untyped-def]
        calls.append(num_a.shape[1])
        return _t_only(num_a, den_a, num_b, den_b, groups, first)

    whole = simulate_paired((PAPER, SLOW), "trials_mean", (4,), 50, 0.05, 9, counted)
    assert calls == [50, 50]
    monkeypatch.setattr(paired, "STUDY_BLOCK", 7)
    calls.clear()
    blocked = simulate_paired((PAPER, SLOW), "trials_mean", (4,), 50, 0.05, 9, counted)
    assert calls == [7] * 7 + [1] + [7] * 7 + [1]
    assert blocked == whole
