"""The report's figures, PNG and SVG: the paper's Fig. 2 and Fig. 3, and two more.

matplotlib is the optional `report` extra: the robot never imports this
module's drawing code, so matplotlib is imported only when a report draws.
Figures are drawn on matplotlib's Agg canvas directly (no pyplot), so no
display and no global backend state are involved.

Conditions are drawn side by side: lines or grouped bars on one axes where
values share a scale, one panel per condition for the heat maps.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from kasparctl.game.phrases import Band
from kasparctl.research.conditions import Condition

INSTALL_HINT = "pip install 'kasparctl[report]'"
FORMATS = ("png", "svg")
PNG_DPI = 120
PANELS_PER_ROW = 4


class FiguresUnavailable(Exception):
    """matplotlib is not installed; the message says how to install it."""


def require_matplotlib() -> None:
    """Fail before any work when the figures cannot be drawn."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as error:
        raise FiguresUnavailable(
            f"the report's figures need matplotlib, which is not installed: {INSTALL_HINT}"
        ) from error


@dataclass
class Drawn:
    """The figures a report drew, by name, and those it left out."""

    names: list[str] = field(default_factory=list)
    # Figures left out and why ("no answer key"), for the summary.
    notes: list[str] = field(default_factory=list)


def draw_all(conditions: Sequence[Condition], bands: Sequence[Band], out: Path) -> Drawn:
    """Draw every figure the conditions allow into `out`, as PNG and SVG."""
    require_matplotlib()
    drawn = Drawn()
    figures: dict[str, Callable[[], tuple[Any, str]]] = {
        "entropy_by_trial": lambda: entropy_by_trial(conditions, bands),
        "final_q": lambda: final_q(conditions),
        "trials_to_learn": lambda: trials_to_learn(conditions),
        "feedback_by_child": lambda: feedback_by_child(conditions),
    }
    for name, draw in figures.items():
        figure, note = draw()
        if figure is None:
            drawn.notes.append(f"{name}: not drawn, {note}")
            continue
        _save(figure, out, name)
        drawn.names.append(name)
    return drawn


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _save(figure: Any, out: Path, name: str) -> None:
    import matplotlib

    # A fixed salt and no date: the same sessions give the same SVG, so reports diff cleanly.
    with matplotlib.rc_context({"svg.hashsalt": "kasparctl"}):
        figure.savefig(out / f"{name}.png", dpi=PNG_DPI, metadata={"Software": None})
        figure.savefig(out / f"{name}.svg", metadata={"Date": None})


def _colours(count: int) -> list[Any]:
    from matplotlib import colormaps

    palette = colormaps["tab10"]
    return [palette(index % 10) for index in range(count)]


def entropy_by_trial(conditions: Sequence[Condition], bands: Sequence[Band]) -> tuple[Any, str]:
    """Fig. 2: mean entropy before guess k of a problem, with the phrase bands shaded."""
    if not any(c.stats.entropy_by_trial for c in conditions):
        return None, "no trials"
    figure = _figure(7.5, 4.2)
    axes = figure.add_subplot()
    longest = max(len(c.stats.entropy_by_trial) for c in conditions)
    toys = max(len(p.toys) for c in conditions for p in c.problems)
    top = math.log2(toys) * 1.06
    shades = ("#e8f4e8", "#f4f4e0", "#f8ece0", "#f8e4e4")
    for index, band in enumerate(bands):
        if band.min >= top:
            continue
        axes.axhspan(band.min, min(band.max, top), color=shades[index % len(shades)], zorder=0)
        axes.text(
            longest + 0.6,
            (band.min + min(band.max, top)) / 2,
            band.name.replace("_", " "),
            va="center",
            fontsize=8,
            color="0.3",
        )
    axes.axhline(math.log2(toys), color="0.5", linestyle=":", linewidth=1)
    axes.text(
        longest + 0.6,
        math.log2(toys),
        f"no idea ({toys} toys)",
        va="bottom",
        fontsize=8,
        color="0.3",
    )
    for condition, colour in zip(conditions, _colours(len(conditions)), strict=True):
        means = condition.stats.entropy_by_trial
        axes.plot(
            range(1, len(means) + 1),
            means,
            marker="o",
            markersize=4,
            color=colour,
            label=f"{condition.label} ({condition.stats.problems} problems)",
        )
    axes.set_xlim(0.5, longest + 2.5)
    axes.set_ylim(0, top)
    axes.xaxis.get_major_locator().set_params(integer=True)
    axes.set_xlabel("guess within a problem")
    axes.set_ylabel("entropy before the guess (bits)")
    axes.set_title("Kaspar's uncertainty by trial, averaged over problems")
    # Below the axes: inside, the legend would hide the late trials' means.
    figure.legend(loc="outside lower center", ncols=min(len(conditions), 2), fontsize=8)
    return figure, ""


