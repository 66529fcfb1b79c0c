"""Fig. 2: the mean entropy before guess k of a problem, with its interval and n, by condition.

Every point has its 95 % interval (a whisker; none where a condition has too few
clusters) and its n (the problems with a k-th guess) in a strip under its panel.
Points over fewer than MIN_N problems are hollow and not joined: no trend is drawn
through them. The phrase bands are shaded and named outside the axes, "no idea"
(log2 of the toys offered, one dotted line for each number in the problems) is in
the legend: no text lies over the data.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from kasparctl.research.figure_data import FigureData
from kasparctl.research.figure_layout import (
    EDGE,
    PAD,
    TICK,
    legend_below,
    lines,
    points,
    title_above,
    widest,
)
from kasparctl.research.figure_panels import Layout, Panel, arrange
from kasparctl.research.figure_strip import N_FONT, label_every, n_strip, strip_grid
from kasparctl.research.figure_style import (
    FONT_SIZE,
    MIN_N,
    PAGE_WIDTH,
    SMALL,
    chunks,
    grid_shape,
    hollow_key,
    new_figure,
    short,
    whiskers,
)

PANELS_PER_PAGE = 6
COLUMNS = 2
# Beyond this many guesses a line is drawn through every few, and marked every few.
MAX_PLOTTED_GUESSES = 400
MAX_MARKED_GUESSES = 40
BAND_SHADES = ("#f2f2f2", "#e4e4e4")
BAND_FONT = SMALL - 0.5
# Between a panel's axes and its strip (the axes' tick marks), points; and under a
# title (axes.titlepad).
STRIP_GAP = 3.5 + 1.0
TITLE_PAD = 6.0


def entropy_by_trial(data: FigureData) -> tuple[list[Any] | None, str]:
    """The pages of Fig. 2 (None and why when no condition has a guess)."""
    conditions = [c for c in data.conditions if c.stats.entropy_by_trial]
    if not conditions:
        return None, "no trials"
    layout = arrange(conditions)
    longest = max(len(c.stats.entropy_by_trial) for c in conditions)
    candidates = sorted(
        {p.record.candidates for c in conditions for p in c.problems if p.record.candidates > 1}
    ) or [max(len(p.toys) for c in conditions for p in c.problems)]
    top = max(math.log2(max(candidates)), 0.5) * 1.06
    pages = chunks(layout.panels, PANELS_PER_PAGE)
    figures = [
        _page(data, layout, panels, longest, candidates, top, number, len(pages))
        for number, panels in enumerate(pages, 1)
    ]
    return figures, ""


def _page(
    data: FigureData,
    layout: Layout,
    panels: list[Panel],
    longest: int,
    candidates: list[int],
    top: float,
    number: int,
    count: int,
) -> Any:
    from matplotlib.lines import Line2D

    rows, columns = grid_shape(len(panels), COLUMNS)
    width = PAGE_WIDTH if columns > 1 else 6.0
    figure = new_figure(width, 1.2 + rows * (2.3 + 0.12 * _series_most(panels)), layout=None)
    handles = [
        Line2D([], [], label=short(name, 30), markersize=3.5, **style.line())
        for name, style in layout.legend.items()
    ]
    handles += [
        hollow_key(f"n < {MIN_N} problems: hollow, not joined"),
        Line2D([], [], color="0.45", linestyle=":", label="no idea: log2(toys offered)"),
    ]
    # The fixed layout (figure_layout): the legend and title first, as they set the
    # margins; band names right of the last column (and of a last panel left alone).
    legend = legend_below(
        figure,
        handles=handles,
        ncols=min(len(handles), 3),
        title=f"{layout.factor}; whiskers: 95 % interval (groups resampled); "
        "strip: n problems with that guess",
    )
    title = "Kaspar's uncertainty by guess: mean entropy"
    heading = title_above(
        figure, title + (f" (page {number} of {count})" if count > 1 else ""), FONT_SIZE + 2
    )
    bands = _band_spans(data, top)
    named = widest(figure, [name for _, _, name in bands], BAND_FONT) + points(PAD)
    ticks = widest(figure, ["0.0"], SMALL) + points(TICK)
    titled = lines(1, SMALL + 1) + points(TITLE_PAD) if any(p.title for p in panels) else 0.0
    axis = lines(1, SMALL) + points(TICK)  # the strip's tick labels under it
    alone = len(panels) % columns != 0 and columns > 1  # the last panel in the left column
    outer, inner = strip_grid(
        figure, rows, columns, points(STRIP_GAP) + lines(1, N_FONT),
        left=points(EDGE) + lines(1, FONT_SIZE) + points(PAD) + ticks,
        right=points(EDGE) + named,
        top=heading + titled + points(PAD),
        bottom=legend + points(PAD) + axis + lines(1, FONT_SIZE),
        across=ticks + points(PAD) + (named if alone else 0.0),
        down=axis + (lines(1, FONT_SIZE) if alone else 0.0) + titled + points(PAD),
    )  # fmt: skip
    column_width = (width - 0.9) / columns
    for place, panel in enumerate(panels):
        row, column = divmod(place, columns)
        cell = outer[row, column].subgridspec(
            2, 1, height_ratios=[4.0, 0.35 + 0.22 * len(panel.series)], hspace=inner
        )
        axes = figure.add_subplot(cell[0])
        strip = figure.add_subplot(cell[1], sharex=axes)
        _panel(data, panel, axes, strip, longest, candidates, top, column_width)
        axes.tick_params(labelbottom=False)
        if column == 0:
            axes.set_ylabel("entropy before the guess (bits)")
        if row == rows - 1 or place + columns >= len(panels):
            strip.set_xlabel("guess within a problem")
        if column == columns - 1 or place == len(panels) - 1:
            _band_names(bands, axes)
    return figure


def _series_most(panels: Sequence[Panel]) -> int:
    return max(len(panel.series) for panel in panels)


def _panel(
    data: FigureData,
    panel: Panel,
    axes: Any,
    strip: Any,
    longest: int,
    candidates: list[int],
    top: float,
    column_width: float,
) -> None:
    for index, band in enumerate(data.bands):
        if band.min < top:
            axes.axhspan(
                band.min, min(band.max, top), color=BAND_SHADES[index % 2], zorder=0, linewidth=0
            )
    for count in candidates:
        axes.axhline(math.log2(count), color="0.45", linestyle=":", linewidth=0.8, zorder=1)
    largest = max(max(s.condition.stats.entropy_by_trial_n) for s in panel.series)
    every = label_every(largest, longest, column_width)
    counts = []
    spread = 0.36 / max(len(panel.series), 1)
    for row, series in enumerate(panel.series):
        condition, style = series.condition, series.style
        found = data.intervals[condition.label].entropy_by_trial
        means = np.array(condition.stats.entropy_by_trial, dtype=float)
        ns = np.array(condition.stats.entropy_by_trial_n)
        offset = (row - (len(panel.series) - 1) / 2) * spread
        ks = np.arange(1, len(means) + 1) + offset
        shown = np.unique(
            np.linspace(0, len(ks) - 1, min(len(ks), MAX_PLOTTED_GUESSES)).astype(int)
        )
        enough = ns >= MIN_N
        joined = np.where(enough, means, np.nan)[shown]
        mark_every = max(1, math.ceil(len(shown) / MAX_MARKED_GUESSES))
        axes.plot(ks[shown], joined, zorder=3, markevery=mark_every, **style.line())
        few = shown[~enough[shown]]
        axes.plot(
            ks[few],
            means[few],
            linestyle="none",
            marker=style.marker,
            markerfacecolor="white",
            markeredgecolor=style.colour,
            zorder=3,
        )
        lows = np.array([np.nan if e.low is None else e.low for e in found], dtype=float)
        highs = np.array([np.nan if e.high is None else e.high for e in found], dtype=float)
        bounded = shown[~np.isnan(lows[shown])]
        if len(bounded):
            whiskers(
                axes, ks[bounded], means[bounded], lows[bounded], highs[bounded], style.colour,
                zorder=2,
            )
        counts.append((style, list(range(1, len(ns) + 1)), [int(n) for n in ns]))
    n_strip(strip, counts, every, left=0.1)
    axes.set_xlim(-0.3, longest + 0.7)
    axes.set_ylim(0, top)
    if panel.title:
        axes.set_title(short(panel.title, 44), fontsize=SMALL + 1)


def _band_spans(data: FigureData, top: float) -> list[tuple[float, float, str]]:
    """The phrase bands within the axes: their bottom, top and name."""
    return [
        (b.min, min(b.max, top), b.name.replace("_", " ")) for b in data.bands if b.min < top
    ]


def _band_names(spans: list[tuple[float, float, str]], axes: Any) -> None:
    """The phrase bands' names beside the axes, where no data are: texts, not a second
    axis (whose ticks would cost a draw each)."""
    from matplotlib.transforms import ScaledTranslation

    beside = axes.get_yaxis_transform() + ScaledTranslation(
        points(PAD), 0, axes.figure.dpi_scale_trans
    )
    for low, high, name in spans:
        axes.text(
            1.0, (low + high) / 2, name, transform=beside, fontsize=BAND_FONT, va="center"
        )
