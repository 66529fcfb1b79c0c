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


def resample_weights(clusters: int, replicates: int, rng: np.random.Generator) -> FloatArray:
    """How many times each cluster is drawn in each resample: (replicates, clusters)."""
    if clusters == 0:
        return np.zeros((replicates, 0))
    weights: FloatArray = rng.multinomial(
        clusters, np.full(clusters, 1.0 / clusters), replicates
    ).astype(np.float64)
    return weights


def _ratio(numerator: FloatArray, denominator: FloatArray) -> FloatArray:
    with np.errstate(divide="ignore", invalid="ignore"):
        result: FloatArray = np.where(denominator > 0, numerator / denominator, np.nan)
    return result


def _interval(values: FloatArray) -> tuple[float, float] | None:
    finite = values[np.isfinite(values)]
    # Too few resamples where the statistic exists: no honest interval.
    if len(finite) < 0.5 * len(values) or len(finite) == 0:
        return None
    tail = (1.0 - LEVEL) / 2 * 100
    low, high = np.percentile(finite, [tail, 100 - tail])
    return float(low), float(high)


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


def _estimate(
    numerator: FloatArray, denominator: FloatArray, weights: FloatArray
) -> tuple[Estimate, FloatArray]:
    total = float(denominator.sum())
    value = float(numerator.sum()) / total if total > 0 else None
    replicates = _ratio(weights @ numerator, weights @ denominator)
    interval = _interval(replicates) if len(numerator) >= 2 and value is not None else None
    low, high = interval if interval else (None, None)
    return Estimate(value, low, high, len(numerator)), replicates


@dataclass(frozen=True)
class Intervals:
    """A condition's measures with intervals, Fig. 2's points, and the histogram's shares."""

    measures: dict[str, Estimate]
    entropy_by_trial: list[Estimate]
    entropy_by_trial_n: list[int]
    trials_share: list[Estimate]  # share of learned problems per trials-to-learn bin
    trials_bins_start: int
    # The replicates, kept for contrasts: measure -> (replicates,)
    replicates: dict[str, FloatArray]
    cluster_values: dict[str, FloatArray]


def intervals(
    condition: Condition, replicates: int = DEFAULT_REPLICATES, seed: int = DEFAULT_SEED
) -> Intervals:
    """Every measure of a condition with its cluster-bootstrap interval."""
    totals = cluster_totals(condition)
    rng = np.random.default_rng([seed, _stable_hash(condition.label)])
    weights = resample_weights(totals.size, replicates, rng)
    measures: dict[str, Estimate] = {}
    kept: dict[str, FloatArray] = {}
    values: dict[str, FloatArray] = {}
    for measure in MEASURES:
        numerator, denominator = totals.numerators[measure.name], totals.denominators[measure.name]
        measures[measure.name], kept[measure.name] = _estimate(numerator, denominator, weights)
        values[measure.name] = _ratio(numerator, denominator)
    entropy = [
        _estimate(totals.entropy_sum[:, k], totals.entropy_count[:, k], weights)[0]
        for k in range(totals.entropy_sum.shape[1])
    ]
    counts = [int(n) for n in totals.entropy_count.sum(axis=0)]
    learned = totals.denominators["trials_mean"]
    shares = [
        _estimate(totals.learned_by_trials[:, b], learned, weights)[0]
        for b in range(totals.learned_by_trials.shape[1])
    ]
    return Intervals(measures, entropy, counts, shares, totals.bins_start, kept, values)


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


