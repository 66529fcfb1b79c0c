"""Feedback accuracy: the share of each child's answers that agreed with the answer key.

By participant where the plans name children by codes: a dot a child with its 95 %
Wilson interval and n (answers checked), marked and coloured by the first category of
participants.csv; a child of a group planned without codes, or a category left empty,
is "uncoded", shown like the rest (never dropped, never "None"). Past
MAX_CHILDREN_SHOWN children the figure aggregates: the distribution of the children's
shares per level, with each level's n. Without codes: by place in the turn order, a
row per condition (pages of ROWS_PER_PAGE), saying that a place pools different
children.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from kasparctl.research.children import ChildMeasures
from kasparctl.research.conditions import Condition
from kasparctl.research.figure_data import FigureData
from kasparctl.research.figure_style import (
    PAGE_HEIGHT,
    PAGE_WIDTH,
    SMALL,
    UNCODED,
    chunks,
    new_figure,
    short,
    style,
)
from kasparctl.research.participants import Participants

ROWS_PER_COLUMN = 60
MAX_CHILDREN_SHOWN = 2 * ROWS_PER_COLUMN
ROWS_PER_PAGE = 50
BINS = np.linspace(0, 100, 11)


def wilson(right: int, total: int, z: float = 1.959964) -> tuple[float, float]:
    """The Wilson 95 % interval of a share right/total (0 to 1)."""
    if total == 0:
        return 0.0, 1.0
    share = right / total
    centre = (share + z * z / (2 * total)) / (1 + z * z / total)
    spread = z * math.sqrt(share * (1 - share) / total + z * z / (4 * total * total))
    spread /= 1 + z * z / total
    return max(0.0, centre - spread), min(1.0, centre + spread)


def feedback_by_child(data: FigureData) -> tuple[list[Any] | None, str]:
    """By participant where any plan has codes, else by place in the turn order."""
    checked = [c for c in data.children if c.feedback.checked]
    if any(c.participant is not None for c in checked):
        return _by_participant(checked, data.participants), ""
    return _by_position(data.conditions)


def level_of(child: ChildMeasures, participants: Participants, attribute: str | None) -> str:
    """The child's level of `attribute`: "uncoded" without a code or a value."""
    if child.participant is None:
        return UNCODED
    if attribute is None:
        return "coded"
    value = participants.attributes(child.participant).get(attribute)
    return UNCODED if value is None or str(value).strip() == "" else str(value)


def _levels(found: set[str]) -> list[str]:
    return sorted(found - {UNCODED}) + ([UNCODED] if UNCODED in found else [])


def _by_participant(children: Sequence[ChildMeasures], participants: Participants) -> list[Any]:
    categories = participants.categories()
    attribute = categories[0] if categories else None
    levels_of = {c.key: level_of(c, participants, attribute) for c in children}
    levels = _levels(set(levels_of.values()))
    styles = {level: style(i) for i, level in enumerate(levels)}
    title = attribute or "participant code"
    if len(children) > MAX_CHILDREN_SHOWN:
        return [_distribution(children, levels_of, levels, styles, title)]
    ordered = sorted(children, key=lambda c: (levels.index(levels_of[c.key]), c.label))
    columns = chunks(ordered, ROWS_PER_COLUMN)
    most = max(len(column) for column in columns)
    figure = new_figure(max(5.0, 3.6 * len(columns) + 0.4), min(PAGE_HEIGHT, 1.4 + 0.15 * most))
    grid = figure.subplots(1, len(columns), squeeze=False).ravel()
    for axes, column in zip(grid, columns, strict=True):
        for row, child in enumerate(column):
            f = child.feedback
            share = 100 * f.right / f.checked
            low, high = wilson(f.right, f.checked)
            look = styles[levels_of[child.key]]
            axes.errorbar(
                [share],
                [row],
                xerr=[[max(share - 100 * low, 0)], [max(100 * high - share, 0)]],
                color=look.colour,
                marker=look.marker,
                markersize=3,
                elinewidth=0.7,
                capsize=1.2,
            )
        axes.set_yticks(range(len(column)), [short(c.label, 24) for c in column])
        counts = axes.secondary_yaxis("right")
        counts.set_yticks(range(len(column)), [f"n={c.feedback.checked}" for c in column])
        counts.tick_params(length=0, pad=1)
        axes.set_ylim(len(column) - 0.5, -0.5)
        axes.set_xlim(0, 100)
        axes.set_xlabel("answers agreeing with the answer key (%)")
    _legend(figure, styles, title)
    figure.suptitle("Feedback accuracy per participant (95 % Wilson interval; n: answers checked)")
    return [figure]


