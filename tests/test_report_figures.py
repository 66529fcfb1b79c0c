"""Every figure of the report, drawn on several studies and at scale.

Each figure is drawn once (`render`) and its texts' boxes on that draw are checked:
none reaches outside the figure (or the axes clipping it), none lies over another.
And: PNG at 300 dpi, PDF with TrueType (Type 42) fonts, SVG with text as text; every
page within 7.5 x 9.5 inches however many conditions, children and contrasts; the
series in Okabe-Ito colours, each with its marker and line style; small multiples
past a handful of conditions; n and intervals on the points; nothing joined below
the minimum n; uncoded children shown as "uncoded", never "None".
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
from kasparctl.research.children import ChildMeasures, Children, Feedback
from kasparctl.research.conditions import Condition, Factors, Problem, by_condition
from kasparctl.research.figure_style import MARKERS, MIN_N, OKABE_ITO, PAGE_HEIGHT, PAGE_WIDTH
from kasparctl.research.figures import (
    FORMATS,
    SVG,
    FigureData,
    clipped_texts,
    draw_all,
    drawn_texts,
    figure_table,
    overlapping_texts,
    render,
)
from kasparctl.research.inference import (
    Contrast,
    Estimate,
    attribute_contrasts,
    condition_contrasts,
    intervals,
)
from kasparctl.research.participants import NO_PARTICIPANTS, Participants, load_participants

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


def synthetic(
    conditions: int, label_length: int, clusters: int = 5, replicates: int = 200
) -> FigureData:
    """Conditions with long labels, many guesses and a child per place: the crowded case."""
    rng = np.random.default_rng(1)
    made = []
    toys = tuple(f"toy number {i}" for i in range(6))
    for index in range(conditions):
        label = f"profile-{index}-" + "x" * label_length + ("/spoken" if index % 2 else "/silent")
        mode = ("spoken", "body", "both", "none")[index % 4]
        condition = Condition(label, Factors(f"p{index // 4}", mode, "names"))
        for cluster in range(clusters):
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
    found = {c.label: intervals(c, replicates, 0) for c in made}
    return FigureData(made, found, BANDS, contrasts=condition_contrasts(made, "group", replicates, 0))


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


def pages(data: FigureData, name: str) -> list[Any]:
    figures, _ = figure_table(data)[name]()
    return [] if figures is None else figures


def first(data: FigureData, name: str) -> Any:
    (figure, *_) = pages(data, name)
    return figure


@pytest.mark.parametrize("name", FIGURES)
def test_no_label_is_cut_off_or_over_another(studies: dict[str, FigureData], name: str) -> None:
    drawn = 0
    for study, data in studies.items():
        for figure in pages(data, name):
            drawn += 1
            rendered = render(figure)
            assert rendered.clipped() == [], (name, study)
            assert rendered.overlapping() == [], (name, study)
    assert drawn >= 2, name


@pytest.mark.filterwarnings("ignore:constrained_layout not applied")
def test_the_checker_finds_a_label_cut_off() -> None:
    """The check itself fails on what the old Fig. 3 did: a label past the figure's edge."""
    from kasparctl.research.figure_style import new_figure

    figure = new_figure(4, 3)
    axes = figure.add_subplot()
    axes.plot([1, 2], [1, 2])
    axes.set_xlabel("fine")
    axes.text(1.9, 1.5, "a label that runs far past the right edge of the figure", fontsize=12)
    assert any("runs far past" in text for text in clipped_texts(figure))
    figure = new_figure(4, 3)
    axes = figure.add_subplot()
    axes.text(0.5, 2.5, "outside its axes", clip_on=True)
    axes.set_ylim(0, 1)
    assert any("outside its axes" in text for text in clipped_texts(figure))


def test_the_checker_finds_labels_over_each_other() -> None:
    from kasparctl.research.figure_style import new_figure

    figure = new_figure(4, 3)
    axes = figure.add_subplot()
    axes.text(0.5, 0.5, "twenty-four")
    axes.text(0.52, 0.5, "seventeen")
    axes.text(0.5, 0.1, "alone")
    found = overlapping_texts(figure)
    assert found == ["'twenty-four' over 'seventeen'"]


def texts_of(figure: Any) -> list[str]:
    return [text.get_text() for text in drawn_texts(figure)]


