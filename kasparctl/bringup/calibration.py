"""Calibration by hand: what the engineer showed becomes a proposed range, rest and direction.

The chosen joints go limp and the engineer moves each through its whole safe
travel, starting from rest and moving first the way its angle should grow (an
arm up, the mouth open, the head to the robot's left), and leaves it at rest.
From the positions seen, each joint gets:
- a range: the lowest and highest positions seen, each brought in by a margin,
  never beyond what the servo can reach;
- a rest position: where it was left, inside that range;
- a direction: flipped if the first movement went the wrong way; the proposed
  range and rest are then given in the flipped convention.
A joint moved less than MIN_SPAN_DEG keeps its configuration (it was probably
not moved at all). The proposal is shown as a diff of the configuration text,
written only when asked, with every comment kept.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from hal.servos.settings import JointSettings
from kasparctl.bringup.toml_patch import TomlValue, set_joint_keys

MIN_SPAN_DEG = 5.0  # a joint moved less than this was not demonstrated
FIRST_MOVE_DEG = 3.0  # the first excursion this far from the start gives the direction


@dataclass
class Sweep:
    """The positions seen of one joint while the engineer moved it."""

    joint: str
    start: float
    low: float = math.inf
    high: float = -math.inf
    last: float = math.nan
    first_move: float = 0.0  # sign of the first excursion beyond FIRST_MOVE_DEG (0: none yet)
    samples: int = 0

    def see(self, degrees: float) -> None:
        """One more sample."""
        self.low = min(self.low, degrees)
        self.high = max(self.high, degrees)
        self.last = degrees
        self.samples += 1
        if not self.first_move and abs(degrees - self.start) >= FIRST_MOVE_DEG:
            self.first_move = math.copysign(1.0, degrees - self.start)

    @property
    def span(self) -> float:
        """Degrees between the lowest and highest positions seen (0 without samples)."""
        return max(0.0, self.high - self.low) if self.samples else 0.0


@dataclass
class Proposal:
    """One joint's calibration: seen travel, current and proposed settings, and notes."""

    joint: str
    seen: tuple[float, float] | None
    current: dict[str, Any]
    proposed: dict[str, Any] = field(default_factory=dict)  # only the keys that change
    notes: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        """A JSON-ready dict (ranges as lists)."""
        def plain(values: Mapping[str, Any]) -> dict[str, Any]:
            return {k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}

        return {
            "joint": self.joint,
            "seen_deg": None if self.seen is None else [round(v, 2) for v in self.seen],
            "current": plain(self.current),
            "proposed": plain(self.proposed),
            "notes": self.notes,
        }


def propose(sweep: Sweep, joint: JointSettings, margin: float) -> Proposal:
    """The settings `sweep` shows for `joint`; unchanged ones are left out of `proposed`."""
    current: dict[str, Any] = {
        "range_deg": tuple(joint.range_deg),
        "rest_deg": joint.rest_deg,
        "direction": joint.direction,
    }
    seen = (sweep.low, sweep.high) if sweep.samples else None
    proposal = Proposal(joint.name, seen, current)
    if sweep.span < MIN_SPAN_DEG:
        proposal.notes.append(
            f"moved only {sweep.span:.1f} deg (less than {MIN_SPAN_DEG:.0f}): kept as configured"
        )
        return proposal
    flip = sweep.first_move < 0
    direction = -joint.direction if flip else joint.direction
    offset = joint.offset_deg

    def convert(degrees: float) -> float:
        # The same servo position in the other sign convention: 2 * offset - degrees.
        return 2 * offset - degrees if flip else degrees

    low, high = sorted((convert(sweep.low), convert(sweep.high)))
    low, high = low + margin, high - margin
    reach_low, reach_high = joint.servo.reach(direction, offset)
    if low < reach_low or high > reach_high:
        proposal.notes.append(
            f"brought within what a {joint.model} can reach [{reach_low:.1f}, {reach_high:.1f}]"
        )
    low, high = max(low, reach_low), min(high, reach_high)
    low, high = math.ceil(low * 10) / 10, math.floor(high * 10) / 10  # inward when rounding
    if high - low < 1.0:
        proposal.notes.append(
            f"travel of {sweep.span:.1f} deg leaves no range inside a {margin} deg margin: "
            "kept as configured"
        )
        return proposal
    rest = round(min(high, max(low, convert(sweep.last))), 1)
    if flip:
        proposal.notes.append(
            "first moved the other way: direction flipped (range and rest in the new sign)"
        )
    candidate: dict[str, TomlValue] = {"range_deg": (low, high), "rest_deg": rest}
    if direction != joint.direction:
        candidate["direction"] = direction
    proposal.proposed = {k: v for k, v in candidate.items() if v != current.get(k)}
    return proposal


def edit_config(text: str, proposals: list[Proposal]) -> str:
    """The configuration text with every proposal applied, comments and layout kept."""
    for proposal in proposals:
        if proposal.proposed:
            text = set_joint_keys(text, proposal.joint, proposal.proposed)
    return text


def diff(before: str, after: str, path: str) -> str:
    """A unified diff of the configuration, as `git diff` shows it."""
    return "".join(
        difflib.unified_diff(
            before.splitlines(keepends=True), after.splitlines(keepends=True),
            fromfile=f"{path} (now)", tofile=f"{path} (calibrated)",
        )
    )
