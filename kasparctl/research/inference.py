"""Confidence intervals and contrasts whose unit is the group (or the child), not the trial.

Trials of one group are not independent (the same children, the same robot,
one learner per problem), so a trial-level interval would be far too narrow.
Every interval here is a cluster bootstrap: the clusters (groups of
children, or sessions; children for the per-child measures) are resampled
with replacement, and each statistic is recomputed from the resampled
clusters' totals (a ratio of sums, as the point estimate is). 95 %
percentile intervals from B resamples (2,000 by default, seeded, so a report
is reproducible).

A contrast between two conditions resamples each condition's clusters
independently; it gives the difference (in the measure's own unit) with its
interval, and Hedges' g (the difference of the clusters' own means over
their pooled standard deviation, small-sample corrected) with its interval.
With fewer than two clusters in a condition there is no interval (None).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kasparctl.learning.study_stats import count_errors
from kasparctl.research.children import ChildMeasures, Feedback
from kasparctl.research.conditions import Condition
from kasparctl.research.participants import Participants

FloatArray = NDArray[np.float64]
LEVEL = 0.95
DEFAULT_REPLICATES = 2000
DEFAULT_SEED = 0


@dataclass(frozen=True)
class Measure:
    """A statistic that is a ratio of per-cluster sums: numerator over denominator."""

    name: str
    label: str
    unit: str  # "trials", "bits", "share"


# The measures with intervals, in the order the summary shows them.
MEASURES = (
    Measure("trials_mean", "Trials to learn, mean", "trials"),
    Measure("problems_learned_rate", "Problems learned", "share"),
    Measure("first_guess_correct_rate", "First guess correct", "share"),
    Measure("perseverative_error_rate", "Perseverative errors per trial", "share"),
    Measure("win_shift_rate", "Win-shifts per trial", "share"),
    Measure("final_entropy_mean", "Final entropy, before the last guess", "bits"),
    Measure("final_entropy_after_mean", "Final entropy, after the last update", "bits"),
    Measure("wrong_feedback_rate", "Wrong feedback, of checked answers", "share"),
    Measure("wrong_green_rate", "False greens, of wrong guesses", "share"),
    Measure("wrong_red_rate", "False reds, of right guesses", "share"),
)


@dataclass(frozen=True)
class ClusterTotals:
    """Per-cluster numerators and denominators of every measure, and of Fig. 2's points."""

    clusters: list[str]
    numerators: dict[str, FloatArray]
    denominators: dict[str, FloatArray]
    # (clusters, guesses): the sum and count of entropies before guess k+1.
    entropy_sum: FloatArray
    entropy_count: FloatArray
    # (clusters, bins): learned problems by trials to learn, bins from `bins_start`.
    learned_by_trials: FloatArray
    bins_start: int

    @property
    def size(self) -> int:
        """How many clusters."""
        return len(self.clusters)


