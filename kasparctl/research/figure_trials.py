"""The share of learned problems that took k trials, by condition: points, intervals and n.

No grouped bars (24 conditions of 17 bars each were unreadable): each condition is
a series of points in its style with 95 % whiskers, the conditions arranged in the
same panels as Fig. 2, and the count under each point in a strip. A condition with
fewer than MIN_N learned problems has its points hollow and not joined. Over a range
too wide for a point per value, MAX_BINS equal bins (without intervals: the
bootstrap's bins are single values).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from kasparctl.research.conditions import Condition
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
MAX_BINS = 32
# Between a panel's axes and its strip (the axes' tick marks), points; and under a
# title (axes.titlepad).
STRIP_GAP = 3.5 + 1.0
TITLE_PAD = 6.0


def learned_lengths(condition: Condition) -> list[int]:
    """Trials each learned problem took (confirming greens included)."""
    return [len(p.record.trials) for p in condition.problems if p.record.learned is not None]


def trials_to_learn(data: FigureData) -> tuple[list[Any] | None, str]:
    """The pages of the trials-to-learn figure (None and why when nothing was learned)."""
    lengths = {c.label: learned_lengths(c) for c in data.conditions}
    shown = [c for c in data.conditions if lengths[c.label]]
    if not shown:
        return None, "no problem was learned"
    low = min(min(v) for v in lengths.values() if v)
    high = max(max(v) for v in lengths.values() if v)
    if high - low + 1 > MAX_BINS:
        edges = np.linspace(low, high + 1, MAX_BINS + 1)
    else:
        edges = np.arange(low, high + 2, dtype=float)
    layout = arrange(shown)
    pages = chunks(layout.panels, PANELS_PER_PAGE)
    return [
        _page(data, layout, panels, lengths, edges, number, len(pages))
        for number, panels in enumerate(pages, 1)
    ], ""


def _page(
    data: FigureData,
    layout: Layout,
    panels: list[Panel],
    lengths: dict[str, list[int]],
    edges: Any,
    number: int,
    count: int,
) -> Any:
    from matplotlib.lines import Line2D

    rows, columns = grid_shape(len(panels), COLUMNS)
    width = PAGE_WIDTH if columns > 1 else 6.0
    most = max(len(p.series) for p in panels)
    figure = new_figure(width, 1.2 + rows * (2.1 + 0.12 * most), layout=None)
    binned = len(edges) - 1 == MAX_BINS and edges[1] - edges[0] != 1
    handles = [
        Line2D([], [], label=short(name, 30), **style.line())
        for name, style in layout.legend.items()
    ]
    handles.append(hollow_key(f"fewer than {MIN_N} learned: hollow, not joined"))
    # The fixed layout (figure_layout): the legend and title first, as they set the margins.
    legend = legend_below(
        figure,
        handles=handles,
        ncols=min(len(handles), 3),
        title=f"{layout.factor}; whiskers: 95 % interval (groups resampled); "
        "strip: n learned problems in that bin",
    )
    suffix = f" (page {number} of {count})" if count > 1 else ""
    heading = title_above(
        figure, "Trials to learn: share of each condition's learned problems" + suffix,
        FONT_SIZE + 2,
    )  # fmt: skip
    ticks = widest(figure, ["100"], SMALL) + points(TICK)
    titled = lines(1, SMALL + 1) + points(TITLE_PAD) if any(p.title for p in panels) else 0.0
    axis = lines(1, SMALL) + points(TICK)  # the strip's tick labels under it
    alone = len(panels) % columns != 0 and columns > 1  # a panel above an empty place
    outer, inner = strip_grid(
        figure, rows, columns, points(STRIP_GAP) + lines(1, N_FONT),
        left=points(EDGE) + lines(1, FONT_SIZE) + points(PAD) + ticks,
        right=points(EDGE) + ticks / 2,
        top=heading + titled + points(PAD),
        bottom=legend + points(PAD) + axis + lines(1, FONT_SIZE),
        across=ticks + points(PAD),
        down=axis + (lines(1, FONT_SIZE) if alone else 0.0) + titled + points(PAD),
    )  # fmt: skip
    tallest = 0.0
    axes_made = []
    for place, panel in enumerate(panels):
        row, column = divmod(place, columns)
        cell = outer[row, column].subgridspec(
            2, 1, height_ratios=[4.0, 0.35 + 0.22 * len(panel.series)], hspace=inner
        )
        axes = figure.add_subplot(cell[0])
        strip = figure.add_subplot(cell[1], sharex=axes)
        tallest = max(tallest, _panel(data, panel, axes, strip, lengths, edges, width / columns))
        axes.tick_params(labelbottom=False)
        if panel.title:
            axes.set_title(short(panel.title, 44), fontsize=SMALL + 1)
        if column == 0:
            axes.set_ylabel("learned problems (%)")
        if place + columns >= len(panels):
            strip.set_xlabel(
                f"trials to learn, in bins of {edges[1] - edges[0]:.0f}"
                if binned
                else "trials to learn (confirming greens included)"
            )
        axes_made.append(axes)
    for axes in axes_made:
        axes.set_ylim(0, max(tallest * 1.08, 5.0))
    return figure


def _panel(
    data: FigureData,
    panel: Panel,
    axes: Any,
    strip: Any,
    lengths: dict[str, list[int]],
    edges: Any,
    width: float,
) -> float:
    """Draw one panel; its tallest point or whisker (%)."""
    centres = (edges[:-1] + edges[1:] - 1) / 2 if edges[1] - edges[0] != 1 else edges[:-1]
    step = float(edges[1] - edges[0])
    spread = 0.36 * step / max(len(panel.series), 1)
    tallest = 0.0
    rows = []
    largest = 1
    for index, series in enumerate(panel.series):
        condition, style = series.condition, series.style
        values = lengths[condition.label]
        tally, _ = np.histogram(values, bins=edges)
        shares = 100.0 * tally / len(values)
        found = data.intervals[condition.label]
        lows: list[float] = []
        highs: list[float] = []
        for centre in edges[:-1]:
            position = int(centre) - found.trials_bins_start
            estimate = (
                found.trials_share[position]
                if step == 1 and 0 <= position < len(found.trials_share)
                else None
            )
            if estimate is None or estimate.low is None or estimate.high is None:
                lows.append(np.nan)
                highs.append(np.nan)
            else:
                lows.append(100 * estimate.low)
                highs.append(100 * estimate.high)
        x = centres + (index - (len(panel.series) - 1) / 2) * spread
        if len(values) >= MIN_N:
            axes.plot(x, shares, zorder=3, **style.line())
        else:
            axes.plot(
                x,
                shares,
                linestyle="none",
                marker=style.marker,
                markerfacecolor="white",
                markeredgecolor=style.colour,
                zorder=3,
            )
        low, high = np.array(lows), np.array(highs)
        bounded = ~np.isnan(low)
        if bounded.any():
            whiskers(
                axes, x[bounded], shares[bounded], low[bounded], high[bounded], style.colour
            )
            tallest = max(tallest, float(np.nanmax(high)))
        tallest = max(tallest, float(shares.max()))
        rows.append((style, list(centres), [int(n) for n in tally]))
        largest = max(largest, int(tally.max()))
    n_strip(strip, rows, label_every(largest, len(centres), width - 0.5), left=centres[0] - step)
    axes.set_xlim(centres[0] - 1.5 * step, centres[-1] + 0.7 * step)
    return tallest
