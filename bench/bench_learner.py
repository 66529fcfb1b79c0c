"""One game trial of the learner: softmax, entropy, choose and update on a 3x6 table.

Run on demand: .venv/bin/python bench/bench_learner.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from kasparctl.learning.learner import (
    LearnerParams,
    choose,
    entropy_bits,
    new_table,
    softmax,
    update,
)

TARGET_US = 20.0
TRIALS = 20_000


def main() -> None:
    params = LearnerParams()
    rng = np.random.default_rng(1)
    table = new_table(3, 6, params)
    candidates = np.ones(6, dtype=bool)
    answers = (0, 2, 4)
    timings_ns = []
    for trial in range(TRIALS + 1000):
        target = trial % 3
        if trial % 30 == 0:
            # A fresh table now and then, so the trials span the whole learning curve.
            table = new_table(3, 6, params)
        start = time.perf_counter_ns()
        probabilities = softmax(table[target], params.beta, candidates)
        entropy_bits(probabilities)
        choice = choose(probabilities, rng)
        table = update(table, target, choice, params.reward(choice == answers[target]), params)
        elapsed = time.perf_counter_ns() - start
        if trial >= 1000:  # the first thousand warm caches up
            timings_ns.append(elapsed)
    median_us = statistics.median(timings_ns) / 1000
    verdict = "PASS" if median_us < TARGET_US else "FAIL"
    print(
        f"learner trial (softmax+entropy+choose+update, 3x6): {median_us:.1f} µs median "
        f"(target < {TARGET_US:g} µs) {verdict}"
    )


if __name__ == "__main__":
    main()
