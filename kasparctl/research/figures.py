"""The report's figures for a journal: PNG at 300 dpi, PDF (and SVG on request) with real text.

Fig. 2 (entropy_by_trial), Fig. 3 (final_q), trials_to_learn, feedback_by_child and
contrasts, a module each (figure_entropy, figure_final_q, figure_trials,
figure_feedback, figure_contrasts); the look (Okabe-Ito palette, markers and line
styles, the page, the minimum n) in figure_style, small multiples in figure_panels,
the single draw, its checks and the files in figure_render. Every point shows its n
and, where it has one, its 95 % interval; no figure is larger than a page (more becomes
panels, pages, or an aggregate); each is drawn once and checked on that draw: a label
cut off, or two labels over each other, is named in the summary's notes (and the tests fail on it).

matplotlib is the optional `report` extra: the robot never imports these modules'
drawing code, so matplotlib is imported only when a report draws. Figures are drawn
on matplotlib's Agg canvas directly (no pyplot), so no display and no global backend
state are involved.
"""

from __future__ import annotations

import gc
import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hal.errors import KasparError
from kasparctl.research.figure_contrasts import contrasts
from kasparctl.research.figure_data import Drawn, FigureData
from kasparctl.research.figure_entropy import entropy_by_trial
from kasparctl.research.figure_feedback import feedback_by_child, wilson
from kasparctl.research.figure_final_q import final_q
from kasparctl.research.figure_render import FORMATS, SVG, Rendered, render, save
from kasparctl.research.figure_style import RC
from kasparctl.research.figure_trials import trials_to_learn

__all__ = [
    "FORMATS",
    "SVG",
    "Drawn",
    "FigureData",
    "FiguresUnavailable",
    "clipped_texts",
    "draw_all",
    "drawn_texts",
    "figure_table",
    "page_name",
    "render",
    "require_matplotlib",
    "wilson",
]

INSTALL_HINT = "pip install 'kasparctl[report]'"

Pages = tuple[list[Any] | None, str]


class FiguresUnavailable(KasparError):
    """matplotlib is not installed; the message says how to install it."""


def require_matplotlib() -> None:
    """Fail before any work when the figures cannot be drawn."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as error:
        raise FiguresUnavailable(
            f"the report's figures need matplotlib, which is not installed: {INSTALL_HINT}"
        ) from error


def _styled(draw: Callable[[], Pages]) -> Callable[[], Pages]:
    """`draw` under the figures' rc settings (sizes and fonts are read as artists are made)."""

    def drawing() -> Pages:
        import matplotlib

        with matplotlib.rc_context(RC):
            return draw()

    return drawing


def figure_table(data: FigureData) -> dict[str, Callable[[], Pages]]:
    """Each figure's name and the function that draws its pages (None and why if it cannot)."""
    return {
        "entropy_by_trial": _styled(lambda: entropy_by_trial(data)),
        "final_q": _styled(lambda: final_q(data.conditions)),
        "trials_to_learn": _styled(lambda: trials_to_learn(data)),
        "feedback_by_child": _styled(lambda: feedback_by_child(data)),
        "contrasts": _styled(lambda: contrasts(data.contrasts)),
    }


def page_name(name: str, page: int) -> str:
    """A figure's file name without suffix: `name` for its first page, then `name-2`..."""
    return name if page == 1 else f"{name}-{page}"


# The slowest first (final_q and contrasts are several pages at scale), so the last figure
# to start is a short one and no worker waits long on another.
LONGEST_FIRST = ("final_q", "contrasts", "entropy_by_trial", "trials_to_learn")


@dataclass
class Outcome:
    """One figure drawn (or not) by one process: its pages and notes, for the summary."""

    name: str
    pages: int = 0
    notes: list[str] = field(default_factory=list)
    failed: bool = False


