"""Fig. 3: the mean final Q row of learned problems, one row per correct toy, by condition.

One heat map a condition on one colour scale (ColorBrewer's RdBu, readable with the
common colour vision deficiencies, and the values written in the cells when a cell
is big enough for 5-point text), up to PANELS_PER_PAGE a page. Each row's n (learned
problems with that correct toy) is beside it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from kasparctl.research.conditions import Condition
from kasparctl.research.figure_style import (
    PAGE_WIDTH,
    chunks,
    grid_shape,
    new_figure,
    short,
)

PANELS_PER_PAGE = 12
COLUMNS = 3
CELL_FONT = 5.0
# The smallest cell, in points, that its value (e.g. "-0.53" at CELL_FONT) fits in.
MIN_CELL_POINTS = 5 * 0.62 * CELL_FONT + 2

Panel = tuple[Condition, dict[str, list[dict[str, float]]]]


def final_q(conditions: Sequence[Condition]) -> tuple[list[Any] | None, str]:
    """The pages of Fig. 3 (None and why when no learned problem has an answer key)."""
    panels: list[Panel] = []
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
    matrices = [_matrix(by_answer, toys) for _, by_answer in panels]
    limit = max(float(np.nanmax(np.abs(m))) for m in matrices) or 1.0
    pages = chunks(list(zip(panels, matrices, strict=True)), PANELS_PER_PAGE)
    return [
        _page(page, toys, limit, number, len(pages)) for number, page in enumerate(pages, 1)
    ], ""


def _matrix(by_answer: dict[str, list[dict[str, float]]], toys: list[str]) -> Any:
    matrix = np.full((len(toys), len(toys)), np.nan)
    for answer, rows in by_answer.items():
        for column, toy in enumerate(toys):
            values = [row[toy] for row in rows if toy in row]
            if values:
                matrix[toys.index(answer), column] = float(np.mean(values))
    return matrix


def _page(
    page: list[tuple[Panel, Any]], toys: list[str], limit: float, number: int, count: int
) -> Any:
    rows, columns = grid_shape(len(page), COLUMNS)
    width = min(PAGE_WIDTH, 1.6 + 2.3 * columns)
    figure = new_figure(width, 1.0 + 2.25 * rows)
    grid = figure.subplots(rows, columns, squeeze=False)
    flat = grid.ravel()
    for unused in flat[len(page) :]:
        unused.set_axis_off()
    cell_points = (width - 1.4) / columns / (len(toys) + 1.5) * 72
    annotate = cell_points >= MIN_CELL_POINTS
    image = None
    for place, ((condition, by_answer), matrix) in enumerate(page):
        axes = flat[place]
        column = place % columns
        image = axes.imshow(matrix, cmap="RdBu_r", vmin=-limit, vmax=limit)
        bottom = place + columns >= len(page)
        axes.set_xticks(
            range(len(toys)),
            toys if bottom else [],
            rotation=90,
        )
        axes.set_yticks(range(len(toys)), toys if column == 0 else [])
        counts = axes.secondary_yaxis("right")
        counts.set_yticks(range(len(toys)), [f"n={len(by_answer.get(t, []))}" for t in toys])
        counts.tick_params(length=0, pad=1)
        if bottom:
            axes.set_xlabel("toy")
        if column == 0:
            axes.set_ylabel("correct toy (learned problems)")
        learned = sum(len(rows) for rows in by_answer.values())
        axes.set_title(f"{short(condition.label, 30)}\n{learned} learned problems")
        if annotate:
            for (r, c), value in np.ndenumerate(matrix):
                if not math.isnan(value):
                    ink = "white" if abs(value) > 0.6 * limit else "black"
                    axes.text(
                        c,
                        r,
                        f"{value:.2f}",
                        ha="center",
                        va="center",
                        fontsize=CELL_FONT,
                        color=ink,
                    )
    colourbar = figure.colorbar(image, ax=list(flat), shrink=0.6, aspect=30)
    colourbar.set_label("mean final Q-value")
    suffix = f" (page {number} of {count})" if count > 1 else ""
    figure.suptitle("Final Q-values by correct toy" + suffix)
    return figure