def final_q(conditions: Sequence[Condition]) -> tuple[Any, str]:
    """Fig. 3: the mean final Q row of learned problems, one row per correct toy."""
    panels = []
    for condition in conditions:
        by_answer: dict[str, list[dict[str, float]]] = {}
        for problem in condition.problems:
            answer = problem.answer
            if answer is None or problem.record.learned is None:
                continue
            row = dict(zip(problem.toys, problem.record.final_q, strict=True))
            by_answer.setdefault(answer, []).append(row)
        if by_answer:
            panels.append((condition, by_answer))
    if not panels:
        return None, "no learned problem with an answer key"
    toys: list[str] = []
    for condition, _ in panels:
        for problem in condition.problems:
            toys.extend(toy for toy in problem.toys if toy not in toys)
    matrices = []
    for _, by_answer in panels:
        matrix = np.full((len(toys), len(toys)), np.nan)
        for answer, rows in by_answer.items():
            for column, toy in enumerate(toys):
                values = [row[toy] for row in rows if toy in row]
                if values:
                    matrix[toys.index(answer), column] = float(np.mean(values))
        matrices.append(matrix)
    limit = max(float(np.nanmax(np.abs(m))) for m in matrices) or 1.0
    # At most four panels a row, so eight conditions stay readable on a page.
    columns = min(len(panels), PANELS_PER_ROW)
    panel_rows = math.ceil(len(panels) / columns)
    figure = _figure(1.0 + 4.2 * columns, 0.4 + 4.0 * panel_rows)
    grid = figure.subplots(panel_rows, columns, squeeze=False).ravel()
    for unused in grid[len(panels) :]:
        unused.set_axis_off()
    image = None
    annotate = len(toys) <= 8
    for axes, (condition, by_answer), matrix in zip(grid, panels, matrices, strict=False):
        image = axes.imshow(matrix, cmap="RdBu_r", vmin=-limit, vmax=limit)
        axes.set_xticks(range(len(toys)), toys, rotation=45, ha="right", fontsize=8)
        axes.set_yticks(range(len(toys)), toys, fontsize=8)
        axes.set_xlabel("toy")
        axes.set_ylabel("correct toy")
        problems = sum(len(rows) for rows in by_answer.values())
        axes.set_title(f"{condition.label}\n({problems} learned problems)", fontsize=9)
        if annotate:
            for (row, column), value in np.ndenumerate(matrix):
                if not np.isnan(value):
                    ink = "white" if abs(value) > 0.6 * limit else "black"
                    axes.text(
                        column, row, f"{value:.2f}", ha="center", va="center", fontsize=6, color=ink
                    )
    figure.colorbar(image, ax=list(grid), label="mean final Q-value", shrink=0.8)
    figure.suptitle("Final Q-values by correct toy")
    return figure, ""


def trials_to_learn(conditions: Sequence[Condition]) -> tuple[Any, str]:
    """Histogram of the trials each learned problem took, conditions as grouped bars."""
    counts = [
        [len(p.record.trials) for p in c.problems if p.record.learned is not None]
        for c in conditions
    ]
    if not any(counts):
        return None, "no problem was learned"
    low = min(min(c) for c in counts if c)
    high = max(max(c) for c in counts if c)
    bins = np.arange(low, high + 1)
    figure = _figure(7.0, 4.0)
    axes = figure.add_subplot()
    width = 0.8 / len(conditions)
    colours = _colours(len(conditions))
    for index, (condition, values) in enumerate(zip(conditions, counts, strict=True)):
        heights = [values.count(int(b)) for b in bins]
        offset = (index - (len(conditions) - 1) / 2) * width
        axes.bar(
            bins + offset,
            heights,
            width=width,
            color=colours[index],
            label=f"{condition.label} ({len(values)} learned)",
        )
    axes.set_xticks(bins)
    axes.yaxis.get_major_locator().set_params(integer=True)
    axes.set_xlabel("trials to learn (confirming greens included)")
    axes.set_ylabel("problems")
    axes.set_title("Trials to learn")
    axes.legend(fontsize=8)
    return figure, ""


def feedback_by_child(conditions: Sequence[Condition]) -> tuple[Any, str]:
    """Share of each child's answers that agreed with the answer key, per condition."""
    tallies: list[dict[int, tuple[int, int]]] = []
    for condition in conditions:
        counting: dict[int, list[int]] = {}
        for trial in condition.trials:
            if trial.feedback_right is None:
                continue
            entry = counting.setdefault(trial.child_index + 1, [0, 0])
            entry[0] += trial.feedback_right
            entry[1] += 1
        tallies.append({child: (right, total) for child, (right, total) in counting.items()})
    if not any(tallies):
        return None, "no session has an answer key"
    children = sorted({child for tally in tallies for child in tally})
    figure = _figure(7.0, 4.0)
    axes = figure.add_subplot()
    width = 0.8 / len(conditions)
    colours = _colours(len(conditions))
    for index, (condition, tally) in enumerate(zip(conditions, tallies, strict=True)):
        if not tally:
            continue
        offset = (index - (len(conditions) - 1) / 2) * width
        xs = [child + offset for child in children if child in tally]
        shares = [100 * tally[c][0] / tally[c][1] for c in children if c in tally]
        bars = axes.bar(xs, shares, width=width, color=colours[index], label=condition.label)
        axes.bar_label(
            bars, labels=[f"n={tally[c][1]}" for c in children if c in tally], fontsize=7
        )
    axes.set_xticks(children, [f"child {c}" for c in children])
    axes.set_ylim(0, 125)
    axes.set_ylabel("feedback agreeing with the answer key (%)")
    axes.set_title("Feedback accuracy per child's turn")
    axes.legend(fontsize=8, loc="upper center", ncols=min(len(conditions), 3))
    return figure, ""
