"""Confidence intervals and contrasts whose unit is the group (or the child), not the trial.

Trials of one group are not independent (the same children, the same robot,
one learner per problem), so a trial-level interval would be far too narrow.
A condition's intervals are a cluster bootstrap: the clusters (groups of
children, or sessions; children for the per-child measures) are resampled
with replacement, and each statistic is recomputed from the resampled
clusters' totals (a ratio of sums, as the point estimate is); the 95 %
percentile interval from B resamples (2,000 by default, seeded, so a report
is reproducible) is stretched for its number of clusters (`expansion`), as a
bootstrap over few clusters is too narrow.

A contrast between two conditions is a cluster-level t: the difference's CR2
cluster-robust standard error with Satterthwaite's degrees of freedom (k - 1
when the same clusters meet both sides, a paired analysis, with the order
reported; Welch's for independent clusters). It gives the difference (in the
measure's own unit) with its interval, Hedges' g (that same difference over
the pooled SD of the clusters' own values, small-sample corrected) with the
interval in those units, and the t's p, Holm-adjusted over a report's
contrasts (`holm`). Children go with their groups. Below MIN_CLUSTERS clusters
with data (a side) there is no interval (None). The coverage and false
positives, 4 to 20 clusters: bench/bench_inference.py.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from kasparctl.learning.study_stats import count_errors
from kasparctl.research import student_t
from kasparctl.research.children import ChildMeasures, Feedback
from kasparctl.research.conditions import Condition, cluster_of
from kasparctl.research.participants import Participants

FloatArray = NDArray[np.float64]
LEVEL = 0.95
DEFAULT_REPLICATES = 2000
DEFAULT_SEED = 0
# Below this many clusters (on a side of a contrast) no interval is given: a bootstrap over
# two clusters has three outcomes, over three ten, and a t with 1 or 2 df is all tail.
MIN_CLUSTERS = 4


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


def expansion(numerators: FloatArray, denominators: FloatArray) -> float:
    """How far a k-cluster percentile interval's half-widths are stretched (k >= 2 with data).

    The bootstrap's variance of a ratio of sums is about the plug-in one, sum e_g^2 / N^2
    (e_g a cluster's residual from the ratio), which over few clusters is too small: the
    CR2 variance divides each e_g^2 by 1 - h_g (h_g the cluster's share of N; k/(k-1) for
    equal clusters), and a t with k - 1 df replaces the normal's quantile. At 4 clusters
    the plain interval covered 78 %, stretched 94 % (bench/bench_inference.py).
    """
    present = denominators > 0
    k = int(present.sum())
    total = float(denominators.sum())
    residual = numerators - float(numerators.sum()) / total * denominators
    plug_in = float(np.sum(residual**2))
    share = denominators[present] / total
    corrected = float(np.sum(residual[present] ** 2 / (1.0 - np.minimum(share, 1 - 1e-12))))
    ratio = math.sqrt(corrected / plug_in) if plug_in > 0 else math.sqrt(k / (k - 1))
    z = student_t.quantile(1.0 - (1.0 - LEVEL) / 2, 1e9)
    return ratio * student_t.quantile(1.0 - (1.0 - LEVEL) / 2, k - 1) / z


def estimates(
    numerators: FloatArray,
    denominators: FloatArray,
    replicates: int,
    seed: int,
    salt: str,
    bounds: tuple[FloatArray, FloatArray] | None = None,
) -> list[Estimate]:
    """Each column's ratio of sums over clusters (rows), with its cluster-bootstrap interval.

    The percentile interval is stretched about the estimate for the column's number of
    clusters with data (`expansion`), then kept within `bounds` (each column's lowest and
    highest possible value: a share within 0 and 1). No interval below MIN_CLUSTERS
    clusters with data. Columns are resampled a block at a time with the same
    resamples, so a thousand columns (Fig. 2's guesses) cost no more memory than ten.
    """
    clusters, columns = numerators.shape
    totals = denominators.sum(axis=0)
    with_data = (denominators > 0).sum(axis=0)
    values = [
        float(numerators[:, j].sum() / totals[j]) if totals[j] > 0 else None for j in range(columns)
    ]
    found: list[tuple[float, float] | None] = [None] * columns
    if clusters >= MIN_CLUSTERS:
        seeds = _batch_seeds(replicates, seed, salt)
        for start in range(0, columns, BLOCK):
            block = slice(start, start + BLOCK)
            resampled = _ratio_replicates(
                numerators[:, block], denominators[:, block], replicates, seeds
            )
            found[block] = _intervals(resampled)
    result = []
    for j, (value, interval) in enumerate(zip(values, found, strict=True)):
        k = int(with_data[j])
        if value is None or interval is None or k < MIN_CLUSTERS:
            result.append(Estimate(value, None, None, clusters))
            continue
        factor = expansion(numerators[:, j], denominators[:, j])
        low = value - factor * (value - interval[0])
        high = value + factor * (interval[1] - value)
        if bounds is not None:
            low, high = max(low, float(bounds[0][j])), min(high, float(bounds[1][j]))
        result.append(Estimate(value, low, high, clusters))
    return result


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
    # A stretched interval stays where the measure can be: shares within 0 and 1, counts,
    # trials and bits at or above 0.
    highest = np.array([1.0 if m.unit == "share" else math.inf for m in MEASURES])
    measured = estimates(
        np.column_stack([totals.numerators[n] for n in names]),
        np.column_stack([totals.denominators[n] for n in names]),
        replicates,
        seed,
        salt,
        (np.zeros(len(names)), highest),
    )
    guesses = totals.entropy_sum.shape[1]
    entropy = estimates(
        totals.entropy_sum,
        totals.entropy_count,
        replicates,
        seed,
        salt,
        (np.zeros(guesses), np.full(guesses, math.inf)),
    )
    learned = totals.denominators["trials_mean"]
    bins = totals.learned_by_trials.shape[1]
    shares = estimates(
        totals.learned_by_trials,
        np.repeat(learned[:, None], bins, axis=1),
        replicates,
        seed,
        salt,
        (np.zeros(bins), np.ones(bins)),
    )
    counts = [int(n) for n in totals.entropy_count.sum(axis=0)]
    return Intervals(
        dict(zip(names, measured, strict=True)), entropy, counts, shares, totals.bins_start
    )


def _stable_hash(text: str) -> int:
    # Python's hash() changes between runs; a report must not. The whole salt is hashed:
    # a prefix would give the ":a" and ":b" sides of a contrast the same resamples.
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "big") % (1 << 63)


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


def standardised(
    difference: FloatArray,
    own_a: FloatArray,
    own_b: FloatArray,
    rows_a: FloatArray,
    rows_b: FloatArray,
) -> FloatArray:
    """Hedges' g with the contrast's own difference on top (so the two never point apart).

    The difference (of ratios of sums) is divided by the pooled standard deviation of the
    rows' own values, weighted by how often each row is drawn, small-sample corrected.
    `rows_a` and `rows_b` are (resamples, rows) draw counts; `difference` is (resamples, columns).
    """
    na, _, va = _moments(own_a, rows_a)
    nb, _, vb = _moments(own_b, rows_b)
    with np.errstate(divide="ignore", invalid="ignore"):
        pooled = ((na - 1) * va + (nb - 1) * vb) / (na + nb - 2)
        effect = difference / np.sqrt(pooled) * (1 - 3 / (4 * (na + nb) - 9))
    result: FloatArray = np.where(pooled > 1e-15, effect, np.nan)
    return result


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
    # Whether the same clusters met both sides (a paired analysis: their two sides differenced).
    paired: bool = False
    shared: int = 0  # clusters on both sides
    # Two-sided t p of "no difference", and after Holm's correction over the report.
    p: float | None = None
    p_adjusted: float | None = None
    # Paired: how many shared clusters met A first, B first, and the difference in each.
    a_first: int = 0
    b_first: int = 0
    difference_a_first: float | None = None
    difference_b_first: float | None = None
    # The t's degrees of freedom (Satterthwaite; k - 1 paired); None without an interval.
    df: float | None = None

    @property
    def significant(self) -> bool | None:
        """Whether the Holm-adjusted p is below 5 % (None without a p)."""
        return None if self.p_adjusted is None else self.p_adjusted < 1 - LEVEL

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
            "paired": self.paired,
            "shared_clusters": self.shared,
            "p": self.p,
            "p_holm": self.p_adjusted,
            "significant_holm": self.significant,
            "order_a_first": self.a_first,
            "order_b_first": self.b_first,
            "difference_a_first": self.difference_a_first,
            "difference_b_first": self.difference_b_first,
            "df": self.df,
        }


Side = tuple[FloatArray, FloatArray]  # (rows x measures) numerators, denominators
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class Spread:
    """A difference's cluster-robust standard error, its degrees of freedom, and its clusters."""

    se: float
    df: float
    clusters_a: int  # clusters with data on each side (a non-zero denominator)
    clusters_b: int


def _leveraged(
    numerators: FloatArray, denominators: FloatArray, codes: IntArray, count: int
) -> tuple[FloatArray, FloatArray]:
    """Per cluster: the residual sum over the side's total, leverage-corrected; and its count.

    The ratio of sums is the OLS fit of each answer on its side, so a cluster's share of the
    side's total is its leverage h; dividing its residual by sqrt(1 - h) (CR2, Bell and
    McCaffrey 2002) undoes the shrinking of the residuals of a cluster that pulls the fit.
    """
    total = float(denominators.sum())
    rate = float(numerators.sum()) / total
    residual = np.bincount(codes, numerators - rate * denominators, minlength=count)
    size = np.bincount(codes, denominators, minlength=count)
    with np.errstate(divide="ignore", invalid="ignore"):
        adjusted: FloatArray = residual / np.sqrt(1.0 - size / total) / total
    kept: FloatArray = np.where(size > 0, adjusted, 0.0)
    return kept, size.astype(np.float64)


def _spread(
    a: tuple[FloatArray, FloatArray, IntArray],
    b: tuple[FloatArray, FloatArray, IntArray],
    count: int,
) -> Spread | None:
    """The cluster-robust (CR2) SE of a ratio difference, with Satterthwaite's df.

    Each cluster contributes its leverage-corrected residuals of side A minus side B (a
    paired cluster both, so its two sides' noise cancels as it does in the difference).
    Clusters on both sides, on A only and on B only are three samples of such contributions;
    the df combine theirs (k - 1 each) as Welch does: k - 1 when every cluster is paired,
    Welch-Satterthwaite for independent groups. None when either side lacks data.
    """
    (num_a, den_a, codes_a), (num_b, den_b, codes_b) = a, b
    if den_a.sum() <= 0 or den_b.sum() <= 0:
        return None
    part_a, size_a = _leveraged(num_a, den_a, codes_a, count)
    part_b, size_b = _leveraged(num_b, den_b, codes_b, count)
    in_a, in_b = size_a > 0, size_b > 0
    if not (np.all(np.isfinite(part_a)) and np.all(np.isfinite(part_b))):
        return None  # one cluster holds a whole side: no residual to measure spread by
    contribution = part_a - part_b
    variance = float(np.sum(contribution**2))
    denominator = 0.0
    for members in (in_a & in_b, in_a & ~in_b, ~in_a & in_b):
        k = int(members.sum())
        if k:
            denominator += float(np.sum(contribution[members] ** 2)) ** 2 / max(k - 1, 1)
    df = variance**2 / denominator if denominator > 0 else math.inf
    return Spread(math.sqrt(variance), df, int(in_a.sum()), int(in_b.sum()))


def _t_test(difference: float, spread: Spread) -> tuple[float, float, float]:
    """The 95 % interval and two-sided p of a difference, from t with the spread's df."""
    if spread.se == 0.0:
        # Every cluster sits on its side's rate: no spread, the difference is all there is.
        return difference, difference, 1.0 if difference == 0.0 else 0.0
    df = min(spread.df, 1e6)
    half = student_t.quantile(1.0 - (1.0 - LEVEL) / 2, df) * spread.se
    return difference - half, difference + half, student_t.two_sided_p(difference / spread.se, df)


def compare(
    factor: str,
    labels: tuple[str, str],
    measures: Sequence[str],
    sides: tuple[Side, Side],
    unit: str,
    replicates: int,
    seed: int,
    clusters: tuple[Sequence[str], Sequence[str]] | None = None,
    first: dict[str, str] | None = None,
) -> list[Contrast]:
    """Contrasts A - B of ratio measures, from each side's per-row sums.

    `clusters` names each row's cluster (default: every row its own cluster); a cluster
    on both sides (the same group in both conditions) makes the contrast paired. The
    interval and p are a cluster-level t: the CR2 cluster-robust standard error with
    Satterthwaite's degrees of freedom (`_spread`), small-sample correct from 4 clusters
    a side, as a percentile bootstrap over so few clusters is not. Hedges' g is the same
    difference over the pooled SD of the rows' own values, its interval the difference's
    in those units. No interval or p below MIN_CLUSTERS (with data) a side.
    `replicates` and `seed` are kept for callers; a contrast draws no resamples.
    `first` names, for clusters on both sides, which side ("a" or "b") they met first:
    the order is reported (counts, and the difference within each order).
    """
    (num_a, den_a), (num_b, den_b) = sides
    rows_a, rows_b = num_a.shape[0], num_b.shape[0]
    names_a = list(clusters[0]) if clusters else [f"a{i}" for i in range(rows_a)]
    names_b = list(clusters[1]) if clusters else [f"b{i}" for i in range(rows_b)]
    shared = sorted(set(names_a) & set(names_b))
    paired = bool(shared)
    ka, kb = len(set(names_a)), len(set(names_b))
    value_a = _ratio(num_a.sum(axis=0), den_a.sum(axis=0))
    value_b = _ratio(num_b.sum(axis=0), den_b.sum(axis=0))
    own_a, own_b = _ratio(num_a, den_a), _ratio(num_b, den_b)
    ones_a, ones_b = np.ones((1, rows_a)), np.ones((1, rows_b))
    # Hedges' g per unit of difference: g is the difference times it, and so is its interval.
    per_unit = standardised(np.ones((1, len(measures))), own_a, own_b, ones_a, ones_b)[0]
    union = sorted(set(names_a) | set(names_b))
    place = {name: i for i, name in enumerate(union)}
    codes_a = np.array([place[n] for n in names_a], dtype=np.int64)
    codes_b = np.array([place[n] for n in names_b], dtype=np.int64)
    by_order: dict[str, FloatArray] = {}
    for order in ("a", "b"):
        met = {n for n in shared if (first or {}).get(n) == order}
        rows_a_o = [i for i, n in enumerate(names_a) if n in met]
        rows_b_o = [i for i, n in enumerate(names_b) if n in met]
        by_order[order] = _ratio(num_a[rows_a_o].sum(axis=0), den_a[rows_a_o].sum(axis=0)) - _ratio(
            num_b[rows_b_o].sum(axis=0), den_b[rows_b_o].sum(axis=0)
        )
    orders = [(first or {}).get(n) for n in shared]
    contrasts = []
    for j, measure in enumerate(measures):
        a_value = None if np.isnan(value_a[j]) else float(value_a[j])
        b_value = None if np.isnan(value_b[j]) else float(value_b[j])
        difference = None if a_value is None or b_value is None else a_value - b_value
        scale = float(per_unit[j])
        g_value = None if difference is None or not np.isfinite(scale) else difference * scale
        low = high = p = df = g_low = g_high = None
        spread = None
        if difference is not None and ka >= MIN_CLUSTERS and kb >= MIN_CLUSTERS:
            spread = _spread(
                (num_a[:, j], den_a[:, j], codes_a), (num_b[:, j], den_b[:, j], codes_b), len(union)
            )
        if (
            difference is not None
            and spread is not None
            and min(spread.clusters_a, spread.clusters_b) >= MIN_CLUSTERS
        ):
            low, high, p = _t_test(difference, spread)
            df = spread.df if math.isfinite(spread.df) else None
            if g_value is not None:
                g_low, g_high = low * scale, high * scale
        contrasts.append(
            Contrast(
                factor,
                labels[0],
                labels[1],
                measure,
                a_value,
                b_value,
                Estimate(difference, low, high, ka + kb - len(shared)),
                Estimate(g_value, g_low, g_high, ka + kb - len(shared)),
                unit,
                ka,
                kb,
                paired,
                len(shared),
                p,
                None,
                orders.count("a"),
                orders.count("b"),
                _finite(by_order["a"][j]),
                _finite(by_order["b"][j]),
                df,
            )
        )
    return contrasts


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def holm(contrasts: Sequence[Contrast]) -> list[Contrast]:
    """The contrasts with Holm-adjusted p over all of them (one family: the report's)."""
    tested = sorted((c.p, i) for i, c in enumerate(contrasts) if c.p is not None)
    m = len(tested)
    adjusted: dict[int, float] = {}
    running = 0.0
    for rank, (p, i) in enumerate(tested):
        running = max(running, min(1.0, (m - rank) * p))
        adjusted[i] = running
    return [replace(c, p_adjusted=adjusted.get(i)) for i, c in enumerate(contrasts)]


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
                (totals[a.label].clusters, totals[b.label].clusters),
                _first_met(a, b, unit),
            )
    return contrasts


def _first_met(a: Condition, b: Condition, unit: str) -> dict[str, str]:
    """For each cluster with sessions in both conditions: the one it met first ("a" or "b")."""
    earliest: list[dict[str, str]] = [{}, {}]
    for side, condition in zip(earliest, (a, b), strict=True):
        for session in condition.sessions:
            cluster = cluster_of(session, unit)
            started = session.meta.created or session.name
            side[cluster] = min(side.get(cluster, started), started)
    both = set(earliest[0]) & set(earliest[1])
    return {c: "a" if earliest[0][c] <= earliest[1][c] else "b" for c in both}


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

    Children are nested in groups (the same robot, the same game, each other): the
    group is what is resampled, its children with it, and a group with children at
    both levels is resampled once for both (paired). Each child's own values give
    Hedges' g's SD. Only children with a participant code (and a row in the file) take part.
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
                    "group",
                    replicates,
                    seed,
                    ([_group(c) for c in levels[a]], [_group(c) for c in levels[b]]),
                )
    return contrasts


def _group(child: ChildMeasures) -> str:
    """The cluster a child is resampled with: its group (or groups), else the child alone."""
    return "+".join(sorted(child.groups)) or f"child {child.key}"
