"""Coverage and false positives of the cluster bootstrap, over 500 simulated studies.

Each study has groups of children (5-30 answers a group, groups of their own
level: answers within a group correlate) in two conditions; condition A adds a
known effect to the chance of a right answer. Designs: independent groups
(20 a condition) and paired (the same 16 groups meet both conditions). For each:
coverage of the 95 % interval of the difference with a true effect of +0.10
(target 92-98 %), and the share of studies with p < 0.05 under no effect
(target 5 % +- 2). One run, seeded.
Run: .venv/bin/python bench/bench_inference.py [studies] [replicates]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]

from kasparctl.research.inference import compare  # noqa: E402

EFFECT = 0.10


def simulate(rng: np.random.Generator, groups: int, effect: float, paired: bool) -> tuple:  # type: ignore[type-arg]
    levels = rng.normal(0.45, 0.1, 2 * groups)
    sides = []
    for side, shift in ((0, effect), (1, 0.0)):
        ids = range(groups) if paired or side == 0 else range(groups, 2 * groups)
        sizes = rng.integers(5, 31, groups).astype(float)
        chances = np.clip(levels[list(ids)] + shift, 0.0, 1.0)
        right = rng.binomial(sizes.astype(int), chances).astype(float)
        sides.append((right[:, None], sizes[:, None], [f"g{i}" for i in ids]))
    return sides


def run(studies: int, replicates: int, groups: int, paired: bool) -> tuple[float, float]:
    rng = np.random.default_rng(2026 + paired)
    covered = false_positives = 0
    for study in range(studies):
        for effect in (EFFECT, 0.0):
            (na, da, ca), (nb, db, cb) = simulate(rng, groups, effect, paired)
            c = compare("f", ("A", "B"), ["rate"], ((na, da), (nb, db)), "group",
                        replicates, study, (ca, cb))[0]
            low, high = c.difference.low, c.difference.high
            assert low is not None and high is not None and c.p is not None
            if effect:
                covered += low <= EFFECT <= high
            else:
                false_positives += c.p < 0.05
    return covered / studies, false_positives / studies


def main() -> None:
    studies = int(sys.argv[1]) if len(sys.argv) > 1 else 500
    replicates = int(sys.argv[2]) if len(sys.argv) > 2 else 2000
    for name, groups, paired in (("independent, 20 groups a side", 20, False),
                                 ("paired, 16 groups in both", 16, True)):
        start = time.perf_counter()
        coverage, fpr = run(studies, replicates, groups, paired)
        took = time.perf_counter() - start
        print(f"{name}: coverage {100 * coverage:.1f} % (target 92-98 %), "
              f"false positives {100 * fpr:.1f} % (target 3-7 %), "
              f"{studies} studies x {replicates} resamples in {took:.1f} s")


if __name__ == "__main__":
    main()
