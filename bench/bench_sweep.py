"""1,000,000 pilot problems through the vectorised simulator (kasparctl.sim.sweep).

Run on demand: .venv/bin/python bench/bench_sweep.py
"""

from __future__ import annotations

import time

import numpy as np

from kasparctl.learning.study_stats import summarise_table
from kasparctl.sim.sweep import simulate_pilot_problems

TARGET_S = 10.0
PROBLEMS = 1_000_000


def main() -> None:
    alpha = np.full(PROBLEMS, 0.6)
    beta = np.full(PROBLEMS, 8.0)
    start = time.perf_counter()
    (table,) = simulate_pilot_problems(alpha, beta, np.random.default_rng(1))
    stats = summarise_table(table)
    elapsed = time.perf_counter() - start
    verdict = "PASS" if elapsed < TARGET_S else "FAIL"
    print(
        f"sweep of {PROBLEMS:,} pilot problems: {elapsed:.2f} s "
        f"(target < {TARGET_S:g} s) {verdict}  [trials to learn {stats.trials_mean:.3f} "
        f"± {stats.trials_sd:.3f}]"
    )


if __name__ == "__main__":
    main()
