"""Inference: independent sides, the group as the unit, paired groups, Holm, effect sizes.

Checked against statsmodels' cluster-robust OLS (an independent computation) on
simulated studies with a known effect. The 500-study coverage and null figures are
in bench/bench_inference.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from kasparctl.research.inference import (
    MIN_CLUSTERS,
    _batch_seeds,
    compare,
    estimates,
    expansion,
    holm,
)
from kasparctl.research.student_t import quantile, two_sided_p

FloatArray = np.ndarray


def study(
    rng: np.random.Generator,
    groups: int,
    effect: float,
    paired: bool = False,
    spread: float = 0.15,
) -> tuple[list[tuple[FloatArray, FloatArray, list[str]]], list[tuple[float, str, str]]]:
    """Per-group successes/answers for two conditions, and the answers themselves.

    Each group has its own level (so answers within a group correlate); condition A
    adds `effect` to the chance of success. Paired: the same groups meet both.
    """
    sides = []
    answers: list[tuple[float, str, str]] = []
    levels = {f"g{g}": rng.normal(0.5, spread) for g in range(2 * groups)}
    for side, shift in (("a", effect), ("b", 0.0)):
        names = [f"g{g}" for g in range(groups)] if paired or side == "a" else [
            f"g{g}" for g in range(groups, 2 * groups)
        ]
        successes, totals = [], []
        for name in names:
            n = int(rng.integers(5, 30))  # groups of different sizes
            chance = float(np.clip(levels[name] + shift, 0.02, 0.98))
            y = rng.random(n) < chance
            successes.append(float(y.sum()))
            totals.append(float(n))
            answers += [(float(v), side, name) for v in y]
        sides.append((np.array(successes)[:, None], np.array(totals)[:, None], names))
    return sides, answers


def contrast_of(sides: list[tuple[FloatArray, FloatArray, list[str]]], replicates: int, seed: int):  # type: ignore[no-untyped-def]
    (na, da, ca), (nb, db, cb) = sides
    return compare("f", ("A", "B"), ["rate"], ((na, da), (nb, db)), "group", replicates, seed, (ca, cb))[0]


def test_the_two_sides_of_a_contrast_are_resampled_independently() -> None:
    """Defect 1: salts differing past their 32nd byte drew the same resamples on both sides."""
    long = "uncertainty mode:paper/body (names):paper/silent (names)"
    a = _batch_seeds(250, 0, long + ":a")[0].generate_state(4)
    b = _batch_seeds(250, 0, long + ":b")[0].generate_state(4)
    assert list(a) != list(b)
    # The same six clusters on both sides, under different names: with one set of
    # weights for both, every resampled difference would be 0 and the interval [0, 0].
    num = np.array([[1.0], [4.0], [2.0], [6.0], [3.0], [5.0]])
    den = np.full((6, 1), 8.0)
    names_a = [f"x{i}" for i in range(6)]
    names_b = [f"y{i}" for i in range(6)]
    c = compare(long, ("paper/body (names)", "paper/silent (names)"), ["m"], ((num, den), (num, den)),
                "group", 1000, 0, (names_a, names_b))[0]
    assert c.difference.value == 0.0 and not c.paired
    assert c.difference.low is not None and c.difference.high is not None
    assert c.difference.low < -0.05 and c.difference.high > 0.05


def test_no_interval_below_the_minimum_number_of_clusters() -> None:
    """Defect 9: a bootstrap over two or three clusters has a handful of outcomes."""
    rng = np.random.default_rng(1)
    for k in range(1, MIN_CLUSTERS):
        num, den = rng.integers(0, 5, (k, 1)).astype(float), np.full((k, 1), 5.0)
        (estimate,) = estimates(num, den, 500, 0, "s")
        assert estimate.value is not None and estimate.low is None and estimate.high is None
        c = compare("f", ("A", "B"), ["m"], ((num, den), (num + 1, den)), "group", 500, 0)[0]
        assert c.difference.value is not None and c.difference.low is None
        assert c.hedges_g.low is None and c.p is None
    num, den = rng.integers(0, 5, (MIN_CLUSTERS, 1)).astype(float), np.full((MIN_CLUSTERS, 1), 5.0)
    assert estimates(num, den, 500, 0, "s")[0].low is not None


def test_a_condition_interval_is_stretched_for_few_clusters() -> None:
    """A percentile bootstrap over k clusters is too narrow: its half-widths are stretched
    by sqrt(k/(k-1)) t(k-1)/z for equal clusters (more when one cluster weighs more), and
    the result stays where a share can be."""
    z = quantile(0.975, 1e9)
    equal = np.full(4, 10.0)
    assert expansion(np.array([2.0, 5.0, 7.0, 4.0]), equal) == pytest.approx(
        np.sqrt(4 / 3) * quantile(0.975, 3) / z, rel=1e-9
    )
    # Unequal sizes: the heavy cluster's residual counts for more.
    assert expansion(np.array([2.0, 5.0, 35.0, 4.0]), np.array([10.0, 10.0, 50.0, 10.0])) > (
        np.sqrt(4 / 3) * quantile(0.975, 3) / z
    )
    # Rows without data do not count as clusters.
    assert expansion(np.array([2.0, 5.0, 7.0, 4.0, 0.0]), np.append(equal, 0.0)) == pytest.approx(
        expansion(np.array([2.0, 5.0, 7.0, 4.0]), equal)
    )
    num, den = np.array([[0.0], [0.0], [0.0], [1.0]]), np.full((4, 1), 20.0)
    plain = estimates(num, den, 2000, 0, "s")[0]
    bounded = estimates(num, den, 2000, 0, "s", (np.zeros(1), np.ones(1)))[0]
    assert plain.low is not None and plain.low < 0  # stretched past what a share can be
    assert bounded.low == 0.0 and bounded.high == plain.high
    # Four rows, but only three with data for the column: no interval.
    three = estimates(np.array([[1.0], [2.0], [3.0], [0.0]]), np.array([[5.0], [5.0], [5.0], [0.0]]), 500, 0, "s")[0]
    assert three.value == pytest.approx(0.4) and three.low is None


def test_hedges_g_points_the_way_its_difference_does() -> None:
    """Defect 10: the pooled rate favours A, the clusters' own means favour B; g must follow
    the difference it sits beside (and its interval the difference's resamples)."""
    # A: one big good cluster, small bad ones; B: middling clusters.
    num_a = np.array([[90.0], [0.0], [0.0], [0.0], [0.0]])
    den_a = np.array([[100.0], [2.0], [2.0], [2.0], [2.0]])
    num_b = np.array([[30.0], [30.0], [30.0], [30.0], [30.0]])
    den_b = np.full((5, 1), 60.0)
    c = compare("f", ("A", "B"), ["m"], ((num_a, den_a), (num_b, den_b)), "group", 1000, 0)[0]
    assert c.difference.value is not None and c.difference.value > 0
    # The clusters' own means: A 0.18, B 0.5 (the old g was negative here).
    assert np.mean(num_a / den_a) < np.mean(num_b / den_b)
    assert c.hedges_g.value is not None and c.hedges_g.value > 0
    rng = np.random.default_rng(7)
    for _ in range(30):
        sides, _answers = study(rng, 6, float(rng.normal(0, 0.1)))
        c = contrast_of(sides, 300, 0)
        assert np.sign(c.hedges_g.value) == np.sign(c.difference.value)
        # g's interval is the difference's in SD units: it excludes 0 exactly when that does.
        scale = c.hedges_g.value / c.difference.value  # type: ignore[operator]
        assert c.hedges_g.low == pytest.approx(c.difference.low * scale)  # type: ignore[operator]
        assert c.hedges_g.high == pytest.approx(c.difference.high * scale)  # type: ignore[operator]


def test_a_group_in_both_conditions_is_resampled_as_a_pair() -> None:
    """Groups differ far more than conditions do: pairing removes the groups' spread."""
    rng = np.random.default_rng(2)
    sides, _answers = study(rng, 8, 0.1, paired=True, spread=0.2)
    paired = contrast_of(sides, 2000, 0)
    (na, da, ca), (nb, db, cb) = sides
    unpaired = compare("f", ("A", "B"), ["rate"], ((na, da), (nb, db)), "group", 2000, 0,
                       (ca, [f"other {n}" for n in cb]))[0]
    assert paired.paired and paired.shared == 8 and not unpaired.paired
    assert paired.difference.value == pytest.approx(unpaired.difference.value)
    width = paired.difference.high - paired.difference.low  # type: ignore[operator]
    unpaired_width = unpaired.difference.high - unpaired.difference.low  # type: ignore[operator]
    assert width < 0.7 * unpaired_width
    # The standard errors (half-widths over their t quantiles): pairing pays k - 1 = 7 df
    # for the groups' spread, which dominates here.
    assert paired.df == pytest.approx(7.0)
    se = width / quantile(0.975, paired.df)
    assert se < 0.6 * unpaired_width / quantile(0.975, unpaired.df)  # type: ignore[arg-type]
    assert paired.plain()["paired"] is True and paired.plain()["shared_clusters"] == 8


def test_holm_adjusts_every_contrast_of_the_family() -> None:
    rng = np.random.default_rng(4)
    contrasts = [contrast_of(study(rng, 8, effect)[0], 1000, 0) for effect in (0.0, 0.0, 0.3, 0.05)]
    adjusted = holm(contrasts)
    ps = [c.p for c in contrasts]
    assert all(p is not None for p in ps)
    multipletests = pytest.importorskip("statsmodels.stats.multitest").multipletests
    expected = multipletests(ps, alpha=0.05, method="holm")[1]
    assert [c.p_adjusted for c in adjusted] == pytest.approx(list(expected))
    assert all(c.p_adjusted >= c.p for c in adjusted)  # type: ignore[operator]
    assert adjusted[2].significant is True
    assert "p_holm" in adjusted[0].plain() and "significant_holm" in adjusted[0].plain()


def test_student_t_matches_scipy_at_fractional_degrees_of_freedom() -> None:
    """Welch-Satterthwaite df are not whole numbers; numpy has no t distribution."""
    stats = pytest.importorskip("scipy.stats")
    for df in (0.7, 1.0, 2.5, 3.0, 4.3, 7.9, 19.0, 250.0):
        for t in (0.0, 0.3, 1.0, 2.0, 3.5, 12.0):
            assert two_sided_p(t, df) == pytest.approx(2 * stats.t.sf(t, df), rel=1e-9, abs=1e-14)
        for probability in (0.6, 0.975, 0.995):
            assert quantile(probability, df) == pytest.approx(stats.t.ppf(probability, df), rel=1e-9)
    with pytest.raises(ValueError, match="degrees of freedom"):
        two_sided_p(1.0, 0.0)


def _cr2_by_matrices(answers: list[tuple[float, str, str]]) -> float:
    """CR2 variance of the condition coefficient, the textbook way: OLS of each answer on
    the condition, each cluster's residuals times (I - H_gg)^(-1/2), the sandwich."""
    y = np.array([a[0] for a in answers])
    x = np.column_stack([np.ones(len(y)), [1.0 if a[1] == "a" else 0.0 for a in answers]])
    bread = np.linalg.inv(x.T @ x)
    residual = y - x @ (bread @ x.T @ y)
    meat = np.zeros((2, 2))
    for group in sorted({a[2] for a in answers}):
        rows = np.array([a[2] == group for a in answers])
        xg = x[rows]
        values, vectors = np.linalg.eigh(np.eye(rows.sum()) - xg @ bread @ xg.T)
        root = vectors @ np.diag(1 / np.sqrt(np.clip(values, 1e-12, None))) @ vectors.T
        score = xg.T @ root @ residual[rows]
        meat += np.outer(score, score)
    return float((bread @ meat @ bread)[1, 1])


@pytest.mark.parametrize("paired", [False, True])
@pytest.mark.parametrize("groups", [4, 7])
def test_the_standard_error_is_cr2_computed_from_the_answers(paired: bool, groups: int) -> None:
    """An independent computation of the same estimator: the interval's half-width is
    t(df) times the CR2 standard error of OLS on the answers, and df is k - 1 paired."""
    rng = np.random.default_rng(groups + 10 * paired)
    sides, answers = study(rng, groups, 0.1, paired=paired)
    c = contrast_of(sides, 0, 0)
    se = np.sqrt(_cr2_by_matrices(answers))
    assert c.df is not None and c.difference.high is not None and c.difference.value is not None
    assert c.difference.high - c.difference.value == pytest.approx(quantile(0.975, c.df) * se, rel=1e-9)
    assert c.p == pytest.approx(two_sided_p(c.difference.value / se, c.df), rel=1e-9)
    if paired:
        assert c.df == pytest.approx(groups - 1)
    else:
        assert groups - 1 <= c.df <= 2 * groups - 2  # Welch: between one side's and both


@pytest.mark.parametrize("paired", [False, True])
def test_the_difference_and_interval_match_cluster_robust_ols(paired: bool) -> None:
    """statsmodels: OLS of each answer on the condition, SEs clustered by group, t with
    G - 1 df. Its coefficient is the ratio-of-sums difference exactly; its CR1 interval
    and p and ours (CR2, Satterthwaite df) agree closely with 40 groups a side, where the
    small-sample corrections hardly matter."""
    sm = pytest.importorskip("statsmodels.api")
    rng = np.random.default_rng(11 + paired)
    sides, answers = study(rng, 40, 0.08, paired=paired)
    c = contrast_of(sides, 0, 3)
    y = np.array([a[0] for a in answers])
    x = sm.add_constant(np.array([1.0 if a[1] == "a" else 0.0 for a in answers]))
    groups = np.unique([a[2] for a in answers], return_inverse=True)[1]
    fit = sm.OLS(y, x).fit(cov_type="cluster", cov_kwds={"groups": groups}, use_t=True)
    assert c.difference.value == pytest.approx(fit.params[1], abs=1e-12)
    low, high = fit.conf_int(0.05)[1]
    width = high - low
    assert c.difference.low == pytest.approx(low, abs=0.02 * width)
    assert c.difference.high == pytest.approx(high, abs=0.02 * width)
    assert c.p == pytest.approx(fit.pvalues[1], rel=0.15)


def test_the_order_of_conditions_is_reported_for_paired_groups() -> None:
    """Groups that met A first do better on A by 0.3, groups that met B first by 0.1."""
    names = ["g1", "g2", "g3", "g4", "g5"]
    num_a = np.array([[8.0], [8.0], [6.0], [6.0], [6.0]])
    num_b = np.array([[5.0], [5.0], [5.0], [5.0], [5.0]])
    den = np.full((5, 1), 10.0)
    first = {"g1": "a", "g2": "a", "g3": "b", "g4": "b", "g5": "b"}
    c = compare("f", ("A", "B"), ["m"], ((num_a, den), (num_b, den)), "group", 500, 0, (names, names), first)[0]
    assert c.paired and (c.a_first, c.b_first) == (2, 3)
    assert c.difference_a_first == pytest.approx(0.3)
    assert c.difference_b_first == pytest.approx(0.1)
    assert c.plain()["order_a_first"] == 2


@pytest.mark.slow
@pytest.mark.parametrize("paired", [False, True])
def test_coverage_and_false_positives_with_the_fewest_clusters(paired: bool) -> None:
    """95 % intervals cover a known effect in 92-98 % of studies; p < 0.05 under none in
    3-7 %, with 4 groups a side, the fewest given an interval (the bootstrap this replaced
    rejected 16 % of null studies with 4 paired groups). 1,000 studies, so the targets are
    about 3 binomial SDs wide. Every number of clusters from 4 to 20, both designs:
    bench/bench_inference.py."""
    groups = 4
    rng = np.random.default_rng(500 + paired)
    covered = false_positives = 0
    studies = 1000
    for seed in range(studies):
        effect_side, _ = study(rng, groups, 0.1, paired=paired, spread=0.1)
        c = contrast_of(effect_side, 0, seed)
        covered += c.difference.low <= 0.1 <= c.difference.high  # type: ignore[operator]
        null_side, _ = study(rng, groups, 0.0, paired=paired, spread=0.1)
        false_positives += contrast_of(null_side, 0, seed).p < 0.05  # type: ignore[operator]
    assert 0.92 <= covered / studies <= 0.98
    assert 0.03 <= false_positives / studies <= 0.07


@pytest.mark.slow
def test_a_condition_interval_covers_with_the_fewest_clusters() -> None:
    """One condition, 4 groups: its rate's interval covers the true rate in 92-98 % of
    1,000 studies (the plain percentile interval covered about 78 %)."""
    rng = np.random.default_rng(44)
    covered = 0
    studies = 1000
    for seed in range(studies):
        levels = rng.normal(0.45, 0.1, 4)
        sizes = rng.integers(5, 31, 4).astype(float)
        right = rng.binomial(sizes.astype(int), np.clip(levels, 0, 1)).astype(float)
        (estimate,) = estimates(right[:, None], sizes[:, None], 500, seed, "one")
        covered += estimate.low <= 0.45 <= estimate.high  # type: ignore[operator]
    assert 0.92 <= covered / studies <= 0.98