def series_lines(axes: Any) -> list[Any]:
    """The lines that draw data (not the "no idea" levels nor the bands)."""
    return [line for line in axes.get_lines() if len(line.get_xdata()) > 0 and line.get_marker() not in ("None", "", None)]


def test_fig2_shows_every_points_n_and_its_interval(studies: dict[str, FigureData]) -> None:
    data = studies["cohort with participants"]
    figure = first(data, "entropy_by_trial")
    shown = texts_of(figure)
    main_axes, strip = figure.axes[0], figure.axes[1]
    strip_texts = [t.get_text() for t in strip.texts]
    for condition in data.conditions:
        for n in condition.stats.entropy_by_trial_n:
            assert str(n) in strip_texts
    # One whisker set per condition with intervals: a LineCollection of vertical bars.
    from matplotlib.collections import LineCollection

    whiskers = [c for c in main_axes.collections if isinstance(c, LineCollection)]
    with_intervals = [
        c for c in data.conditions if any(e.low is not None for e in data.intervals[c.label].entropy_by_trial)
    ]
    assert len(whiskers) == len(with_intervals) > 0
    assert f"n < {MIN_N} problems: hollow, not joined" in shown


def test_fig2_joins_no_point_below_the_minimum_n(studies: dict[str, FigureData]) -> None:
    data = studies["six sessions, five conditions"]
    figure = first(data, "entropy_by_trial")
    # Five conditions: small multiples, so every panel's lines (the strips' markers are
    # filled single points, never a hollow one nor a line of a condition's length).
    lines = [line for axes in figure.axes for line in series_lines(axes)]
    checked = 0
    for condition in data.conditions:
        ns = np.array(condition.stats.entropy_by_trial_n)
        means = np.array(condition.stats.entropy_by_trial)
        for line in lines:
            y = np.asarray(line.get_ydata(), dtype=float)
            if line.get_linestyle() != "None" and len(y) == len(ns) and np.allclose(
                np.nan_to_num(y, nan=-1), np.where(ns >= MIN_N, means, -1)
            ):
                # Below MIN_N the line has gaps (NaN): never a segment through those means.
                assert np.isnan(y[ns < MIN_N]).all()
                checked += 1
    assert checked == len(data.conditions)
    few = sum(int((np.array(c.stats.entropy_by_trial_n) < MIN_N).sum()) for c in data.conditions)
    hollow = [
        line for line in lines if line.get_linestyle() == "None" and line.get_markerfacecolor() == "white"
    ]
    assert sum(len(line.get_xdata()) for line in hollow) == few > 0


def test_series_differ_by_colour_marker_and_line_style(studies: dict[str, FigureData]) -> None:
    """Never hue alone: Okabe-Ito colours, and each series its own marker and line style."""
    from matplotlib.colors import to_hex

    palette = {c.lower() for c in OKABE_ITO}
    for name in ("entropy_by_trial", "trials_to_learn"):
        figure = first(studies["six sessions, five conditions"], name)
        for axes in figure.axes:
            joined = [line for line in series_lines(axes) if line.get_linestyle() != "None"]
            if len(joined) < 2:
                continue
            assert {to_hex(line.get_color()) for line in joined} <= palette, name
            assert all(line.get_marker() in MARKERS for line in joined), name
            assert len({line.get_marker() for line in joined}) == len(joined), name
            assert len({line.get_linestyle() for line in joined}) == len(joined), name


def test_past_a_handful_of_conditions_small_multiples(studies: dict[str, FigureData]) -> None:
    data = studies["eight conditions, long labels"]
    for name in ("entropy_by_trial", "trials_to_learn"):
        figure = first(data, name)
        panels = [a for a in figure.axes if series_lines(a) and a.get_ylabel() != "n"]
        assert len(panels) >= 2, name
        for axes in panels:
            joined = [line for line in series_lines(axes) if line.get_linestyle() != "None"]
            assert len(joined) <= 4, name
        # One legend for all panels: the uncertainty modes, each once.
        legend = figure.legends[0]
        labels = [t.get_text() for t in legend.get_texts()]
        assert {"spoken", "body", "both", "none"} <= set(labels), name


def test_fig2_in_the_names_game_draws_no_idea_for_each_number_of_toys(
    studies: dict[str, FigureData],
) -> None:
    figure = first(studies["six sessions, five conditions"], "entropy_by_trial")
    levels = {
        round(float(line.get_ydata()[0]), 6)
        for line in figure.axes[0].get_lines()
        if line.get_linestyle() == ":"
    }
    assert levels == {round(float(np.log2(n)), 6) for n in (6, 5, 4, 3, 2)}


