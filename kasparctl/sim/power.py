"""Study design by simulation: the power to detect a difference, against the number of groups.

A comparison has two arms (two learner profiles, two teacher models, two
error rates...). For each number of groups per arm, many studies are
simulated; each is analysed as a report would: one value per group (the
group is the unit, kasparctl.sim.studies.group_values) and a two-sided Welch
t-test of the two arms' group values at the chosen level. Power is the share
of simulated studies in which the test rejects; its Monte Carlo error is
sqrt(p (1 - p) / studies).

The groups are simulated once per arm, as many as the largest design needs;
a smaller design uses the first groups of each study, so the curve is smooth
(its points share groups) and costs one simulation per arm.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kasparctl.config import GameSettings
from kasparctl.learning.learner import LearnerParams
from kasparctl.sim.simulate import OptionError
from kasparctl.sim.studies import concatenate, group_values, simulate_groups
from kasparctl.sim.teacher import Teacher, TeacherModel

FloatArray = NDArray[np.float64]
DEFAULT_GROUPS = (4, 8, 12, 16, 24, 32, 48, 64)
DEFAULT_STUDIES = 1000
# groups x studies x arms simulated at most: about a minute on a small computer.
MAX_SIMULATED_GROUPS = 5_000_000


class PowerError(OptionError):
    """A design that cannot be simulated; the message names the option."""


@dataclass(frozen=True)
class Arm:
    """One side of the comparison: its label, game, learner and children."""

    label: str
    game: GameSettings
    params: LearnerParams
    teacher: Teacher | TeacherModel


@dataclass(frozen=True)
class PowerPoint:
    """The power at one number of groups per arm, with its Monte Carlo error."""

    groups: int
    power: float
    mc_error: float
    # The mean difference of the arms' group values (A - B), over the simulated studies.
    difference: float

    def plain(self) -> dict[str, float]:
        """As JSON-ready data."""
        return {
            "groups_per_arm": self.groups,
            "power": self.power,
            "mc_error": self.mc_error,
            "mean_difference": self.difference,
        }


def _betacf(a: FloatArray, b: FloatArray, x: FloatArray) -> FloatArray:
    """The continued fraction of the regularised incomplete beta (modified Lentz)."""
    tiny = 1e-300
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c = np.ones_like(x)
    d = 1.0 - qab * x / qap
    d = np.where(np.abs(d) < tiny, tiny, d)
    d = 1.0 / d
    h = d.copy()
    for m in range(1, 300):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = np.where(np.abs(d) < tiny, tiny, d)
        c = 1.0 + aa / c
        c = np.where(np.abs(c) < tiny, tiny, c)
        d = 1.0 / d
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = np.where(np.abs(d) < tiny, tiny, d)
        c = 1.0 + aa / c
        c = np.where(np.abs(c) < tiny, tiny, c)
        d = 1.0 / d
        delta = d * c
        h *= delta
        if np.all(np.abs(delta - 1.0) < 1e-14):
            break
    return h


def incomplete_beta(a: FloatArray, b: FloatArray, x: FloatArray) -> FloatArray:
    """The regularised incomplete beta function I_x(a, b), element-wise."""
    a, b, x = np.broadcast_arrays(
        np.asarray(a, dtype=np.float64),
        np.asarray(b, dtype=np.float64),
        np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0),
    )
    lgamma = np.vectorize(math.lgamma)
    with np.errstate(divide="ignore", invalid="ignore"):
        front = np.exp(lgamma(a + b) - lgamma(a) - lgamma(b) + a * np.log(x) + b * np.log1p(-x))
        direct = x < (a + 1.0) / (a + b + 2.0)
        small = front * _betacf(a, b, x) / a
        large = 1.0 - front * _betacf(b, a, 1.0 - x) / b
    result: FloatArray = np.where(direct, small, large)
    result = np.where(x <= 0.0, 0.0, np.where(x >= 1.0, 1.0, result))
    return result


def t_two_sided_p(t: FloatArray, df: FloatArray) -> FloatArray:
    """P(|T| >= |t|) for Student's t with `df` degrees of freedom (NaN where undefined)."""
    t = np.asarray(t, dtype=np.float64)
    df = np.asarray(df, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(df) & (df > 0)
    safe_t = np.where(ok, t, 0.0)
    safe_df = np.where(ok, df, 1.0)
    p = incomplete_beta(safe_df / 2.0, np.full_like(safe_df, 0.5), safe_df / (safe_df + safe_t**2))
    return np.where(ok, p, np.nan)


def welch(a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Welch's t-test of the rows of a and b (NaN values left out): (difference, p)."""
    na = np.isfinite(a).sum(axis=1).astype(np.float64)
    nb = np.isfinite(b).sum(axis=1).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        ma, mb = np.nanmean(a, axis=1), np.nanmean(b, axis=1)
        va, vb = np.nanvar(a, axis=1, ddof=1), np.nanvar(b, axis=1, ddof=1)
        sa, sb = va / na, vb / nb
        t = (ma - mb) / np.sqrt(sa + sb)
        df = (sa + sb) ** 2 / (sa**2 / (na - 1) + sb**2 / (nb - 1))
    # Two arms with no spread at all: equal means are no evidence, different ones are certain.
    p = t_two_sided_p(t, df)
    flat = (sa + sb) == 0
    p = np.where(flat, np.where(ma == mb, 1.0, 0.0), p)
    return ma - mb, p


def power_curve(
    arms: tuple[Arm, Arm],
    measure: str,
    groups: Sequence[int] = DEFAULT_GROUPS,
    studies: int = DEFAULT_STUDIES,
    level: float = 0.05,
    seed: int | None = None,
) -> list[PowerPoint]:
    """The power of a Welch t-test on group values, for each number of groups per arm."""
    if not groups or min(groups) < 2:
        raise PowerError("--groups-per-arm: expected numbers >= 2 (a t-test needs two groups)")
    largest = max(groups)
    needed = 2 * studies * largest
    if needed > MAX_SIMULATED_GROUPS:
        raise PowerError(
            f"--studies {studies} x {largest} groups x 2 arms = {needed:,} simulated groups; "
            f"expected at most {MAX_SIMULATED_GROUPS:,} (fewer studies or groups)"
        )
    streams = np.random.SeedSequence(seed).spawn(2)
    values = []
    for arm, stream in zip(arms, streams, strict=True):
        rng = np.random.default_rng(stream)
        table = concatenate(
            list(simulate_groups(studies * largest, arm.game, arm.params, arm.teacher, rng))
        )
        values.append(group_values(table, measure).reshape(studies, largest))
    points = []
    for n in sorted(set(groups)):
        difference, p = welch(values[0][:, :n], values[1][:, :n])
        rejected = np.nan_to_num(p, nan=1.0) < level
        power = float(rejected.mean())
        points.append(
            PowerPoint(
                n,
                power,
                math.sqrt(power * (1 - power) / studies),
                float(np.nanmean(difference)),
            )
        )
    return points


def draw_power(points: Sequence[PowerPoint], title: str, studies: int) -> Any:
    """The power curve: power against groups per arm, with 95 % Monte Carlo error bars.

    Needs matplotlib (ImportError otherwise); drawn on an Agg canvas, no pyplot.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(7.0, 4.4), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    groups = [p.groups for p in points]
    power = [p.power for p in points]
    errors = [1.96 * p.mc_error for p in points]
    axes.errorbar(groups, power, yerr=errors, marker="o", markersize=4, capsize=3, color="C0")
    for point in points:
        axes.annotate(
            f"{point.power:.2f}",
            (point.groups, point.power),
            textcoords="offset points",
            xytext=(5, -9),
            ha="left",
            fontsize=7,
        )
    axes.axhline(0.8, color="0.5", linestyle=":", linewidth=1)
    axes.text(groups[-1], 0.79, "80 %", fontsize=7, color="0.3", va="top", ha="right")
    axes.set_ylim(0, 1.1)
    axes.set_xlabel("groups per arm")
    axes.set_ylabel("power")
    axes.set_title(title, fontsize=9)
    axes.text(
        0.99,
        0.02,
        f"{studies} simulated studies per point; bars: 95 % Monte Carlo error",
        transform=axes.transAxes,
        ha="right",
        fontsize=7,
        color="0.3",
    )
    return figure
