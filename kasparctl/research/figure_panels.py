"""Conditions arranged as small multiples: a handful of series a panel, one style per level.

Up to MAX_SERIES conditions share one axes, each its own style. Past that, one
factor of the design (the uncertainty mode, else the profile, else the variant:
the one with most levels that still fits in a panel) is drawn as the series,
in the same style in every panel (one legend serves them all), and the other
factors make the panels: a 3-profile x 4-mode x 2-variant study is six panels of
four lines. Conditions without factors (or too many levels of everything) get a
panel each.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from kasparctl.research.conditions import MODE_ORDER, Condition
from kasparctl.research.figure_style import MAX_SERIES, Style, style

FACTORS = ("uncertainty", "profile", "variant")


@dataclass(frozen=True)
class Series:
    """One condition as a series: its style and its name in the legend."""

    condition: Condition
    style: Style
    name: str


@dataclass(frozen=True)
class Panel:
    """One axes' worth of series, and its title (empty when there is one panel)."""

    title: str
    series: list[Series]


@dataclass(frozen=True)
class Layout:
    """The panels, and the legend shared by them: each series name's style."""

    panels: list[Panel]
    legend: dict[str, Style]
    # What the series are, for the legend's title ("uncertainty", or "condition").
    factor: str


def arrange(conditions: Sequence[Condition]) -> Layout:
    """The panels for `conditions` (see the module's docstring)."""
    if len(conditions) <= MAX_SERIES:
        series = [Series(c, style(i), c.label) for i, c in enumerate(conditions)]
        return Layout([Panel("", series)], {s.name: s.style for s in series}, "condition")
    factor = _series_factor(conditions)
    if factor is None:
        panels = [Panel(c.label, [Series(c, style(0), c.label)]) for c in conditions]
        return Layout(panels, {}, "condition")
    levels = _ordered(factor, {_level(c, factor) for c in conditions})
    styles = {level: style(i) for i, level in enumerate(levels)}
    grouped: dict[str, list[Series]] = {}
    if len({(_rest(c, factor), _level(c, factor)) for c in conditions}) < len(conditions):
        # Two conditions alike in every factor (labels differing otherwise): one panel each.
        panels = [Panel(c.label, [Series(c, style(0), c.label)]) for c in conditions]
        return Layout(panels, {}, "condition")
    for condition in conditions:
        level = _level(condition, factor)
        grouped.setdefault(_rest(condition, factor), []).append(
            Series(condition, styles[level], level)
        )
    panels = [
        Panel(title, sorted(series, key=lambda s: levels.index(s.name)))
        for title, series in sorted(grouped.items())
    ]
    return Layout(panels, styles, factor)


def _level(condition: Condition, factor: str) -> str:
    assert condition.factors is not None
    return str(getattr(condition.factors, factor))


def _rest(condition: Condition, factor: str) -> str:
    """The panel's title: the condition's other factors that vary."""
    assert condition.factors is not None
    return " / ".join(str(getattr(condition.factors, f)) for f in FACTORS if f != factor)


def _ordered(factor: str, levels: set[str]) -> list[str]:
    if factor == "uncertainty":
        return [m for m in MODE_ORDER if m in levels] + sorted(levels - set(MODE_ORDER))
    return sorted(levels)


def _series_factor(conditions: Sequence[Condition]) -> str | None:
    if any(c.factors is None for c in conditions):
        return None
    best: tuple[int, str] | None = None
    for factor in FACTORS:
        count = len({_level(c, factor) for c in conditions})
        if 1 < count <= MAX_SERIES and (best is None or count > best[0]):
            best = (count, factor)
    return None if best is None else best[1]
