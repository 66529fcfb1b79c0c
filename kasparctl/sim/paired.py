"""Within-group (paired) designs by simulation: each group plays both conditions.

`simulate --power --paired`: a study of N groups in which every group plays
arm A and arm B, half of them A first (groups alternate: the first A first, the
second B first...), as `kasparctl plan` counterbalances them. Each simulated
study is analysed as the report analyses a real one: the caller passes the
analysis (`Analysis`: the report's paired cluster t,
kasparctl.research.inference.compare, with each group's two sessions entering
its one contribution together), and power is the share of studies whose p is below the level.

An order effect is optional: a group's second session is `order_effect` higher
on the measure (in its own unit: trials, a share, bits), as children who know
the game might teach faster; counterbalanced, it leaves the mean difference
alone and widens its spread. Beside the power, each design's rate of
rejection under the null (both conditions arm A, played twice by each group)
says whether the test holds its level at that size; a paired t-test of the
groups' own differences on the same studies is given beside it for reference.

The simulator's groups differ only by chance (one teacher model for all), so
a group's two sessions are no more alike than two groups' are: what pairing
gains here is sessions (N groups give N in each condition), not the smaller
spread real groups with lasting traits would give; for those, these figures are
conservative.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kasparctl.config import GameSettings
from kasparctl.sim.power import (
    MAX_SIMULATED_GROUPS,
    Arm,
    PowerError,
    PowerPoint,
    draw_power,
    t_two_sided_p,
)
from kasparctl.sim.simulate import SimulationError
from kasparctl.sim.studies import concatenate, group_sums, simulate_groups

FloatArray = NDArray[np.float64]
# Below this many groups the report gives no interval and no p (research.inference's
# MIN_CLUSTERS); the caller passes it in, as it passes the analysis.
DEFAULT_MIN_GROUPS = 4
# Studies analysed in one call: 500 resamples x 2,000 studies x 8 bytes x a few arrays.
STUDY_BLOCK = 2000

# (A's numerators, A's denominators, B's numerators, B's denominators), each (groups,
# studies), one column per simulated study; the groups' names; which arm each met
# first ("a" or "b"); the seed -> each study's two-sided p (None: no test).
Analysis = Callable[
    [FloatArray, FloatArray, FloatArray, FloatArray, list[str], dict[str, str]],
    list[float | None],
]


@dataclass(frozen=True)
class PairedPoint:
    """The power at one number of groups (each in both conditions), and the null rate."""

    groups: int
    power: float
    mc_error: float
    difference: float  # the mean difference A - B over the simulated studies
    null_rate: float  # the share of null studies (A against A) rejected
    a_first: int  # of the groups, how many play A first
    # The same studies by a paired t-test of the groups' own differences, for reference.
    power_t: float
    null_rate_t: float

    def plain(self) -> dict[str, float | int]:
        """As JSON-ready data."""
        return {
            "groups": self.groups,
            "power": self.power,
            "mc_error": self.mc_error,
            "mean_difference": self.difference,
            "null_rejection_rate": self.null_rate,
            "a_first": self.a_first,
            "power_paired_t": self.power_t,
            "null_rejection_rate_paired_t": self.null_rate_t,
        }


def _sums(arm: Arm, measure: str, count: int, rng: np.random.Generator) -> list[FloatArray]:
    table = concatenate(list(simulate_groups(count, arm.game, arm.params, arm.teacher, rng)))
    return list(group_sums(table, measure))


def paired_power(
    arms: tuple[Arm, Arm],
    measure: str,
    groups: Sequence[int],
    studies: int,
    level: float,
    seed: int | None,
    analyse: Analysis,
    order_effect: float = 0.0,
    min_groups: int = DEFAULT_MIN_GROUPS,
) -> list[PairedPoint]:
    """The power of the report's paired analysis, for each number of groups."""
    if not groups or min(groups) < min_groups:
        raise PowerError(
            f"--groups-per-arm: expected numbers >= {min_groups} with --paired (the report "
            f"gives no interval or p below {min_groups} groups), found {min(groups, default=0)}"
        )
    if not math.isfinite(order_effect):
        raise PowerError(f"--order-effect: expected a finite number, found {order_effect}")
    largest = max(groups)
    # Arm A, arm B, and arm A again for the null: three sessions' worth of groups.
    needed = 3 * studies * largest
    if needed > MAX_SIMULATED_GROUPS:
        raise PowerError(
            f"--studies {studies} x {largest} groups x 3 sessions (A, B, A again for the "
            f"null) = {needed:,} simulated sessions; expected at most "
            f"{MAX_SIMULATED_GROUPS:,} (fewer studies or groups)"
        )
    streams = np.random.SeedSequence(seed).spawn(3)
    simulated = [
        _sums(arm, measure, studies * largest, np.random.default_rng(stream))
        for arm, stream in zip((arms[0], arms[1], arms[0]), streams, strict=True)
    ]
    # (groups, studies): group i of study s is row i, column s, in every arm.
    shaped = [[v.reshape(studies, largest).T for v in pair] for pair in simulated]
    a_first = np.arange(largest) % 2 == 0
    points = []
    for n in sorted(set(groups)):
        names = [f"group {i + 1:03d}" for i in range(n)]
        first = {name: "a" if a_first[i] else "b" for i, name in enumerate(names)}
        rejected, rejected_t = [], []
        for (num_a, den_a), (num_b, den_b) in ((shaped[0], shaped[1]), (shaped[0], shaped[2])):
            num_a, den_a, num_b, den_b = (m[:n] for m in (num_a, den_a, num_b, den_b))
            # The session played second is `order_effect` higher: A's for B-first groups.
            second_a = ~a_first[:n, None]
            num_a = num_a + np.where(second_a, order_effect * den_a, 0.0)
            num_b = num_b + np.where(~second_a, order_effect * den_b, 0.0)
            # A block of studies at a time: the analysis holds (resamples x studies).
            p: list[float | None] = []
            for start in range(0, studies, STUDY_BLOCK):
                block = slice(start, start + STUDY_BLOCK)
                p += analyse(num_a[:, block], den_a[:, block], num_b[:, block], den_b[:, block],
                             names, first)  # fmt: skip
            rejected.append(np.array([q is not None and q < level for q in p]))
            rejected_t.append(np.nan_to_num(paired_t(num_a, den_a, num_b, den_b), nan=1.0) < level)
            if len(rejected) == 1:
                difference = _mean_difference(num_a, den_a, num_b, den_b)
        power = float(rejected[0].mean())
        points.append(
            PairedPoint(
                n,
                power,
                math.sqrt(power * (1 - power) / studies),
                difference,
                float(rejected[1].mean()),
                int(a_first[:n].sum()),
                float(rejected_t[0].mean()),
                float(rejected_t[1].mean()),
            )
        )
    return points