def cluster_totals(condition: Condition, longest: int | None = None) -> ClusterTotals:
    """Sum every measure's numerator and denominator by cluster."""
    clusters = condition.clusters or list(condition.feedback_by_cluster)
    position = {cluster: index for index, cluster in enumerate(clusters)}
    k = len(clusters)
    sums = {
        name: np.zeros(k)
        for name in (
            "learned",
            "problems",
            "trials_learned",
            "first_correct",
            "answer_known",
            "trials_total",
            "perseverative",
            "win_shift",
            "final_entropy",
            "final_entropy_after",
        )
    }
    lengths = [len(p.record.trials) for p in condition.problems]
    longest = longest or max(lengths, default=0)
    entropy_sum = np.zeros((k, longest))
    entropy_count = np.zeros((k, longest))
    learned_lengths = [
        n for p, n in zip(condition.problems, lengths, strict=True) if p.record.learned is not None
    ]
    low = min(learned_lengths, default=0)
    high = max(learned_lengths, default=-1)
    by_trials = np.zeros((k, max(high - low + 1, 0)))
    for problem, length in zip(condition.problems, lengths, strict=True):
        c = position[problem.cluster]
        record = problem.record
        trials = record.trials
        learned = record.learned is not None
        errors = count_errors(trials)
        sums["problems"][c] += 1
        sums["trials_total"][c] += length
        sums["perseverative"][c] += errors.perseverative
        sums["win_shift"][c] += errors.win_shift
        if trials[0].correct is not None:
            sums["answer_known"][c] += 1
            sums["first_correct"][c] += trials[0].correct is True
        if learned:
            sums["learned"][c] += 1
            sums["trials_learned"][c] += length
            sums["final_entropy"][c] += trials[-1].entropy
            sums["final_entropy_after"][c] += record.entropy_after
            by_trials[c, length - low] += 1
        n = min(length, longest)
        entropy_sum[c, :n] += [t.entropy for t in trials[:n]]
        entropy_count[c, :n] += 1
    feedback = [condition.feedback_by_cluster.get(cluster, Feedback()) for cluster in clusters]

    def tally(read: Callable[[Feedback], int]) -> FloatArray:
        return np.array([float(read(f)) for f in feedback])

    numerators = {
        "trials_mean": sums["trials_learned"],
        "problems_learned_rate": sums["learned"],
        "first_guess_correct_rate": sums["first_correct"],
        "perseverative_error_rate": sums["perseverative"],
        "win_shift_rate": sums["win_shift"],
        "final_entropy_mean": sums["final_entropy"],
        "final_entropy_after_mean": sums["final_entropy_after"],
        "wrong_feedback_rate": tally(lambda f: f.checked - f.right),
        "wrong_green_rate": tally(lambda f: f.wrong_green),
        "wrong_red_rate": tally(lambda f: f.wrong_red),
    }
    denominators = {
        "trials_mean": sums["learned"],
        "problems_learned_rate": sums["problems"],
        "first_guess_correct_rate": sums["answer_known"],
        "perseverative_error_rate": sums["trials_total"],
        "win_shift_rate": sums["trials_total"],
        "final_entropy_mean": sums["learned"],
        "final_entropy_after_mean": sums["learned"],
        "wrong_feedback_rate": tally(lambda f: f.checked),
        "wrong_green_rate": tally(lambda f: f.wrong_guesses),
        "wrong_red_rate": tally(lambda f: f.right_guesses),
    }
    return ClusterTotals(
        clusters, numerators, denominators, entropy_sum, entropy_count, by_trials, low
    )


# Resamples are drawn and reduced this many at a time, and statistics this many columns at
# a time: memory stays at (batch x clusters) + (replicates x block), whatever the study.
BATCH = 250
BLOCK = 256


