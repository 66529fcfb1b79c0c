"""What the figures draw from, and what a report drew."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from kasparctl.game.phrases import Band
from kasparctl.research.children import ChildMeasures
from kasparctl.research.conditions import Condition
from kasparctl.research.inference import Contrast, Intervals
from kasparctl.research.participants import NO_PARTICIPANTS, Participants


@dataclass(frozen=True)
class FigureData:
    """Everything the figures draw from."""

    conditions: Sequence[Condition]
    intervals: dict[str, Intervals]
    bands: Sequence[Band]
    children: Sequence[ChildMeasures] = ()
    participants: Participants = NO_PARTICIPANTS
    contrasts: Sequence[Contrast] = ()


@dataclass
class Drawn:
    """The figures a report drew, by name, and those it left out."""

    names: list[str] = field(default_factory=list)
    # Figures left out and why ("no answer key"), or drawn with a fault, for the summary.
    notes: list[str] = field(default_factory=list)
    # Figures whose drawing failed (their note says how).
    failed: list[str] = field(default_factory=list)
    # Pages of each figure drawn: name.png, then name-2.png, name-3.png...
    pages: dict[str, int] = field(default_factory=dict)
    # The files written for each page, by suffix ("png", "pdf", and "svg" if asked).
    formats: list[str] = field(default_factory=list)
