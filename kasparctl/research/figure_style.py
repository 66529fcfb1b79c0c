"""The figures' look, one place: the palette, markers and line styles, the page, the minimum n.

Okabe and Ito's colour-blind-safe palette, and every series also has its own marker
and line style, so no two series (and no green against red answer) differ by hue
alone: a figure printed in grey still tells them apart. The phrase bands (once shaded
green to red, by hue alone) are shaded in greys and named beside the axes. A figure never exceeds a
journal page (PAGE_WIDTH x PAGE_HEIGHT inches); more conditions, children or
contrasts than fit become small multiples over several pages, or are aggregated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

# Okabe & Ito (2008), "Color Universal Design": distinguishable under the common colour
# vision deficiencies. Black first, yellow last (faint on white, so the last resort).
OKABE_ITO = (
    "#000000",  # black
    "#E69F00",  # orange
    "#56B4E9",  # sky blue
    "#009E73",  # bluish green
    "#0072B2",  # blue
    "#D55E00",  # vermillion
    "#CC79A7",  # reddish purple
    "#F0E442",  # yellow
)
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
LINESTYLES = ("-", "--", "-.", ":")

# A journal page's text block, in inches: no figure is larger.
PAGE_WIDTH = 7.5
PAGE_HEIGHT = 9.5
PNG_DPI = 300
# More series than this in one axes become small multiples: a handful is readable.
MAX_SERIES = 4
# A mean over fewer problems (answers) than this is shown as a hollow point, never
# joined into a line: a mean of one or two problems is no trend.
MIN_N = 5
# What a missing participant code, or a missing category of a participant, is called.
UNCODED = "uncoded"

FONT_SIZE = 7.0
SMALL = 6.0
# Real text in the vector files: TrueType (Type 42) fonts in the PDF, <text> in the SVG,
# so a journal's editor can search and restyle the labels.
RC: dict[Any, Any] = {
    "pdf.fonttype": 42,
    "ps.fonttype": 42,
    "svg.fonttype": "none",
    # A fixed salt and no date: the same sessions give the same files, so reports diff.
    "svg.hashsalt": "kasparctl",
    "font.size": FONT_SIZE,
    "axes.titlesize": FONT_SIZE + 1,
    "axes.labelsize": FONT_SIZE,
    "xtick.labelsize": SMALL,
    "ytick.labelsize": SMALL,
    "legend.fontsize": SMALL,
    "legend.title_fontsize": SMALL,
    "figure.titlesize": FONT_SIZE + 2,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "lines.linewidth": 1.2,
    "lines.markersize": 3.5,
    "errorbar.capsize": 1.5,
}


@dataclass(frozen=True, slots=True)
class Style:
    """How one series is drawn: never by its colour alone."""

    colour: str
    marker: str
    linestyle: str

    def line(self) -> dict[str, Any]:
        """Keyword arguments for a line with markers."""
        return {
            "color": self.colour,
            "marker": self.marker,
            "linestyle": self.linestyle,
            "markerfacecolor": self.colour,
            "markeredgecolor": self.colour,
        }

    def points(self, hollow: bool = False) -> dict[str, Any]:
        """Keyword arguments for markers alone (hollow: a white face)."""
        return {
            "color": self.colour,
            "marker": self.marker,
            "linestyle": "none",
            "markerfacecolor": "white" if hollow else self.colour,
            "markeredgecolor": self.colour,
        }


def style(index: int) -> Style:
    """The index-th series' style: colour, marker and line style all change together, and
    past eight the markers and line styles keep pairs apart."""
    return Style(
        OKABE_ITO[index % len(OKABE_ITO)],
        MARKERS[index % len(MARKERS)],
        LINESTYLES[(index + index // len(OKABE_ITO)) % len(LINESTYLES)],
    )


def short(label: str, width: int = 28) -> str:
    """A label cut to `width` characters, with an ellipsis."""
    return label if len(label) <= width else label[: width - 1] + "…"


def new_figure(
    width: float, height: float, layout: Literal["constrained"] | None = "constrained"
) -> Any:
    """A figure on its own Agg canvas (no pyplot, no global state), at most a page.

    `layout` None: the figure places its own grid (figure_layout), which costs nothing
    at its draw."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(
        figsize=(min(width, PAGE_WIDTH), min(height, PAGE_HEIGHT)),
        dpi=PNG_DPI,
        layout=layout,
    )
    FigureCanvasAgg(figure)
    return figure


def grid_shape(panels: int, columns: int) -> tuple[int, int]:
    """Rows and columns of a grid of `panels` panels, at most `columns` wide."""
    across = max(1, min(panels, columns))
    return -(-panels // across), across


def chunks(items: list[Any], size: int) -> list[list[Any]]:
    """`items` in pages of at most `size`, spread evenly (never a last page of one)."""
    if not items:
        return []
    count = -(-len(items) // size)
    per = -(-len(items) // count)
    return [items[start : start + per] for start in range(0, len(items), per)]


def whiskers(axes: Any, x: Any, y: Any, low: Any, high: Any, colour: str, **extra: Any) -> None:
    """95 % whiskers on the points that have an interval, in one look for every figure.

    The distances are clipped at 0: an interval clipped to the measure's range may end at
    the estimate, and matplotlib refuses a negative error.
    """
    axes.errorbar(
        x,
        y,
        yerr=[np.maximum(y - low, 0), np.maximum(high - y, 0)],
        fmt="none",
        ecolor=colour,
        elinewidth=0.6,
        capsize=0,
        alpha=0.7,
        **extra,
    )


def hollow_key(label: str, colour: str = "0.3") -> Any:
    """The legend's key for a hollow point: one drawn without the n (or the clusters) its
    interval or its line needs."""
    from matplotlib.lines import Line2D  # the figures' own import: style stays light

    return Line2D([], [], color=colour, marker="o", markerfacecolor="white",
                  linestyle="none", label=label)
