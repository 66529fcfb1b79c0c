"""A forest plot of every contrast's Hedges' g, grouped by measure, a page at most per 124.

A contrast with an interval is a filled point and its whisker (a diamond when it
survives Holm's correction over the report); one without (fewer than MIN_CLUSTERS
clusters a side) is a hollow circle and says "no interval": it must not look
precise. Each row names its clusters a side. Past ROWS_PER_PANEL rows the rows
continue in a second panel, then on another page.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from kasparctl.research.figure_layout import (
    EDGE,
    PAD,
    TICK,
    legend_below,
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
    hollow_key,
    new_figure,
    short,
)
from kasparctl.research.inference import MEASURES, MIN_CLUSTERS, Contrast

ROWS_PER_PANEL = 62
PANELS_PER_PAGE = 2
LABEL_WIDTH = 50

LABELS = {m.name: m.label for m in MEASURES}
LABELS.update(
    false_green_rate="False greens, of wrong guesses",
    false_red_rate="False reds, of right guesses",
    reaction_time_mean="Reaction time, mean",
    prompts_per_answer="Prompts per answer",
    extra_presses_per_answer="Extra presses per answer",
    undos_per_answer="Undos per answer",
)

Row = tuple[str, Contrast | None]


def row_label(contrast: Contrast) -> str:
    """`A - B (variant) ka/kb`, the shared variant said once."""
    a, b = contrast.a, contrast.b
    tail = _variant(a)
    if tail and tail == _variant(b):
        a, b = a.removesuffix(tail).rstrip(), b.removesuffix(tail).rstrip()
        tail = " " + tail
    else:
        tail = ""
    attribute = contrast.factor.startswith("participant ")
    prefix = contrast.factor.removeprefix("participant ") + " " if attribute else ""
    counts = f" {contrast.clusters_a}/{contrast.clusters_b}"
    return short(f"{prefix}{a} - {b}{tail}", LABEL_WIDTH - len(counts)) + counts


def _variant(label: str) -> str:
    return label[label.rindex("(") :] if label.endswith(")") and "(" in label else ""


def rows_of(found: Sequence[Contrast]) -> list[Row]:
    """A header row per measure, then its contrasts (in the report's order)."""
    by_measure: dict[str, list[Contrast]] = {}
    for contrast in found:
        by_measure.setdefault(contrast.measure, []).append(contrast)
    rows: list[Row] = []
    for measure, mine in by_measure.items():
        rows.append((LABELS.get(measure, measure), None))
        rows += [(row_label(c), c) for c in mine]
    return rows


def contrasts(found: Sequence[Contrast]) -> tuple[list[Any] | None, str]:
    """The forest plot's pages (None and why when no contrast has an effect size)."""
    shown = [c for c in found if c.hedges_g.value is not None]
    if not shown:
        return None, (
            "no contrast with an effect size (it needs two conditions that differ in one "
            "factor, or two levels of a participant attribute, each with at least two clusters)"
        )
    panels = chunks(rows_of(shown), ROWS_PER_PANEL)
    pages = chunks(panels, PANELS_PER_PAGE)
    return [_page(page, number, len(pages)) for number, page in enumerate(pages, 1)], ""


def _page(panels: list[list[Row]], number: int, count: int) -> Any:
    from matplotlib.lines import Line2D

    most = max(len(rows) for rows in panels)
    figure = new_figure(PAGE_WIDTH if len(panels) > 1 else 5.0, 1.4 + 0.128 * most, layout=None)
    handles = [
        Line2D([], [], color="0.1", marker="o", label="Hedges' g, 95 % interval"),
        Line2D([], [], color="0.1", marker="D", label="Holm-adjusted p < 0.05"),
        hollow_key(f"no interval: fewer than {MIN_CLUSTERS} clusters a side", "0.1"),
    ]
    # The fixed layout (figure_layout): each panel's row labels on its left, the legend
    # and the axis labels below, the title above.
    legend = legend_below(
        figure, handles=handles, ncols=3, title="A - B, clusters a side after each row"
    )
    suffix = f" (page {number} of {count})" if count > 1 else ""
    top = title_above(figure, "Contrasts: effect sizes (Hedges' g, A - B)" + suffix, FONT_SIZE + 2)
    labels = [_label_width(figure, rows) + points(TICK_PAD) for rows in panels]
    # Half the widest tick label past an axes' right end ("-0.5" under its last tick).
    overhang = widest(figure, ["-0.5"], SMALL) / 2
    grid = figure.add_gridspec(
        1, len(panels),
        **spacing(
            figure, 1, len(panels),
            left=points(EDGE) + labels[0], right=points(EDGE) + overhang,
            top=top + points(PAD),
            bottom=legend + points(PAD + TICK) + lines(1, SMALL) + lines(1, FONT_SIZE),
            across=max(labels[1:], default=0.0) + overhang + points(PAD),
        ),
    )  # fmt: skip
    grid_axes = grid.subplots(squeeze=False).ravel()
    for axes, rows in zip(grid_axes, panels, strict=True):
        _panel(axes, rows)
    return figure


# The row labels' gap from their axes, points.
TICK_PAD = 3.5


def _label_width(figure: Any, rows: list[Row]) -> float:
    """The widest row label of a panel (the measures' headers are bold), inches."""
    plain = widest(figure, [label for label, c in rows if c is not None], SMALL - 1)
    bold = widest(figure, [label for label, c in rows if c is None], SMALL - 1, "bold")
    return max(plain, bold)


def _panel(axes: Any, rows: list[Row]) -> None:
    """One column of rows: a collection of whiskers and three sets of points, not an
    artist a row (a page has 124)."""
    from matplotlib.collections import LineCollection
    from matplotlib.transforms import ScaledTranslation

    whiskers: list[list[tuple[float, float]]] = []
    significant: list[tuple[float, float]] = []
    other: list[tuple[float, float]] = []
    hollow: list[tuple[float, float]] = []
    for row, (_, contrast) in enumerate(rows):
        if contrast is None:
            continue
        g = contrast.hedges_g
        assert g.value is not None
        if g.low is None or g.high is None:
            hollow.append((g.value, row))
            continue
        whiskers.append([(g.low, row), (g.high, row)])
        (significant if contrast.significant else other).append((g.value, row))
    axes.add_collection(LineCollection(whiskers, colors="0.1", linewidths=0.9))
    sets = ((other, "o", "0.1"), (significant, "D", "0.1"), (hollow, "o", "white"))
    for found, marker, face in sets:
        if found:
            xs, ys = zip(*found, strict=True)
            axes.plot(
                xs, ys, linestyle="none", marker=marker, color="0.1",
                markerfacecolor=face, markersize=3,
            )  # fmt: skip
    axes.autoscale_view()
    axes.axvline(0, color="0.5", linewidth=0.7, linestyle="--")
    # The row labels as texts beside the axes, not as ticks (a tick is five artists).
    axes.set_yticks([])
    beside = axes.get_yaxis_transform() + ScaledTranslation(
        -points(TICK_PAD), 0, axes.figure.dpi_scale_trans
    )
    for row, (label, contrast) in enumerate(rows):
        axes.text(
            0.0, row, label, transform=beside, ha="right", va="center", fontsize=SMALL - 1,
            fontweight="bold" if contrast is None else "normal",
        )  # fmt: skip
    axes.set_ylim(len(rows) - 0.5, -0.5)
    axes.set_xlabel("Hedges' g (clusters' own values)")