def test_the_per_child_figure_is_by_participant_never_past_100_percent(
    studies: dict[str, FigureData],
) -> None:
    data = studies["cohort with participants"]
    figure = first(data, "feedback_by_child")
    axes = figure.axes[0]
    assert axes.get_xlim()[1] <= 100
    labels = [t.get_text() for t in axes.get_yticklabels()]
    assert sorted(labels) == [f"P{i:02d}" for i in range(1, 13)]
    counts = [t.get_text() for t in axes.child_axes[0].get_yticklabels()]
    assert len(counts) == 12 and all(re.fullmatch(r"n=\d+", c) for c in counts)
    # Marked by the participants' first category: a legend titled by it.
    assert figure.legends[0].get_title().get_text() == "group"


def coded_children(count: int, uncoded: int) -> tuple[list[ChildMeasures], Participants]:
    children = []
    rows: dict[str, dict[str, str | float | None]] = {}
    for index in range(count):
        code = f"C{index:04d}"
        child = ChildMeasures(code, code, code)
        child.feedback = Feedback(answers=20, checked=20, right=10 + index % 10)
        children.append(child)
        # Every seventh child has no diagnosis recorded.
        rows[code] = {"group": None if index % 7 == 0 else ("ASC", "TD")[index % 2]}
    for index in range(uncoded):
        child = ChildMeasures(f"S{index} #1", f"20260302T0941-G9 #{index + 1}", None)
        child.feedback = Feedback(answers=20, checked=20, right=15)
        children.append(child)
    return children, Participants(None, ("group",), {"group": "category"}, rows)


@pytest.mark.parametrize("count", [10, 2000])
def test_uncoded_children_are_shown_as_uncoded_never_none_nor_left_out(count: int) -> None:
    children, participants = coded_children(count, uncoded=3)
    data = FigureData([], {}, BANDS, children, participants)
    figure = first(data, "feedback_by_child")
    shown = texts_of(figure)
    assert not any("None" in text for text in shown)
    legend = [t.get_text() for t in figure.legends[0].get_texts()]
    assert [label.split(" ")[0] for label in legend] == ["ASC", "TD", "uncoded"]
    if count < 100:
        # One row per child, the three of the group planned without codes among them.
        rows = [t.get_text() for t in figure.axes[0].get_yticklabels()]
        assert len(rows) == count + 3
        assert sum(label.startswith("20260302T0941-G9") for label in rows) == 3
    else:
        # Aggregated, and the uncoded level counts both kinds: 286 without a diagnosis
        # and the 3 children without a code.
        assert any(label.startswith(f"uncoded (n={len(range(0, count, 7)) + 3} children") for label in legend)


def test_without_codes_the_per_child_figure_is_by_place_with_n(
    studies: dict[str, FigureData],
) -> None:
    figure = first(studies["six sessions, five conditions"], "feedback_by_child")
    axes = figure.axes[0]
    assert axes.get_xlim()[1] <= 100
    assert "not the same children" in axes.get_xlabel()
    counts = axes.child_axes[0].get_yticklabels()
    assert counts and all(t.get_text().startswith("n=") for t in counts)


def test_trials_to_learn_shows_each_points_count(studies: dict[str, FigureData]) -> None:
    data = studies["cohort with participants"]
    figure = first(data, "trials_to_learn")
    strip = [t.get_text() for t in figure.axes[1].texts]
    for condition in data.conditions:
        lengths = [len(p.record.trials) for p in condition.problems if p.record.learned is not None]
        for length in set(lengths):
            assert str(lengths.count(length)) in strip


def test_a_contrast_without_an_interval_does_not_look_precise() -> None:
    found = [contrast(i, interval=i % 2 == 0) for i in range(6)]
    figure = first(FigureData([], {}, BANDS, contrasts=found), "contrasts")
    axes = figure.axes[0]
    # One set of points a look and one collection of whiskers (not an artist a row).
    from matplotlib.collections import LineCollection

    hollow = sum(len(line.get_xdata()) for line in axes.get_lines() if line.get_markerfacecolor() == "white")
    whiskers = [
        segment
        for collection in axes.collections
        if isinstance(collection, LineCollection)
        for segment in collection.get_segments()
    ]
    assert hollow == 3 and len(whiskers) == 3
    assert all(len(segment) == 2 and segment[0][1] == segment[1][1] for segment in whiskers)
    assert any("no interval" in t for t in texts_of(figure))


