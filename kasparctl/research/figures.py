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

from collections.abc import Callable, Sequence
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


def draw_all(data: FigureData, out: Path, formats: Sequence[str] = FORMATS) -> Drawn:
    """Draw every figure the data allow into `out`, each page in `formats` (PNG and PDF;
    SVG too if asked)."""
    require_matplotlib()
    drawn = Drawn(formats=list(formats))
    for name, draw in figure_table(data).items():
        try:
            pages, note = draw()
            if pages is None:
                drawn.notes.append(f"{name}: not drawn, {note}")
                continue
            for page, figure in enumerate(pages, 1):
                rendered = render(figure)
                _check(rendered, name, page, drawn)
                save(rendered, out, page_name(name, page), formats)
        except (ValueError, TypeError, IndexError, ZeroDivisionError, OverflowError) as error:
            # Sessions the tests never imagined must not cost the rest of the report: the
            # figure is left out and the summary's notes (and stderr) say why.
            drawn.notes.append(f"{name}: not drawn, {type(error).__name__}: {error}")
            drawn.failed.append(name)
            continue
        drawn.names.append(name)
        drawn.pages[name] = len(pages)
        if len(pages) > 1:
            files = ", ".join(f"{page_name(name, p)}.png" for p in range(1, len(pages) + 1))
            drawn.notes.append(f"{name}: {len(pages)} pages ({files})")
    return drawn


def _check(rendered: Rendered, name: str, page: int, drawn: Drawn) -> None:
    where = name if page == 1 else f"{name} page {page}"
    clipped = rendered.clipped()
    if clipped:
        drawn.notes.append(f"{where}: labels cut off: {'; '.join(clipped[:3])}")
    overlapping = rendered.overlapping()
    if overlapping:
        drawn.notes.append(f"{where}: labels over each other: {'; '.join(overlapping[:3])}")


def clipped_texts(figure: Any) -> list[str]:
    """The texts of `figure` that reach outside it, or outside the axes clipping them."""
    return render(figure).clipped()


def overlapping_texts(figure: Any) -> list[str]:
    """Pairs of texts of `figure` drawn over each other."""
    return render(figure).overlapping()


def drawn_texts(figure: Any) -> list[Any]:
    """Every text the figure draws (tick labels outside the view are made but not drawn)."""
    return render(figure).texts
