"""Fixed layouts: a page's margins worked out from what it holds, in inches, before its draw.

matplotlib's constrained layout measured every artist of a page twice (two passes of
tight boxes: each axis's ticks made and every label laid out) before the one draw that
then did it all again: half of the drawing time of a 720-session report. The figures
know what they hold (how many rows of a legend, which labels, their font sizes), so
each places its grid from that: the width of its widest label is measured once as a
string (not as an artist), a legend's height is read from the legend alone, and the
rest is font sizes and fixed pads. The one draw's checks (figure_render) still catch
any label cut off or over another.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from typing import Any

# A line of text takes its font size times this (ascent, descent and leading).
LINE = 1.3
# Between a label and whatever is next to it, and around the page, in points.
PAD = 3.0
EDGE = 4.0
# matplotlib's tick marks and the gap before their labels (rcParams' defaults), points.
TICK = 3.5 + 3.5


def points(value: float) -> float:
    """Points in inches."""
    return value / 72.0


def widest(figure: Any, texts: Iterable[str], size: float, weight: str = "normal") -> float:
    """The widest of `texts` at `size` points, in inches: the sum of its characters'
    advances, read once from the font (laying a string out costs 2 ms, as much as drawing
    it; kerning and ligatures only ever make it narrower)."""
    del figure  # the width is the font's, at any dpi
    advances = _advances(_font_file(weight))
    most = max((sum(advances(c) for c in text) for text in texts), default=0.0)
    # Hinting at 300 dpi widens a string by up to 1 %: a little to spare.
    return most * size / 72.0 * 1.02


def _font_file(weight: str) -> str:
    from matplotlib.font_manager import FontProperties, findfont

    return str(findfont(FontProperties(weight=weight)))


@functools.lru_cache(maxsize=8)
def _advances(path: str) -> Callable[[str], float]:
    """A character's advance in ems, for the font in `path` (each read once)."""
    from matplotlib.font_manager import get_font
    from matplotlib.ft2font import LoadFlags

    font = get_font(path)
    per_em = float(font.units_per_EM)

    @functools.cache
    def advance(character: str) -> float:
        glyph = font.load_char(ord(character), flags=LoadFlags.NO_SCALE | LoadFlags.NO_HINTING)
        return float(glyph.horiAdvance) / per_em

    return advance


def lines(count: int, size: float) -> float:
    """The height of `count` lines of text at `size` points, in inches."""
    return points(count * size * LINE)


def spacing(
    figure: Any,
    rows: int,
    columns: int,
    *,
    left: float,
    right: float,
    top: float,
    bottom: float,
    across: float = 0.0,
    down: float = 0.0,
) -> dict[str, float]:
    """A grid's keyword arguments (figure.add_gridspec's) for these margins, and these
    gaps between its columns (`across`) and rows (`down`), all in inches. (A grid is
    given its place when it is made: matplotlib moves the axes of pyplot's figures
    only when a grid changes afterwards.)"""
    width, height = figure.get_size_inches()
    cell_width = (width - left - right - (columns - 1) * across) / columns
    cell_height = (height - top - bottom - (rows - 1) * down) / rows
    if cell_width <= 0 or cell_height <= 0:
        raise ValueError(f"the page has no room for its {rows} x {columns} panels")
    return {
        "left": left / width,
        "right": 1 - right / width,
        "top": 1 - top / height,
        "bottom": bottom / height,
        "wspace": across / cell_width,
        "hspace": down / cell_height,
    }


def legend_below(figure: Any, **options: Any) -> float:
    """A legend centred at the page's foot; its height in inches (with the page's edge)."""
    legend = figure.legend(loc="lower center", bbox_to_anchor=(0.5, 0.0), **options)
    box = legend.get_window_extent(figure.canvas.get_renderer())
    return float(box.height) / float(figure.dpi) + points(EDGE)


def title_above(figure: Any, text: str, size: float) -> float:
    """The page's title at its top; the height it takes in inches (with the page's edge)."""
    height = figure.get_size_inches()[1]
    figure.suptitle(text, y=1 - points(EDGE) / height, va="top", fontsize=size)
    return points(EDGE) + lines(1, size)
