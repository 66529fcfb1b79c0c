"""Student's t distribution with real-valued degrees of freedom: two-sided p and quantiles.

The cluster-robust intervals need t with Welch-Satterthwaite degrees of freedom (not
whole numbers); numpy has no t distribution and scipy is not a dependency, so the
regularised incomplete beta function is evaluated here by its continued fraction.
"""

from __future__ import annotations

import functools
import math

_EPSILON = 1e-15
_TINY = 1e-300
_ITERATIONS = 500


def _continued_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of I_x(a, b) (modified Lentz), valid for x < (a+1)/(a+b+2)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > _TINY else _TINY)
    result = d
    for m in range(1, _ITERATIONS + 1):
        m2 = 2 * m
        for numerator in (m * (b - m) * x / ((qam + m2) * (a + m2)),
                          -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))):
            d = 1.0 + numerator * d
            d = 1.0 / (d if abs(d) > _TINY else _TINY)
            c = 1.0 + numerator / c
            c = c if abs(c) > _TINY else _TINY
            result *= d * c
        if abs(d * c - 1.0) < _EPSILON:
            break
    return result


def incomplete_beta(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b), for a, b > 0 and 0 <= x <= 1."""
    if not 0.0 <= x <= 1.0:
        raise ValueError(f"incomplete_beta: x must be in [0, 1], found {x}")
    if x in (0.0, 1.0):
        return x
    front = math.exp(
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)
        + a * math.log(x) + b * math.log1p(-x)
    )
    # The fraction converges fast only on one side of the mean; the other by symmetry.
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _continued_fraction(a, b, x) / a
    return 1.0 - front * _continued_fraction(b, a, 1.0 - x) / b


def two_sided_p(t: float, df: float) -> float:
    """P(|T| >= |t|) for T ~ Student's t with `df` degrees of freedom (df > 0)."""
    if not df > 0:
        raise ValueError(f"two_sided_p: degrees of freedom must be > 0, found {df}")
    if math.isinf(t):
        return 0.0
    return min(1.0, incomplete_beta(df / 2.0, 0.5, df / (df + t * t)))


def density(t: float, df: float) -> float:
    """The t density at t."""
    log_scale = math.lgamma((df + 1) / 2) - math.lgamma(df / 2) - 0.5 * math.log(df * math.pi)
    return math.exp(log_scale - (df + 1) / 2 * math.log1p(t * t / df))


# Memoised: a report asks for the same few (0.975, df) hundreds of times (every interval's
# stretch, every contrast), and each answer costs dozens of continued fractions.
@functools.lru_cache(maxsize=4096)
def quantile(probability: float, df: float) -> float:
    """The t with P(T <= t) = probability (0.5 < probability < 1).

    Newton's method on the two-sided p (its slope is twice the density), kept inside a
    bracket that halves whenever a step would leave it: a handful of p evaluations.
    """
    if not 0.5 < probability < 1.0:
        raise ValueError(f"quantile: probability must be in (0.5, 1), found {probability}")
    target = 2.0 * (1.0 - probability)
    low, high = 0.0, 2.0
    while two_sided_p(high, df) > target:
        low, high = high, high * 2.0
    t = (low + high) / 2.0
    for _ in range(200):
        excess = two_sided_p(t, df) - target
        if excess > 0:
            low = t
        else:
            high = t
        step = excess / (2.0 * density(t, df))
        following = t + step
        if not low < following < high:
            following = (low + high) / 2.0
        if abs(following - t) <= 1e-14 * t or high - low <= 1e-14 * high:
            return following
        t = following
    return t
