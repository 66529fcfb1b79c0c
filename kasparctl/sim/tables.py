"""The simulator's answers as the tables `kasparctl simulate` and `replicate` print.

Every figure of the paper shown here comes from kasparctl.sim.fit (PAPER_STATS),
formatted by the same function as the simulated figure beside it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import msgspec

from kasparctl.config import GameSettings
from kasparctl.learning.learner import LearnerParams
from kasparctl.learning.study_stats import StudyStats
from kasparctl.sim.fit import FIGURES, PAPER_STATS, Fit
from kasparctl.sim.power import PowerPoint
from kasparctl.sim.teacher import Teacher

Figures = Mapping[str, Any]


def number(value: float | None, decimals: int) -> str:
    """A figure to `decimals` places; "-" where nothing was counted."""
    return "-" if value is None else f"{value:.{decimals}f}"


def _cell(show: Callable[..., str], *keys: str) -> Callable[[Figures], str]:
    """A row's cell: `show` of these figures of a study, or nothing where one is not known."""
    return lambda figures: (
        show(*(figures[key] for key in keys)) if all(key in figures for key in keys) else ""
    )


def _spread(decimals: int) -> Callable[[float | None, float | None], str]:
    return lambda mean, sd: f"{number(mean, decimals)} ± {number(sd, decimals)}"


def _with_rate(count: int, rate: float | None) -> str:
    return f"{count} ({number(None if rate is None else 100 * rate, 2)}%)"


def _problems(figures: Figures) -> str:
    if "problems" not in figures:
        return ""
    learned = figures.get("problems_learned")
    return f"{figures['problems']}" + ("" if learned is None else f" ({learned})")


# The study table's rows: a label, and the cell of a study's figures (simulated or published).
STUDY_ROWS: tuple[tuple[str, Callable[[Figures], str]], ...] = (
    ("problems (learned)", _problems),
    ("trials", _cell(str, "trials_total")),
    ("trials to learn, mean ± sd", _cell(_spread(2), "trials_mean", "trials_sd")),
    (
        "trials to learn, min-max",
        _cell(lambda low, high: f"{number(low, 0)}-{number(high, 0)}", "trials_min", "trials_max"),
    ),
    (
        "given up / learned wrong",
        _cell(lambda up, wrong: f"{up} / {wrong}", "problems_given_up", "problems_learned_wrong"),
    ),
    ("first guess correct", _cell(_with_rate, "first_guess_correct", "first_guess_correct_rate")),
    (
        "perseverative errors (per trial)",
        _cell(_with_rate, "perseverative_errors", "perseverative_error_rate"),
    ),
    ("win-shifts (per trial)", _cell(_with_rate, "win_shifts", "win_shift_rate")),
    ("initial entropy (bits)", _cell(lambda bits: number(bits, 3), "initial_entropy")),
    (
        "final entropy, before last guess",
        _cell(_spread(2), "final_entropy_mean", "final_entropy_sd"),
    ),
    (
        "final entropy, after last update",
        _cell(_spread(3), "final_entropy_after_mean", "final_entropy_after_sd"),
    ),
)


def study(stats: StudyStats, context: Mapping[str, Any], toys: int, targets: int) -> str:
    """A simulated study's statistics, beside the paper's pilot when the variant is the pilot."""
    pilot = context["variant"] == "pilot"
    simulated = msgspec.to_builtins(stats)
    published = PAPER_STATS if pilot else {}
    lines = [
        f"{context['groups']} groups x {targets} problems ({context['variant']}, {toys} toys), "
        f"seed {context['seed']}",
        f"learner: {context['profile']} (alpha {context['alpha']:g}, beta {context['beta']:g}, "
        f"gamma {context['gamma']:g}, {context['correct_answers_to_learn']} greens to learn); "
        f"teacher: {_children(context)}",
        f"guesses per game: {stats.trials_total / context['groups']:.2f}",
        "",
        f"{'':34} {'simulated':>16} {'paper' if pilot else '':>14}".rstrip(),
    ]
    for label, cell in STUDY_ROWS:
        lines.append(f"{label:34} {cell(simulated):>16} {cell(published):>14}".rstrip())
    lines.append("")
    lines.append("entropy before guess k (bits), problems with a k-th guess:")
    for k, (entropy, n) in enumerate(
        zip(stats.entropy_by_trial, stats.entropy_by_trial_n, strict=True), 1
    ):
        lines.append(f"  {k:>3}  {entropy:6.3f}  (n={n})")
    return "\n".join(lines)