def _batch_seeds(replicates: int, seed: int, salt: str) -> list[np.random.SeedSequence]:
    """One seed per batch of resamples: the same resamples for every column of a statistic."""
    batches = -(-replicates // BATCH)
    return np.random.SeedSequence([seed, _stable_hash(salt)]).spawn(batches)


def _weights(clusters: int, count: int, seed: np.random.SeedSequence) -> FloatArray:
    """How many times each cluster is drawn in each of `count` resamples: (count, clusters)."""
    if clusters == 0:
        return np.zeros((count, 0))
    rng = np.random.default_rng(seed)
    weights: FloatArray = rng.multinomial(
        clusters, np.full(clusters, 1.0 / clusters), count
    ).astype(np.float64)
    return weights


def _ratio(numerator: FloatArray, denominator: FloatArray) -> FloatArray:
    with np.errstate(divide="ignore", invalid="ignore"):
        result: FloatArray = np.where(denominator > 0, numerator / denominator, np.nan)
    return result


def _ratio_replicates(
    numerators: FloatArray,
    denominators: FloatArray,
    replicates: int,
    seeds: list[np.random.SeedSequence],
) -> FloatArray:
    """(replicates, columns): each column's ratio of resampled cluster sums."""
    clusters = numerators.shape[0]
    out = np.empty((replicates, numerators.shape[1]))
    for index, seed in enumerate(seeds):
        start = index * BATCH
        count = min(BATCH, replicates - start)
        weights = _weights(clusters, count, seed)
        out[start : start + count] = _ratio(weights @ numerators, weights @ denominators)
    return out


def _intervals(values: FloatArray) -> list[tuple[float, float] | None]:
    """Each column's 95 % percentile interval (None where too few resamples have a value)."""
    tail = (1.0 - LEVEL) / 2 * 100
    found: list[tuple[float, float] | None] = []
    for column in values.T:
        finite = column[np.isfinite(column)]
        # Too few resamples where the statistic exists: no honest interval.
        if len(finite) == 0 or len(finite) < 0.5 * len(column):
            found.append(None)
            continue
        low, high = np.percentile(finite, [tail, 100 - tail])
        found.append((float(low), float(high)))
    return found


@dataclass(frozen=True)
class Estimate:
    """A point estimate, its interval (None without one) and the clusters it rests on."""

    value: float | None
    low: float | None
    high: float | None
    clusters: int

    def plain(self) -> dict[str, float | int | None]:
        """As JSON-ready data."""
        return {"value": self.value, "low": self.low, "high": self.high, "clusters": self.clusters}


def estimates(
    numerators: FloatArray,
    denominators: FloatArray,
    replicates: int,
    seed: int,
    salt: str,
) -> list[Estimate]:
    """Each column's ratio of sums over clusters (rows), with its cluster-bootstrap interval.

    Columns are resampled a block at a time with the same resamples, so a thousand
    columns (Fig. 2's guesses) cost no more memory than ten.
    """
    clusters, columns = numerators.shape
    totals = denominators.sum(axis=0)
    values = [
        float(numerators[:, j].sum() / totals[j]) if totals[j] > 0 else None for j in range(columns)
    ]
    found: list[tuple[float, float] | None] = [None] * columns
    if clusters >= 2:
        seeds = _batch_seeds(replicates, seed, salt)
        for start in range(0, columns, BLOCK):
            block = slice(start, start + BLOCK)
            resampled = _ratio_replicates(
                numerators[:, block], denominators[:, block], replicates, seeds
            )
            found[block] = _intervals(resampled)
    return [
        Estimate(
            value,
            None if interval is None or value is None else interval[0],
            None if interval is None or value is None else interval[1],
            clusters,
        )
        for value, interval in zip(values, found, strict=True)
    ]


@dataclass(frozen=True)
class Intervals:
    """A condition's measures with intervals, Fig. 2's points, and the histogram's shares."""

    measures: dict[str, Estimate]
    entropy_by_trial: list[Estimate]
    entropy_by_trial_n: list[int]
    trials_share: list[Estimate]  # share of learned problems per trials-to-learn bin
    trials_bins_start: int


def intervals(
    condition: Condition, replicates: int = DEFAULT_REPLICATES, seed: int = DEFAULT_SEED
) -> Intervals:
    """Every measure of a condition with its cluster-bootstrap interval."""
    totals = cluster_totals(condition)
    salt = condition.label
    names = [m.name for m in MEASURES]
    measured = estimates(
        np.column_stack([totals.numerators[n] for n in names]),
        np.column_stack([totals.denominators[n] for n in names]),
        replicates,
        seed,
        salt,
    )
    entropy = estimates(totals.entropy_sum, totals.entropy_count, replicates, seed, salt)
    learned = totals.denominators["trials_mean"]
    bins = totals.learned_by_trials.shape[1]
    shares = estimates(
        totals.learned_by_trials,
        np.repeat(learned[:, None], bins, axis=1),
        replicates,
        seed,
        salt,
    )
    counts = [int(n) for n in totals.entropy_count.sum(axis=0)]
    return Intervals(
        dict(zip(names, measured, strict=True)), entropy, counts, shares, totals.bins_start
    )


def _stable_hash(text: str) -> int:
    # Python's hash() changes between runs; a report must not.
    return int.from_bytes(text.encode()[:32].ljust(32, b"\0"), "big") % (1 << 63)


def hedges_g(a: FloatArray, b: FloatArray) -> float | None:
    """Hedges' g of two samples of cluster values (NaN ones left out); None if undefined."""
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    na, nb = len(a), len(b)
    if na < 2 or nb < 2:
        return None
    pooled = ((na - 1) * a.var(ddof=1) + (nb - 1) * b.var(ddof=1)) / (na + nb - 2)
    if pooled <= 0:
        return None
    correction = 1 - 3 / (4 * (na + nb) - 9)
    return float((a.mean() - b.mean()) / math.sqrt(pooled) * correction)


def _moments(values: FloatArray, weights: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per resample and column: count, mean and variance of the drawn clusters' own values."""
    present = np.isfinite(values).astype(np.float64)
    filled = np.nan_to_num(values)
    n = weights @ present
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (weights @ filled) / n
        variance = (weights @ (filled * filled) - n * mean * mean) / (n - 1)
    return n, mean, variance


@dataclass(frozen=True)
class Contrast:
    """One measure compared between two conditions (or two levels of an attribute)."""

    factor: str
    a: str
    b: str
    measure: str
    a_value: float | None
    b_value: float | None
    difference: Estimate
    hedges_g: Estimate
    unit: str  # what a cluster is: "group", "session" or "child"
    clusters_a: int
    clusters_b: int

    def plain(self) -> dict[str, object]:
        """As JSON-ready data."""
        return {
            "factor": self.factor,
            "a": self.a,
            "b": self.b,
            "measure": self.measure,
            "a_value": self.a_value,
            "b_value": self.b_value,
            "difference": self.difference.value,
            "difference_low": self.difference.low,
            "difference_high": self.difference.high,
            "hedges_g": self.hedges_g.value,
            "hedges_g_low": self.hedges_g.low,
            "hedges_g_high": self.hedges_g.high,
            "clusters_a": self.clusters_a,
            "clusters_b": self.clusters_b,
            "unit": self.unit,
        }


Side = tuple[FloatArray, FloatArray]  # (clusters x measures) numerators, denominators


def compare(
    factor: str,
    labels: tuple[str, str],
    measures: Sequence[str],
    sides: tuple[Side, Side],
    unit: str,
    replicates: int,
    seed: int,
) -> list[Contrast]:
    """Contrasts A - B of ratio measures, from each side's per-cluster sums.

    Each side's clusters are resampled on their own (batch by batch); the
    difference of the ratios and Hedges' g of the clusters' own values get
    their 95 % percentile intervals from the same resamples.
    """
    (num_a, den_a), (num_b, den_b) = sides
    ka, kb = num_a.shape[0], num_b.shape[0]
    value_a = _ratio(num_a.sum(axis=0), den_a.sum(axis=0))
    value_b = _ratio(num_b.sum(axis=0), den_b.sum(axis=0))
    own_a, own_b = _ratio(num_a, den_a), _ratio(num_b, den_b)
    g = [hedges_g(own_a[:, j], own_b[:, j]) for j in range(len(measures))]
    differences = np.full((replicates, len(measures)), np.nan)
    gs = np.full((replicates, len(measures)), np.nan)
    if ka >= 2 and kb >= 2:
        salt = f"{factor}:{labels[0]}:{labels[1]}"
        seeds_a = _batch_seeds(replicates, seed, salt + ":a")
        seeds_b = _batch_seeds(replicates, seed, salt + ":b")
        for index, (seed_a, seed_b) in enumerate(zip(seeds_a, seeds_b, strict=True)):
            start = index * BATCH
            count = min(BATCH, replicates - start)
            wa, wb = _weights(ka, count, seed_a), _weights(kb, count, seed_b)
            rows = slice(start, start + count)
            differences[rows] = _ratio(wa @ num_a, wa @ den_a) - _ratio(wb @ num_b, wb @ den_b)
            na, ma, va = _moments(own_a, wa)
            nb, mb, vb = _moments(own_b, wb)
            with np.errstate(divide="ignore", invalid="ignore"):
                pooled = ((na - 1) * va + (nb - 1) * vb) / (na + nb - 2)
                effect = (ma - mb) / np.sqrt(pooled) * (1 - 3 / (4 * (na + nb) - 9))
            gs[rows] = np.where(pooled > 1e-15, effect, np.nan)
    difference_intervals = _intervals(differences)
    g_intervals = _intervals(gs)
    contrasts = []
    for j, measure in enumerate(measures):
        a_value = None if np.isnan(value_a[j]) else float(value_a[j])
        b_value = None if np.isnan(value_b[j]) else float(value_b[j])
        difference = None if a_value is None or b_value is None else a_value - b_value
        low, high = difference_intervals[j] or (None, None)
        g_low, g_high = g_intervals[j] or (None, None)
        if difference is None:
            low = high = None
        if g[j] is None:
            g_low = g_high = None
        contrasts.append(
            Contrast(
                factor,
                labels[0],
                labels[1],
                measure,
                a_value,
                b_value,
                Estimate(difference, low, high, ka + kb),
                Estimate(g[j], g_low, g_high, ka + kb),
                unit,
                ka,
                kb,
            )
        )
    return contrasts


# The measures contrasted between conditions: the learner's, and the children's answers.
CONDITION_MEASURES = (
    "trials_mean",
    "first_guess_correct_rate",
    "perseverative_error_rate",
    "win_shift_rate",
    "final_entropy_mean",
    "wrong_feedback_rate",
)


def condition_contrasts(
    conditions: Sequence[Condition], unit: str, replicates: int, seed: int
) -> list[Contrast]:
    """Every pair of conditions that differ in one factor: uncertainty mode, or learner profile."""
    contrasts = []
    totals = {c.label: cluster_totals(c) for c in conditions}

    def side(label: str) -> Side:
        t = totals[label]
        return (
            np.column_stack([t.numerators[m] for m in CONDITION_MEASURES]),
            np.column_stack([t.denominators[m] for m in CONDITION_MEASURES]),
        )

    for index, first in enumerate(conditions):
        for second in conditions[index + 1 :]:
            factor = _one_factor(first, second)
            if factor is None:
                continue
            a, b = first, second
            if factor == "uncertainty mode" and _shows_less(a, b):
                a, b = b, a  # the mode that shows more first: spoken - silent, both - body
            contrasts += compare(
                factor,
                (a.label, b.label),
                CONDITION_MEASURES,
                (side(a.label), side(b.label)),
                unit,
                replicates,
                seed,
            )
    return contrasts


def _one_factor(first: Condition, second: Condition) -> str | None:
    a, b = first.factors, second.factors
    if a is None or b is None or a.variant != b.variant:
        return None
    if a.profile == b.profile and a.uncertainty != b.uncertainty:
        return "uncertainty mode"
    if a.profile != b.profile and a.uncertainty == b.uncertainty:
        return "learner profile"
    return None


# Uncertainty modes from the one that shows the most: a contrast's A is the earlier.
MODE_ORDER = ("both", "spoken", "body", "none")


def _shows_less(first: Condition, second: Condition) -> bool:
    """Whether `first`'s uncertainty mode comes after `second`'s in MODE_ORDER."""
    assert first.factors is not None and second.factors is not None

    def place(mode: str) -> int:
        return MODE_ORDER.index(mode) if mode in MODE_ORDER else len(MODE_ORDER)

    return place(first.factors.uncertainty) > place(second.factors.uncertainty)


def _child_sums(child: ChildMeasures) -> dict[str, tuple[float, float]]:
    """Each per-child measure's numerator and denominator."""
    f = child.feedback
    times = [t for values in child.reaction_times.values() for t in values]
    return {
        "wrong_feedback_rate": (f.checked - f.right, f.checked),
        "false_green_rate": (f.wrong_green, f.wrong_guesses),
        "false_red_rate": (f.wrong_red, f.right_guesses),
        "reaction_time_mean": (sum(times), len(times)),
        "prompts_per_answer": (child.prompts, f.answers),
        "extra_presses_per_answer": (child.extra_presses, f.answers),
        "undos_per_answer": (child.undos, f.answers),
    }


# Per-child measures contrasted between levels of a participant attribute.
CHILD_MEASURES = (
    "wrong_feedback_rate",
    "false_green_rate",
    "false_red_rate",
    "reaction_time_mean",
    "prompts_per_answer",
    "extra_presses_per_answer",
    "undos_per_answer",
)


def attribute_contrasts(
    children: Sequence[ChildMeasures],
    participants: Participants,
    replicates: int,
    seed: int,
    max_levels: int = 4,
) -> list[Contrast]:
    """Children compared by each category of participants.csv (each pair of its levels).

    The unit is the child: children are resampled, not answers. Only children with
    a participant code (and a row in the file) take part.
    """
    contrasts = []
    for attribute in participants.categories():
        levels: dict[str, list[ChildMeasures]] = {}
        for child in children:
            level = participants.attributes(child.participant).get(attribute)
            if child.participant is not None and level is not None:
                levels.setdefault(str(level), []).append(child)
        names = sorted(levels)
        if not 2 <= len(names) <= max_levels:
            continue

        def side(level: str, levels: dict[str, list[ChildMeasures]] = levels) -> Side:
            sums = [_child_sums(child) for child in levels[level]]
            return (
                np.array([[float(c[m][0]) for m in CHILD_MEASURES] for c in sums]),
                np.array([[float(c[m][1]) for m in CHILD_MEASURES] for c in sums]),
            )

        for index, a in enumerate(names):
            for b in names[index + 1 :]:
                contrasts += compare(
                    f"participant {attribute}",
                    (a, b),
                    CHILD_MEASURES,
                    (side(a), side(b)),
                    "child",
                    replicates,
                    seed,
                )
    return contrasts