def contrast(index: int, interval: bool = True, measure: str = "trials_mean") -> Contrast:
    g = Estimate(0.1 * index - 0.3, 0.1 * index - 0.9 if interval else None, 0.1 * index + 0.3 if interval else None, 10)
    return Contrast(
        "uncertainty", f"p{index}/spoken (names)", f"p{index}/none (names)", measure, 1.0, 1.2,
        g, g, "group", 10 if interval else 3, 10 if interval else 3, p_adjusted=0.01 if index % 3 else 0.5,
    )


@pytest.fixture(scope="module")
def at_scale() -> FigureData:
    """The size of 720 sessions: 24 conditions of 30 groups, 2,000 children, 370 contrasts."""
    data = synthetic(24, 12, clusters=30, replicates=100)
    children, participants = coded_children(2000, uncoded=60)
    measures = ("trials_mean", "first_guess_correct_rate", "perseverative_error_rate", "win_shift_rate", "final_entropy_mean", "wrong_feedback_rate")
    found = [contrast(i, i % 5 != 0, measures[i % 6]) for i in range(370)]
    return FigureData(data.conditions, data.intervals, BANDS, children, participants, found)


@pytest.mark.parametrize("name", FIGURES)
def test_every_page_stays_within_a_page_at_720_sessions(at_scale: FigureData, name: str) -> None:
    figures = pages(at_scale, name)
    assert 1 <= len(figures) <= 4, name
    for figure in figures:
        width, height = figure.get_size_inches()
        assert width <= PAGE_WIDTH and height <= PAGE_HEIGHT, name
    # The first page readable: no label cut off or over another at that size either.
    rendered = render(figures[0])
    assert rendered.clipped() == [] and rendered.overlapping() == [], name


def test_the_files_are_a_300_dpi_png_a_pdf_with_real_text_and_an_svg(
    studies: dict[str, FigureData], tmp_path: Path
) -> None:
    from PIL import Image

    data = studies["cohort with participants"]
    drawn = draw_all(data, tmp_path, (*FORMATS, SVG))
    assert drawn.names == list(FIGURES) and drawn.failed == []
    assert drawn.notes == []
    for name in FIGURES:
        with Image.open(tmp_path / f"{name}.png") as image:
            assert image.info["dpi"] == pytest.approx((300, 300), abs=0.01)
            width, height = image.size
        assert width <= PAGE_WIDTH * 300 and height <= PAGE_HEIGHT * 300
        assert width >= 1200, name  # drawn at 300 dpi, not scaled up from less
        pdf = (tmp_path / f"{name}.pdf").read_bytes()
        assert pdf.startswith(b"%PDF")
        # TrueType fonts embedded (pdf.fonttype 42), no Type 3 glyph drawings.
        assert b"/FontFile2" in pdf and b"/Type3" not in pdf, name
        svg = (tmp_path / f"{name}.svg").read_text()
        assert "<text" in svg and "<defs>\n  <path id=\"DejaVuSans" not in svg, name


def test_figures_drawn_in_parallel_are_those_drawn_one_after_another(
    studies: dict[str, FigureData], tmp_path: Path
) -> None:
    data = studies["cohort with participants"]
    serial, parallel = tmp_path / "serial", tmp_path / "parallel"
    serial.mkdir()
    parallel.mkdir()
    one = draw_all(data, serial, workers=1)
    two = draw_all(data, parallel, workers=2)
    assert two == one and one.names == list(FIGURES)
    files = sorted(p.name for p in serial.iterdir())
    assert sorted(p.name for p in parallel.iterdir()) == files
    assert files == sorted(f"{name}.{kind}" for name in FIGURES for kind in FORMATS)
    # The same bytes: each worker draws its figure under the same settings as serially.
    for name in files:
        assert (parallel / name).read_bytes() == (serial / name).read_bytes(), name


def test_the_power_figure_is_not_cut_off() -> None:
    from kasparctl.sim.power import PowerPoint, draw_power

    points = [PowerPoint(n, min(1.0, n / 20), 0.01, -1.0) for n in (4, 8, 16, 32, 64)]
    figure = draw_power(points, "profile paper vs profile slow: trials_mean (Welch t-test on groups, level 0.05)", 1000)
    assert clipped_texts(figure) == []
