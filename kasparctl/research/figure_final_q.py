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
from kasparctl.research.figure_layout import (
    EDGE,
    PAD,
    TICK,
    lines,
    points,
    spacing,
    title_above,
    widest,
)
from kasparctl.research.figure_style import (
    FONT_SIZE,
    PAGE_WIDTH,
    SMALL,
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
# Each row's n this many points right of its panel; the colour bar's gap and width (in).
N_GAP = 2.0
BAR_GAP = 0.15
BAR_WIDTH = 0.12
# matplotlib's gap under an axes' title (axes.titlepad), points.
TITLE_PAD = 6.0

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
    figure = new_figure(width, 1.0 + 2.25 * rows, layout=None)
    counts = [[f"n={len(by_answer.get(t, []))}" for t in toys] for (_, by_answer), _ in page]
    # The fixed layout (figure_layout): toy names left and below, each panel's n on its
    # right, two-line titles above, the colour bar at the right edge.
    names = widest(figure, toys, SMALL)
    n_width = widest(figure, [n for column in counts for n in column], SMALL) + points(N_GAP)
    bar_labels = widest(figure, [f"{-limit:.2f}", f"{limit:.2f}"], SMALL)
    left = points(EDGE) + lines(1, FONT_SIZE) + points(PAD + TICK) + names
    right = n_width + BAR_GAP + BAR_WIDTH + points(TICK + PAD) + bar_labels
    right += lines(1, FONT_SIZE) + points(EDGE)
    titles = lines(2, FONT_SIZE + 1) + points(TITLE_PAD)
    suffix = f" (page {number} of {count})" if count > 1 else ""
    top = title_above(figure, "Final Q-values by correct toy" + suffix, FONT_SIZE + 2) + titles
    bottom = points(EDGE) + lines(1, FONT_SIZE) + points(PAD + TICK) + names
    grid = figure.add_gridspec(
        rows, columns,
        **spacing(
            figure, rows, columns, left=left, right=right, top=top, bottom=bottom,
            across=n_width + points(PAD + TICK), down=titles + points(PAD + TICK),
        ),
    )  # fmt: skip
    flat = grid.subplots(squeeze=False).ravel()
    for unused in flat[len(page) :]:
        unused.set_axis_off()
    cell_points = (width - 1.4) / columns / (len(toys) + 1.5) * 72
    annotate = cell_points >= MIN_CELL_POINTS
    image = None
    for place_, ((condition, by_answer), matrix) in enumerate(page):
        axes = flat[place_]
        column = place_ % columns
        image = axes.imshow(matrix, cmap="RdBu_r", vmin=-limit, vmax=limit)
        bottom_row = place_ + columns >= len(page)
        axes.set_xticks(range(len(toys)), toys if bottom_row else [], rotation=90)
        axes.set_yticks(range(len(toys)), toys if column == 0 else [])
        # Each row's n beside it: texts, not a second axis (its ticks cost a draw each).
        beside = axes.get_yaxis_transform() + _nudge(figure)
        for row, n in enumerate(counts[place_]):
            axes.text(1.0, row, n, transform=beside, fontsize=SMALL, va="center", ha="left")
        if bottom_row:
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
    page_width, page_height = figure.get_size_inches()
    grid_top, grid_bottom = 1 - top / page_height, bottom / page_height
    tall = 0.6 * (grid_top - grid_bottom)
    bar = figure.add_axes(
        (
            1 - (right - n_width - BAR_GAP) / page_width,
            grid_bottom + (grid_top - grid_bottom - tall) / 2,
            BAR_WIDTH / page_width,
            tall,
        )
    )
    colourbar = figure.colorbar(image, cax=bar)
    colourbar.set_label("mean final Q-value")
    return figure


def _nudge(figure: Any) -> Any:
    """N_GAP points to the right, at any size."""
    from matplotlib.transforms import ScaledTranslation

    return ScaledTranslation(points(N_GAP), 0, figure.dpi_scale_trans)
