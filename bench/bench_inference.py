"""Coverage and false positives of the contrasts' intervals and p, by number of clusters.

Each study has groups of children (5-30 answers a group, groups of their own
level: answers within a group correlate) in two conditions; condition A adds a
known effect to the chance of a right answer. Designs: independent groups (k a
condition) and paired (the same k groups meet both conditions), for k = 4
(the minimum with an interval), 5, 6, 8, 12, 16 and 20. For each: coverage of
the 95 % interval of the difference with a true effect of +0.10 (target
92-98 %), and the share of studies with p < 0.05 under no effect (target
5 % +- 2). Then one condition's own interval (a share's, from the cluster bootstrap
with 2,000 resamples, stretched for k clusters): its coverage of the true rate.
One run, seeded; a row outside a target is marked "MISS".
Run: .venv/bin/python bench/bench_inference.py [studies] [spread]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]

from kasparctl.research.inference import compare, estimates  # noqa: E402

EFFECT = 0.10
CLUSTERS = (4, 5, 6, 8, 12, 16, 20)
COVERAGE = (0.92, 0.98)
FALSE_POSITIVES = (0.03, 0.07)


def simulate(rng: np.random.Generator, groups: int, effect: float, paired: bool,
             spread: float) -> list[tuple[np.ndarray, np.ndarray, list[str]]]:
    levels = rng.normal(0.45, spread, 2 * groups)
    sides = []
    for side, shift in ((0, effect), (1, 0.0)):
        ids = range(groups) if paired or side == 0 else range(groups, 2 * groups)
        sizes = rng.integers(5, 31, groups).astype(float)
        chances = np.clip(levels[list(ids)] + shift, 0.0, 1.0)
        right = rng.binomial(sizes.astype(int), chances).astype(float)
        sides.append((right[:, None], sizes[:, None], [f"g{i}" for i in ids]))
    return sides


def run(studies: int, groups: int, paired: bool, spread: float) -> tuple[float, float]:
    rng = np.random.default_rng(2026 + 100 * groups + paired)
    covered = false_positives = 0
    for study in range(studies):
        for effect in (EFFECT, 0.0):
            (na, da, ca), (nb, db, cb) = simulate(rng, groups, effect, paired, spread)
            c = compare("f", ("A", "B"), ["rate"], ((na, da), (nb, db)), "group",
                        0, study, (ca, cb))[0]
            low, high = c.difference.low, c.difference.high
            assert low is not None and high is not None and c.p is not None
            if effect:
                covered += low <= EFFECT <= high
            else:
                false_positives += c.p < 0.05
    return covered / studies, false_positives / studies


def run_one(studies: int, groups: int, spread: float) -> float:
    """Coverage of one condition's interval of its rate (true rate 0.45)."""
    rng = np.random.default_rng(4052 + groups)
    covered = 0
    for study in range(studies):
        (right, sizes, _), _ = simulate(rng, groups, 0.0, False, spread)
        (estimate,) = estimates(right, sizes, 2000, study, "one")
        assert estimate.low is not None and estimate.high is not None
        covered += estimate.low <= 0.45 <= estimate.high
    return covered / studies


def main() -> None:
    studies = int(sys.argv[1]) if len(sys.argv) > 1 else 500
    spread = float(sys.argv[2]) if len(sys.argv) > 2 else 0.1
    print(f"{studies} simulated studies a row, group levels SD {spread}; "
          f"targets: coverage {100 * COVERAGE[0]:.0f}-{100 * COVERAGE[1]:.0f} %, "
          f"false positives {100 * FALSE_POSITIVES[0]:.0f}-{100 * FALSE_POSITIVES[1]:.0f} %")
    print(f"{'design':<12} {'clusters':>8} {'coverage':>9} {'false +':>8}  verdict")
    start = time.perf_counter()
    misses = 0
    for paired in (False, True):
        for groups in CLUSTERS:
            coverage, fpr = run(studies, groups, paired, spread)
            ok = (COVERAGE[0] <= coverage <= COVERAGE[1]
                  and FALSE_POSITIVES[0] <= fpr <= FALSE_POSITIVES[1])
            misses += not ok
            design = "paired" if paired else "independent"
            print(f"{design:<12} {groups:>8} {100 * coverage:>8.1f}% {100 * fpr:>7.1f}%  "
                  f"{'ok' if ok else 'MISS'}")
    for groups in CLUSTERS:
        coverage = run_one(studies, groups, spread)
        ok = COVERAGE[0] <= coverage <= COVERAGE[1]
        misses += not ok
        print(f"{'one side':<12} {groups:>8} {100 * coverage:>8.1f}% {'-':>8}  "
              f"{'ok' if ok else 'MISS'}")
    took = time.perf_counter() - start
    print(f"{3 * len(CLUSTERS) - misses} of {3 * len(CLUSTERS)} rows within their targets, "
          f"in {took:.1f} s")


if __name__ == "__main__":
    main()
