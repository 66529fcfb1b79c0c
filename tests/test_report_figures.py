"""Every figure of the report, drawn on several studies: no label cut off, n and intervals shown.

`clipped_texts` finds every text a drawn figure shows whose box reaches outside
the figure (or outside the axes that clip it); a test per figure fails on any.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from research_cohort import make_cohort
from research_fixtures import make_study

from kasparctl.game.phrases import load_phrasebook
from kasparctl.learning.learner import LearnerParams
from kasparctl.learning.study_stats import ProblemRecord, TrialRecord
from kasparctl.research.catalogue import find_sessions, open_sessions
from kasparctl.research.children import Children, Feedback
from kasparctl.research.conditions import Condition, Factors, Problem, by_condition
from kasparctl.research.figures import (
    FigureData,
    clipped_texts,
    drawn_texts,
    figure_table,
)
from kasparctl.research.inference import attribute_contrasts, condition_contrasts, intervals
from kasparctl.research.participants import NO_PARTICIPANTS, load_participants

FIGURES = ("entropy_by_trial", "final_q", "trials_to_learn", "feedback_by_child", "contrasts")
BANDS = load_phrasebook("en", None).bands


def figure_data(state_dir: Path, participants_file: Path | None = None) -> FigureData:
    catalogue = open_sessions(find_sessions([state_dir], []))
    participants = load_participants(participants_file) if participants_file else NO_PARTICIPANTS
    children = Children()
    conditions = by_condition(catalogue.sessions, lambda _: LearnerParams(), children)
    found = {c.label: intervals(c, 300, 0) for c in conditions}
    contrasts = condition_contrasts(conditions, "group", 300, 0)
    contrasts += attribute_contrasts(list(children.by_key.values()), participants, 300, 0)
    return FigureData(conditions, found, BANDS, list(children.by_key.values()), participants, contrasts)


def synthetic(conditions: int, label_length: int, children: int = 0) -> FigureData:
    """Conditions with long labels, many guesses and a child per place: the crowded case."""
    rng = np.random.default_rng(1)
    made = []
    toys = tuple(f"toy number {i}" for i in range(6))
    for index in range(conditions):
        label = f"profile-{index}-" + "x" * label_length + ("/spoken" if index % 2 else "/silent")
        condition = Condition(label, Factors(f"p{index}", "spoken" if index % 2 else "none", "names"))
        for cluster in range(5):
            for target in range(6):
                length = int(rng.integers(2, 25))
                trials = tuple(
                    TrialRecord(int(rng.integers(6)), bool(rng.integers(2)), float(rng.uniform(0, 2.58)), bool(rng.integers(2)))
                    for _ in range(length)
                )
                record = ProblemRecord(cluster, target, target, trials, target, tuple(rng.uniform(-1, 1, 6)), 0.1, 6 - target)
                condition.problems.append(Problem(toys, record, f"group {cluster}"))
            condition.feedback_by_cluster[f"group {cluster}"] = Feedback(answers=40, checked=40, right=35, wrong_guesses=20, right_guesses=20, wrong_green=3, wrong_red=2)
        for place in range(1, 4):
            condition.feedback_by_position[place] = Feedback(answers=30, checked=30, right=30 - place)
        made.append(condition)
    found = {c.label: intervals(c, 200, 0) for c in made}
    return FigureData(made, found, BANDS, contrasts=condition_contrasts(made, "group", 200, 0))


@pytest.fixture(scope="module")
def studies(tmp_path_factory: pytest.TempPathFactory) -> dict[str, FigureData]:
    cohort = make_cohort(tmp_path_factory.mktemp("cohort"))
    study = make_study(tmp_path_factory.mktemp("study"))
    return {
        "cohort with participants": figure_data(cohort.state_dir, cohort.participants),
        "cohort without participants.csv": figure_data(cohort.state_dir),
        "six sessions, five conditions": figure_data(study.state_dir),
        "eight conditions, long labels": synthetic(8, 40),
        "one condition": synthetic(1, 0),
    }


def draw(data: FigureData, name: str) -> Any:
    figure, note = figure_table(data)[name]()
    return figure, note


@pytest.mark.parametrize("name", FIGURES)
def test_no_label_of_the_figure_is_cut_off(studies: dict[str, FigureData], name: str) -> None:
    drawn = 0
    for study, data in studies.items():
        figure, _ = draw(data, name)
        if figure is None:
            continue
        drawn += 1
        assert clipped_texts(figure) == [], (name, study)
    assert drawn >= 2, name


@pytest.mark.filterwarnings("ignore:constrained_layout not applied")
def test_the_checker_finds_a_label_cut_off() -> None:
    """The check itself fails on what the old Fig. 3 did: a label past the figure's edge."""
    from kasparctl.research.figures import _figure

    figure = _figure(4, 3)
    axes = figure.add_subplot()
    axes.plot([1, 2], [1, 2])
    axes.set_xlabel("fine")
    axes.text(1.9, 1.5, "a label that runs far past the right edge of the figure", fontsize=12)
    assert any("runs far past" in text for text in clipped_texts(figure))
    figure = _figure(4, 3)
    axes = figure.add_subplot()
    axes.text(0.5, 2.5, "outside its axes", clip_on=True)
    axes.set_ylim(0, 1)
    assert any("outside its axes" in text for text in clipped_texts(figure))


