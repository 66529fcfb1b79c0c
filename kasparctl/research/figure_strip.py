"""The strip of n under a panel: one row a series (its marker), a count under each point."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from kasparctl.research.figure_style import Style

N_FONT = 4.5


def label_every(largest: int, positions: int, width_inches: float) -> int:
    """Label every how-many positions so the counts never run into each other: the
    widest count's digits at N_FONT points against each position's width."""
    per_position = width_inches * 72 / (positions + 1.5)
    return max(1, math.ceil((len(str(largest)) * 0.62 * N_FONT + 1.5) / per_position))


def n_strip(
    strip: Any,
    rows: Sequence[tuple[Style, Sequence[float], Sequence[int]]],
    every: int,
    left: float,
) -> None:
    """Each row: the series' marker at `left`, then its counts at their x positions."""
    for row, (style, xs, counts) in enumerate(rows):
        strip.plot([left], [row], **style.points())
        for x, n in list(zip(xs, counts, strict=True))[::every]:
            strip.text(x, row, str(n), ha="center", va="center", fontsize=N_FONT)
    strip.set_ylim(len(rows) - 0.5, -0.5)
    strip.set_yticks([])
    strip.xaxis.get_major_locator().set_params(integer=True)
    strip.tick_params(left=False)
    strip.spines["left"].set_visible(False)
    strip.set_ylabel("n", rotation=0, va="center", labelpad=6)
    if every > 1:
        strip.set_title(f"n every {every}", fontsize=N_FONT, loc="right", pad=1)


def strip_grid(
    figure: Any, rows: int, columns: int, gap: float, **margins: float
) -> tuple[Any, float]:
    """The page's grid of panels, each an axes over its n strip (figure_layout.spacing's
    `margins`), and the hspace that leaves `gap` inches between a panel's axes and strip."""
    from kasparctl.research.figure_layout import spacing

    grid = spacing(figure, rows, columns, **margins)
    height = figure.get_size_inches()[1] * (grid["top"] - grid["bottom"])
    cell = height / (rows + grid["hspace"] * (rows - 1))
    return figure.add_gridspec(rows, columns, **grid), gap / ((cell - gap) / 2)