def draw_all(
    data: FigureData,
    out: Path,
    formats: Sequence[str] = FORMATS,
    workers: int = 1,
) -> Drawn:
    """Draw every figure the data allow into `out`, each page in `formats` (PNG and PDF;
    SVG too if asked).

    Each figure is drawn whole in one process: up to `workers` at once, so the files and
    the notes are those of drawing them one after another. One by default: each worker
    imports matplotlib and draws a page at 300 dpi, about 200 MB at 720 sessions, so two
    workers and the report's process come to 529 MB against the 300 MB target."""
    require_matplotlib()
    names = list(figure_table(data))
    workers = min(len(names), workers)
    if workers <= 1:
        outcomes = [draw_one(data, name, out, formats) for name in names]
    else:
        order = sorted(names, key=lambda n: LONGEST_FIRST.index(n) if n in LONGEST_FIRST else 99)
        # spawn, not fork: a forked worker counts the parent's sessions in its RSS too, and
        # fork under threads is unsafe; a fresh worker a figure gives its memory back.
        with ProcessPoolExecutor(
            workers, mp_context=multiprocessing.get_context("spawn"), max_tasks_per_child=1
        ) as pool:
            futures = {name: pool.submit(draw_one, data, name, out, formats) for name in order}
            outcomes = [futures[name].result() for name in names]
    drawn = Drawn(formats=list(formats))
    for outcome in outcomes:
        drawn.notes += outcome.notes
        if outcome.failed:
            drawn.failed.append(outcome.name)
        elif outcome.pages:
            drawn.names.append(outcome.name)
            drawn.pages[outcome.name] = outcome.pages
    return drawn


def draw_one(data: FigureData, name: str, out: Path, formats: Sequence[str]) -> Outcome:
    """Draw figure `name` into `out`: every page, checked, in `formats`."""
    outcome = Outcome(name)
    try:
        pages, note = figure_table(data)[name]()
        if pages is None:
            outcome.notes.append(f"{name}: not drawn, {note}")
            return outcome
        for page, figure in enumerate(pages, 1):
            rendered = render(figure)
            outcome.notes += _check(rendered, name, page)
            save(rendered, out, page_name(name, page), formats)
            # Its artists and 300-dpi buffer freed now, not when the last page is done: a
            # worker's peak is one page's, not the figure's (280 MB for final_q's two pages).
            # Not cleared (clearing an axes makes it anew, 0.5 s a report): its canvas's
            # renderer, which holds the buffer, let go, and its artists collected.
            pages[page - 1] = None
            figure.canvas.renderer = None
            del rendered, figure
            gc.collect()
    except (ValueError, TypeError, IndexError, ZeroDivisionError, OverflowError) as error:
        # Sessions the tests never imagined must not cost the rest of the report: the
        # figure is left out and the summary's notes (and stderr) say why.
        outcome.notes.append(f"{name}: not drawn, {type(error).__name__}: {error}")
        outcome.failed = True
        return outcome
    outcome.pages = len(pages)
    if len(pages) > 1:
        files = ", ".join(f"{page_name(name, p)}.png" for p in range(1, len(pages) + 1))
        outcome.notes.append(f"{name}: {len(pages)} pages ({files})")
    return outcome


def _check(rendered: Rendered, name: str, page: int) -> list[str]:
    where = name if page == 1 else f"{name} page {page}"
    notes = []
    clipped = rendered.clipped()
    if clipped:
        notes.append(f"{where}: labels cut off: {'; '.join(clipped[:3])}")
    overlapping = rendered.overlapping()
    if overlapping:
        notes.append(f"{where}: labels over each other: {'; '.join(overlapping[:3])}")
    return notes


def clipped_texts(figure: Any) -> list[str]:
    """The texts of `figure` that reach outside it, or outside the axes clipping them."""
    return render(figure).clipped()


def overlapping_texts(figure: Any) -> list[str]:
    """Pairs of texts of `figure` drawn over each other."""
    return render(figure).overlapping()


def drawn_texts(figure: Any) -> list[Any]:
    """Every text the figure draws (tick labels outside the view are made but not drawn)."""
    return render(figure).texts