def texts_of(figure: Any) -> list[str]:
    return [text.get_text() for text in drawn_texts(figure)]


def test_fig2_shows_every_points_n_and_its_interval(studies: dict[str, FigureData]) -> None:
    data = studies["cohort with participants"]
    figure, _ = draw(data, "entropy_by_trial")
    shown = texts_of(figure)
    for condition in data.conditions:
        for n in condition.stats.entropy_by_trial_n:
            assert str(n) in shown
    main_axes = figure.axes[0]
    # One shaded interval per condition.
    assert len(main_axes.collections) == len(data.conditions)
    # "No idea" for every number of toys offered, not only the first problem's six.
    assert "no idea, 6 toys" in shown


def test_fig2_in_the_names_game_marks_no_idea_for_each_number_of_toys(
    studies: dict[str, FigureData],
) -> None:
    figure, _ = draw(studies["six sessions, five conditions"], "entropy_by_trial")
    shown = texts_of(figure)
    assert {f"no idea, {n} toys" for n in (6, 5, 4, 3, 2)} <= set(shown)


def test_the_per_child_figure_is_by_participant_never_past_100_percent(
    studies: dict[str, FigureData],
) -> None:
    data = studies["cohort with participants"]
    figure, _ = draw(data, "feedback_by_child")
    axes = figure.axes[0]
    assert axes.get_ylim()[1] <= 100
    labels = [t.get_text() for t in axes.get_xticklabels()]
    assert [label.split("\n")[0] for label in labels] == [f"P{i:02d}" for i in range(1, 13)]
    assert all(re.match(r"n=\d+", label.split("\n")[1]) for label in labels)
    # Coloured by the participants' first category: a legend titled by it.
    assert axes.get_legend().get_title().get_text() == "group"


def test_without_codes_the_per_child_figure_is_by_place_with_n(
    studies: dict[str, FigureData],
) -> None:
    figure, _ = draw(studies["six sessions, five conditions"], "feedback_by_child")
    axes = figure.axes[0]
    assert axes.get_ylim()[1] <= 100
    assert "not the same children" in axes.get_xlabel()
    assert any(text.startswith("n=") for text in texts_of(figure))


def test_histogram_bars_carry_their_counts(studies: dict[str, FigureData]) -> None:
    data = studies["cohort with participants"]
    figure, _ = draw(data, "trials_to_learn")
    shown = texts_of(figure)
    for condition in data.conditions:
        lengths = [len(p.record.trials) for p in condition.problems if p.record.learned is not None]
        for length in set(lengths):
            assert str(lengths.count(length)) in shown


def test_the_power_figure_is_not_cut_off() -> None:
    from kasparctl.sim.power import PowerPoint, draw_power

    points = [PowerPoint(n, min(1.0, n / 20), 0.01, -1.0) for n in (4, 8, 16, 32, 64)]
    figure = draw_power(points, "profile paper vs profile slow: trials_mean (Welch t-test on groups, level 0.05)", 1000)
    assert clipped_texts(figure) == []