def _weighted_g(a: FloatArray, wa: FloatArray, b: FloatArray, wb: FloatArray) -> FloatArray:
    """Hedges' g of resampled clusters: each row of the weights is one resample."""

    def moments(x: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        ok = np.isfinite(x)
        x, w = x[ok], w[:, ok]
        n = w.sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            mean = (w @ x) / n
            var = (w @ (x * x) - n * mean * mean) / (n - 1)
        return n, mean, var

    na, ma, va = moments(a, wa)
    nb, mb, vb = moments(b, wb)
    with np.errstate(divide="ignore", invalid="ignore"):
        pooled = ((na - 1) * va + (nb - 1) * vb) / (na + nb - 2)
        g: FloatArray = (ma - mb) / np.sqrt(pooled) * (1 - 3 / (4 * (na + nb) - 9))
    return np.where(pooled > 1e-15, g, np.nan)


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


def compare(
    factor: str,
    labels: tuple[str, str],
    measure: str,
    samples: tuple[tuple[FloatArray, FloatArray], tuple[FloatArray, FloatArray]],
    unit: str,
    replicates: int,
    seed: int,
) -> Contrast:
    """Contrast A - B of a ratio measure, from each side's per-cluster (numerator, denominator)."""
    rng = np.random.default_rng([seed, _stable_hash(f"{factor}:{labels[0]}:{labels[1]}:{measure}")])
    (num_a, den_a), (num_b, den_b) = samples
    wa = resample_weights(len(num_a), replicates, rng)
    wb = resample_weights(len(num_b), replicates, rng)
    a, ra = _estimate(num_a, den_a, wa)
    b, rb = _estimate(num_b, den_b, wb)
    value = None if a.value is None or b.value is None else a.value - b.value
    both = len(num_a) >= 2 and len(num_b) >= 2 and value is not None
    interval = _interval(ra - rb) if both else None
    values_a, values_b = _ratio(num_a, den_a), _ratio(num_b, den_b)
    g = hedges_g(values_a, values_b)
    g_interval = _interval(_weighted_g(values_a, wa, values_b, wb)) if g is not None else None
    low, high = interval or (None, None)
    g_low, g_high = g_interval or (None, None)
    both_sides = len(num_a) + len(num_b)
    return Contrast(
        factor,
        labels[0],
        labels[1],
        measure,
        a.value,
        b.value,
        Estimate(value, low, high, both_sides),
        Estimate(g, g_low, g_high, both_sides),
        unit,
        len(num_a),
        len(num_b),
    )


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
    for index, first in enumerate(conditions):
        for second in conditions[index + 1 :]:
            factor = _one_factor(first, second)
            if factor is None:
                continue
            a, b = (first, second)
            if factor == "uncertainty mode" and a.factors and not a.factors.spoken:
                a, b = b, a  # spoken - silent
            for measure in CONDITION_MEASURES:
                ta, tb = totals[a.label], totals[b.label]
                contrasts.append(
                    compare(
                        factor,
                        (a.label, b.label),
                        measure,
                        (
                            (ta.numerators[measure], ta.denominators[measure]),
                            (tb.numerators[measure], tb.denominators[measure]),
                        ),
                        unit,
                        replicates,
                        seed,
                    )
                )
    return contrasts


def _one_factor(first: Condition, second: Condition) -> str | None:
    a, b = first.factors, second.factors
    if a is None or b is None or a.variant != b.variant:
        return None
    if a.profile == b.profile and a.spoken != b.spoken:
        return "uncertainty mode"
    if a.profile != b.profile and a.spoken == b.spoken:
        return "learner profile"
    return None


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
        sums = {name: [_child_sums(child) for child in levels[name]] for name in names}
        for index, a in enumerate(names):
            for b in names[index + 1 :]:
                for measure in CHILD_MEASURES:

                    def side(
                        level: str,
                        measure: str = measure,
                        sums: dict[str, list[dict[str, tuple[float, float]]]] = sums,
                    ) -> tuple[FloatArray, FloatArray]:
                        pairs = [child[measure] for child in sums[level]]
                        return (
                            np.array([float(n) for n, _ in pairs]),
                            np.array([float(d) for _, d in pairs]),
                        )

                    contrasts.append(
                        compare(
                            f"participant {attribute}",
                            (a, b),
                            measure,
                            (side(a), side(b)),
                            "child",
                            replicates,
                            seed,
                        )
                    )
    return contrasts