def sweep(
    rows: Sequence[Mapping[str, Any]],
    context: Mapping[str, Any],
    problems: int,
    params: LearnerParams,
    teacher: Teacher,
) -> str:
    """One line per (alpha, beta) setting of a sweep."""
    lines = [
        f"pilot problems per setting: {problems} ({context['groups']} groups), "
        f"seed {context['seed']}, gamma {params.gamma:g}, teacher {teacher_text(teacher)}",
        f"{'alpha':>6} {'beta':>6} {'trials mean':>12} {'sd':>6} {'max':>4} {'given up':>9} "
        f"{'persev/trial':>13} {'win-shift/trial':>16}",
    ]
    for row in rows:
        lines.append(
            f"{row['alpha']:>6g} {row['beta']:>6g} {number(row['trials_mean'], 2):>12} "
            f"{number(row['trials_sd'], 2):>6} {number(row['trials_max'], 0):>4} "
            f"{row['problems_given_up']:>9} {number(row['perseverative_error_rate'], 4):>13} "
            f"{number(row['win_shift_rate'], 4):>16}"
        )
    return "\n".join(lines)


def power(
    title: str,
    points: Sequence[PowerPoint],
    studies: int,
    seed: int,
    game: GameSettings,
    measure: str,
) -> str:
    """Power against groups per arm, and the first design that reaches 80 %."""
    lines = [
        f"power: {title}",
        f"{studies} simulated studies per design, seed {seed}; {game.variant}, "
        f"{len(game.targets)} targets, {len(game.toys)} toys; measure: {measure}",
        f"{'groups per arm':>15} {'power':>7} {'MC error':>9} {'mean difference (A - B)':>24}",
    ]
    for point in points:
        lines.append(
            f"{point.groups:>15} {point.power:>7.3f} {point.mc_error:>9.3f} "
            f"{point.difference:>24.4f}"
        )
    enough = next((p.groups for p in points if p.power >= 0.8), None)
    lines.append(
        f"80 % power from {enough} groups per arm"
        if enough is not None
        else "80 % power not reached: try more groups (--groups-per-arm)"
    )
    return "\n".join(lines)


def fits(placed: Sequence[tuple[str, Fit]]) -> str:
    """Each fit's figures among its simulated studies: median, 95 % range, percentile, p."""
    lines = []
    for label, result in placed:
        lines.append(label)
        lines.append(
            f"  {result.studies:,} simulated studies of {result.groups_per_study} groups; "
            "percentile: share of simulated studies below the cohort (ties half); p two-sided"
        )
        lines.append(
            f"  {'figure':38} {'cohort':>8} {'model median':>13} {'95 % range':>17} "
            f"{'percentile':>11} {'p':>7}"
        )
        for figure in result.placed:
            spread = f"{figure.low:.2f}-{figure.high:.2f}"
            lines.append(
                f"  {FIGURES[figure.figure]:38} {figure.cohort:>8.2f} {figure.median:>13.2f} "
                f"{spread:>17} {figure.percentile:>10.1f}% {figure.p:>7.3f}"
            )
        if result.joint_trials_p is not None:
            lines.append(
                "  trials to learn, mean and sd together: "
                + _p(result.joint_trials_p, result.studies)
            )
        if result.entropy_with_win_shifts_p is not None:
            lines.append(
                "  final entropy at least the cohort's with at most its win-shifts: "
                + _p(result.entropy_with_win_shifts_p, result.studies)
            )
        lines.append("")
    return "\n".join(lines)


def _p(p: float, studies: int) -> str:
    """A Monte Carlo p-value, or how rare when no simulated study was as extreme."""
    if round(p * (studies + 1)) <= 1:
        return f"p < {1 / studies:.1g} (none of {studies:,} simulated studies)"
    return f"p = {p:.4f}"


def teacher_text(teacher: Teacher) -> str:
    """The children's rates in words ("honest" when they make no mistake)."""
    if teacher.honest:
        return "honest"
    return (
        f"wrong green {teacher.p_wrong_green:g}, wrong red {teacher.p_wrong_red:g}, "
        f"no answer {teacher.p_no_answer:g}"
    )


def _children(context: Mapping[str, Any]) -> str:
    if "teacher" in context:
        return f"model {context['teacher']} (its children's rates, in turn)"
    return teacher_text(
        Teacher(context["p_wrong_green"], context["p_wrong_red"], context["p_no_answer"])
    )