def paired_t(
    num_a: FloatArray, den_a: FloatArray, num_b: FloatArray, den_b: FloatArray
) -> FloatArray:
    """Each study's (column's) two-sided p of a paired t-test of its groups' own
    differences (a group without a value on a side left out); NaN below two groups."""
    with np.errstate(invalid="ignore", divide="ignore"):
        d = num_a / den_a - num_b / den_b
        d = np.where(np.isfinite(d), d, np.nan)
        n = np.isfinite(d).sum(axis=0).astype(np.float64)
        mean = np.nanmean(d, axis=0)
        sd = np.nanstd(d, axis=0, ddof=1)
        t = mean / (sd / np.sqrt(n))
    p = t_two_sided_p(t, n - 1)
    # No spread at all: equal sessions are no evidence, a constant difference is certain.
    p = np.where(sd == 0, np.where(mean == 0, 1.0, 0.0), p)
    result: FloatArray = np.where(n >= 2, p, np.nan)
    return result


def _mean_difference(
    num_a: FloatArray, den_a: FloatArray, num_b: FloatArray, den_b: FloatArray
) -> float:
    """A - B of each study's ratio of sums (as the report's point estimate), averaged."""
    with np.errstate(invalid="ignore", divide="ignore"):
        each = num_a.sum(axis=0) / den_a.sum(axis=0) - num_b.sum(axis=0) / den_b.sum(axis=0)
    return float(np.nanmean(each))