def _legend(figure: Any, styles: dict[str, Any], title: str) -> None:
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color=s.colour, marker=s.marker, linestyle="none", label=level)
        for level, s in styles.items()
    ]
    figure.legend(handles=handles, title=title, loc="outside lower center", ncols=len(handles))


def _distribution(
    children: Sequence[ChildMeasures],
    levels_of: dict[str, str],
    levels: list[str],
    styles: dict[str, Any],
    title: str,
) -> Any:
    """Too many children for a row each: how their shares spread, per level."""
    from matplotlib.lines import Line2D

    figure = new_figure(PAGE_WIDTH, 5.2)
    spread_axes, summary_axes = figure.subplots(1, 2, width_ratios=[3, 2])
    centres = (BINS[:-1] + BINS[1:]) / 2
    handles = []
    for index, level in enumerate(levels):
        mine = [c for c in children if levels_of[c.key] == level]
        shares = np.array([100 * c.feedback.right / c.feedback.checked for c in mine])
        answers = sum(c.feedback.checked for c in mine)
        tally, _ = np.histogram(shares, bins=BINS)
        look = styles[level]
        spread_axes.plot(centres, 100 * tally / len(mine), **look.line())
        handles.append(
            Line2D(
                [], [], label=f"{level} (n={len(mine)} children, {answers} answers)", **look.line()
            )
        )
        quartiles = np.percentile(shares, [25, 50, 75])
        summary_axes.errorbar(
            [quartiles[1]],
            [index],
            xerr=[[quartiles[1] - quartiles[0]], [quartiles[2] - quartiles[1]]],
            color=look.colour,
            marker=look.marker,
            capsize=2,
        )
    spread_axes.set_xlim(0, 100)
    spread_axes.set_xlabel("child's answers agreeing with the answer key (%)")
    spread_axes.set_ylabel("children (%)")
    summary_axes.set_yticks(range(len(levels)), levels)
    summary_axes.set_ylim(len(levels) - 0.5, -0.5)
    summary_axes.set_xlim(0, 104)  # a median of 100 % is not cut in half by the edge
    summary_axes.set_xlabel("median child (%), bar: quartiles")
    figure.legend(handles=handles, title=title, loc="outside lower center", ncols=2)
    figure.suptitle(
        f"Feedback accuracy of {len(children)} children: the spread of their shares "
        f"(more than {MAX_CHILDREN_SHOWN}, so aggregated)"
    )
    return figure


def _by_position(conditions: Sequence[Condition]) -> tuple[list[Any] | None, str]:
    tallies = [{p: f for p, f in c.feedback_by_position.items() if f.checked} for c in conditions]
    rows = [(c, t) for c, t in zip(conditions, tallies, strict=True) if t]
    if not rows:
        return None, "no session has an answer key"
    positions = sorted({p for _, tally in rows for p in tally})
    styles = {p: style(i) for i, p in enumerate(positions)}
    pages = chunks(rows, ROWS_PER_PAGE)
    figures = []
    for number, page in enumerate(pages, 1):
        figure = new_figure(PAGE_WIDTH, 1.5 + 0.2 * len(page))
        axes = figure.add_subplot()
        spread = 0.5 / len(positions)
        for row, (_, tally) in enumerate(page):
            for index, place in enumerate(positions):
                if place not in tally:
                    continue
                f = tally[place]
                share = 100 * f.right / f.checked
                low, high = wilson(f.right, f.checked)
                look = styles[place]
                axes.errorbar(
                    [share],
                    [row + (index - (len(positions) - 1) / 2) * spread],
                    xerr=[[max(share - 100 * low, 0)], [max(100 * high - share, 0)]],
                    color=look.colour,
                    marker=look.marker,
                    markersize=3,
                    elinewidth=0.7,
                    capsize=1.2,
                )
        axes.set_yticks(range(len(page)), [short(c.label, 34) for c, _ in page])
        counts = axes.secondary_yaxis("right")
        counts.set_yticks(
            range(len(page)),
            [
                "n=" + "/".join(str(t[p].checked) if p in t else "-" for p in positions)
                for _, t in page
            ],
        )
        counts.tick_params(length=0, pad=1)
        axes.set_ylim(len(page) - 0.5, -0.5)
        axes.set_xlim(0, 100)
        axes.set_xlabel(
            "answers agreeing with the answer key (%) by place in the turn order "
            "(pooled over groups: not the same children)"
        )
        _legend(figure, {f"child {p}": styles[p] for p in positions}, "place (n in order)")
        suffix = f" (page {number} of {len(pages)})" if len(pages) > 1 else ""
        figure.suptitle(
            "Feedback accuracy per turn (95 % Wilson interval; n: answers checked)" + suffix,
            fontsize=SMALL + 2,
        )
        figures.append(figure)
    return figures, ""
