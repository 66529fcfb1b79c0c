"""Sessions recorded by Python 3.11 replay bit for bit on the Python that runs the tests.

tests/data/sessions-py311 (Python 3.11, the code before the learner's sums were
written out) and tests/data/sessions-v1 (the code of commit 9c84157, also 3.11): each
trial's probabilities are the learner's softmax of the Q row it recorded, its entropy
is entropy_bits of them, and its choice and the generator after it are the draw from
the generator the session's seed and the trials before it left. Every comparison is of
floats with ==, i.e. of their bits. Only the learner's functions and the records' JSON
are read, so this holds whatever the game around the learner becomes.

The recordings would catch a sum in another order: in some of their entropies the
built-in sum() of Python 3.12 and later (compensated) and math.fsum (exactly rounded)
give other last bits than 3.11's left-to-right sum, which the learner keeps.
"""

from __future__ import annotations

import functools
import json
import math
import operator
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from kasparctl.learning.learner import LearnerParams, choose, entropy_bits, softmax

DATA = Path(__file__).resolve().parent / "data"
RECORDINGS = sorted(
    [
        *(DATA / "sessions-py311" / "state" / "sessions").iterdir(),
        *(DATA / "sessions-v1" / "state" / "sessions").iterdir(),
    ]
)
ASKED = ("question", "trial")  # the records that carry probabilities and an entropy


def records(directory: Path) -> list[dict[str, Any]]:
    lines = (directory / "records.jsonl").read_text().splitlines()
    return [json.loads(line) for line in lines]


def learner_params(plan: dict[str, Any]) -> LearnerParams:
    """The session's learner: its plan names it (sessions-v1: the paper's, by profile)."""
    if "learner" in plan:
        learner = {k: v for k, v in plan["learner"].items() if k != "profile"}
        return LearnerParams(**learner)
    assert plan["plan"]["profile"] == "paper", plan["plan"]
    return LearnerParams()


def terms(probabilities: list[float]) -> list[float]:
    """The terms of Eq. 3, in the order of the labels."""
    return [p * math.log2(p) for p in probabilities if p > 0.0]


def compensated_sum(values: list[float]) -> float:
    """The built-in sum() of floats from Python 3.12 on (Neumaier's compensation), in Python.

    CPython's bltinmodule.c, builtin_sum_impl: the int start 0 plus the first value,
    then each value added with its rounding error kept apart, the error added at the end.
    """
    if not values:
        return 0.0
    total, compensation = 0 + values[0], 0.0
    for value in values[1:]:
        t = total + value
        if abs(total) >= abs(value):
            compensation += (total - t) + value
        else:
            compensation += (value - t) + total
        total = t
    if compensation and math.isfinite(compensation):
        total += compensation
    return total


def left_to_right_sum(values: list[float]) -> float:
    """Python 3.11's sum() of floats: one addition after another, from 0."""
    return functools.reduce(operator.add, values, 0.0)


@pytest.mark.parametrize("directory", RECORDINGS, ids=lambda d: f"{d.parents[2].name}/{d.name}")
def test_every_recorded_guess_is_the_learners_to_the_bit(directory: Path) -> None:
    plan = json.loads((directory / "plan.json").read_text())
    params = learner_params(plan)
    rng = np.random.default_rng(plan["seed"])  # LearnerState.fresh: the session's seed
    asked = trials = 0
    for record in records(directory):
        if record["kind"] not in ASKED:
            continue
        where = f"{directory.name} record {record['seq']}"
        probabilities = record["probabilities"]
        assert entropy_bits(np.array(probabilities)) == record["entropy"], where
        asked += 1
        if record["kind"] != "trial":
            continue
        # A non-candidate has probability exactly 0; no candidate's underflows here.
        offered = np.array([p > 0.0 for p in probabilities])
        assert int(offered.sum()) == len(record["candidates"]), where
        again = softmax(np.array(record["q_before"]), params.beta, offered)
        assert again.tolist() == probabilities, where
        assert choose(again, rng) == record["choice_index"], where
        assert rng.bit_generator.state == record["learner_rng"], where
        trials += 1
    assert trials > 0 and asked >= trials


def test_the_recordings_tell_3_11s_sum_from_a_compensated_or_exact_one() -> None:
    """Without such entropies the test above would pass with any order of addition."""
    entropies = [
        (record["entropy"], terms(record["probabilities"]))
        for directory in RECORDINGS
        for record in records(directory)
        if record["kind"] in ASKED
    ]
    assert all(value == max(0.0, -left_to_right_sum(t)) for value, t in entropies)
    compensated = [value for value, t in entropies if value != max(0.0, -compensated_sum(t))]
    exact = [value for value, t in entropies if value != max(0.0, -math.fsum(t))]
    assert len(compensated) >= 10 and len(exact) >= 10, (len(compensated), len(exact))


def discriminating_record() -> dict[str, Any]:
    """The first trial of sessions-py311's German session (seed 33) whose entropy a
    compensated sum changes: its probabilities and its entropy as Python 3.11 summed it."""
    (german,) = [
        directory for directory in RECORDINGS
        if json.loads((directory / "plan.json").read_text()).get("language") == "de"
    ]  # fmt: skip
    for record in records(german):
        if record["kind"] == "trial":
            t = terms(record["probabilities"])
            if compensated_sum(t) != left_to_right_sum(t):
                return record
    raise AssertionError(f"{german.name}: no entropy a compensated sum changes")


def test_entropy_is_added_left_to_right_as_python_3_11_did() -> None:
    record = discriminating_record()
    probabilities, recorded = record["probabilities"], record["entropy"]
    t = terms(probabilities)
    assert entropy_bits(np.array(probabilities)) == recorded == -left_to_right_sum(t)
    assert -compensated_sum(t) != recorded
    assert -math.fsum(t) != recorded
    if sys.version_info >= (3, 12):
        # The emulation is this Python's sum(): with it, entropy_bits would miss here.
        assert sum(t) == compensated_sum(t)
    else:
        assert sum(t) == left_to_right_sum(t)