@dataclass(frozen=True)
class PairedAnswer:
    """The power curve of a within-group design: one point per number of groups."""

    name: str
    values: tuple[str, str]
    measure: str
    measure_words: str
    studies: int
    level: float
    seed: int
    order_effect: float
    replicates: int
    game: GameSettings
    labels: tuple[str, str]
    points: list[PairedPoint]

    @property
    def title(self) -> str:
        """What was compared and how."""
        return (
            f"{self.labels[0]} vs {self.labels[1]}, each group in both: {self.measure} "
            f"(the report's paired cluster t, level {self.level:g})"
        )

    def plain(self) -> dict[str, Any]:
        """One JSON object: the comparison, the design and the points."""
        return {
            "compare": {"name": self.name, "a": self.values[0], "b": self.values[1]},
            "design": "paired",
            "measure": self.measure,
            "level": self.level,
            "studies": self.studies,
            "replicates": self.replicates,
            "order_effect": self.order_effect,
            "seed": self.seed,
            "variant": self.game.variant,
            "points": [point.plain() for point in self.points],
        }

    def text(self) -> str:
        """Power and the null's rejection rate against the number of groups."""
        game = self.game
        order = f"; order effect {self.order_effect:g} on the second session" if (
            self.order_effect
        ) else ""
        lines = [
            f"power: {self.title}",
            f"{self.studies} simulated studies per design, "
            f"seed {self.seed}; {game.variant}, {len(game.targets)} targets, "
            f"{len(game.toys)} toys; measure: {self.measure_words}{order}",
            f"{'groups':>7} {'A first':>8} {'power':>7} {'MC error':>9} "
            f"{'mean difference (A - B)':>24} {'null rejected':>14} "
            f"{'paired t: power':>16} {'null rejected':>14}",
        ]
        for p in self.points:
            lines.append(
                f"{p.groups:>7} {p.a_first:>8} {p.power:>7.3f} {p.mc_error:>9.3f} "
                f"{p.difference:>24.4f} {p.null_rate:>14.3f} {p.power_t:>16.3f} "
                f"{p.null_rate_t:>14.3f}"
            )
        enough = next((p for p in self.points if p.power >= 0.8), None)
        if enough is None:
            lines.append("80 % power not reached: try more groups (--groups-per-arm)")
        else:
            lines.append(
                f"80 % power from {enough.groups} groups, each playing both conditions "
                f"(the report's cluster t, which there rejects {enough.null_rate:.3f} of null "
                f"studies at level {self.level:g})"
            )
        by_t = next((p.groups for p in self.points if p.power_t >= 0.8), None)
        lines.append(
            f"paired t-test: 80 % power from {by_t} groups"
            if by_t is not None
            else "paired t-test: 80 % power not reached"
        )
        return "\n".join(lines)

    def figure(self, kind: str) -> bytes:
        """The power curve drawn as `kind` (png or svg); needs matplotlib."""
        points = [PowerPoint(p.groups, p.power, p.mc_error, p.difference) for p in self.points]
        try:
            figure = draw_power(points, self.title, self.studies)
        except ImportError:
            raise SimulationError(
                "--figure: needs matplotlib, which is not installed: "
                "pip install 'kasparctl[report]'"
            ) from None
        buffer = io.BytesIO()
        figure.savefig(buffer, format=kind, dpi=120)
        return buffer.getvalue()
