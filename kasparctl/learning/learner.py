"""Tabular Q-learning with a Boltzmann softmax: the paper's section III, Eq. 1-3.

Pure functions over numpy arrays. This module imports nothing else of the
project, so the game, the simulator and the tests share one definition of the
learner. States are targets (a bag, or a location in the pilot), actions are
labels (the toys' names, or the toys in the pilot).

Each operation has a scalar form (one table row, used by the game) and a batch
form over many independent rows (used by the vectorised simulator); the tests
hold the two to the same numbers.
"""

from __future__ import annotations

import bisect
import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


# The largest reward or starting Q the learner takes: far beyond any study's, and small
# enough that Q (bounded by max(|Q0|, |r| / (1 - gamma))) stays a finite number in every
# record, never overflowing into inf or null.
VALUE_LIMIT = 1e6
# The largest inverse temperature: beyond it the softmax is a plain argmax anyway.
BETA_LIMIT = 1e6


class LearnerError(ValueError):
    """A learner parameter or a serialised learner state is unusable.

    `key` names the offending parameter, so a configuration error can point at it.
    """

    def __init__(self, message: str, key: str = "") -> None:
        """The message says what is wrong; `key` is empty when no one parameter is."""
        super().__init__(message)
        self.key = key


@dataclass(frozen=True, slots=True)
class LearnerParams:
    """The learner's parameters. The defaults are the paper's."""

    alpha: float = 0.6
    beta: float = 8.0
    # The paper does not state gamma. A guess is a one-step problem: the game, not
    # the robot's action, picks the next target, so there is nothing to bootstrap
    # from; gamma = 0 reduces Eq. 1 to the delta rule the paper's results fit.
    gamma: float = 0.0
    reward_green: float = 1.0
    reward_red: float = -1.0
    # Q0 = 0 makes every label equally likely at first: the paper's starting
    # entropy of log2(6) = 2.585 bits with six toys.
    initial_q: float = 0.0

    def __post_init__(self) -> None:
        """Refuse parameters the learner cannot use, naming the one at fault."""
        for name in ("alpha", "beta", "gamma", "reward_green", "reward_red", "initial_q"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise LearnerError(f"expected a finite number, found {value!r}", name)
        if not 0.0 < self.alpha <= 1.0:
            raise LearnerError(f"expected a number in (0, 1], found {self.alpha!r}", "alpha")
        if not 0.0 <= self.beta <= BETA_LIMIT:
            raise LearnerError(
                f"expected a number from 0 to {BETA_LIMIT:g}, found {self.beta!r}", "beta"
            )
        if not 0.0 <= self.gamma < 1.0:
            raise LearnerError(f"expected a number in [0, 1), found {self.gamma!r}", "gamma")
        for name in ("reward_green", "reward_red", "initial_q"):
            value = getattr(self, name)
            if abs(value) > VALUE_LIMIT:
                raise LearnerError(
                    f"expected a number from {-VALUE_LIMIT:g} to {VALUE_LIMIT:g}, found {value!r}",
                    name,
                )

    def reward(self, green: bool) -> float:
        """The reward r of Eq. 1 for a green (right) or red (wrong) press."""
        return self.reward_green if green else self.reward_red


def new_table(n_states: int, n_actions: int, params: LearnerParams) -> FloatArray:
    """A Q table of states x actions, every value the initial Q."""
    if n_states < 1 or n_actions < 1:
        raise LearnerError(f"a Q table needs at least 1x1, asked for {n_states}x{n_actions}")
    return np.full((n_states, n_actions), params.initial_q, dtype=np.float64)


def softmax(q_row: FloatArray, beta: float, candidates: BoolArray | None = None) -> FloatArray:
    """Eq. 2 over the candidates; a non-candidate gets probability exactly 0.

    Q is shifted by its largest candidate value before scaling, so no Q
    magnitude overflows: every exponent is <= 0 and the best candidate's is 0.
    The arithmetic is the batch form's, step for step, so both give the same bits.
    The normaliser is numpy's sum, in numpy's order whatever the Python (left to
    right below eight labels, pairwise from eight on), as the batch form's rows.
    """
    q = np.asarray(q_row, dtype=np.float64)
    values = q.tolist()
    # Reductions over six numbers are far cheaper in Python than in numpy, and
    # this runs before every guess; the element-wise maths stays in numpy.
    if candidates is None:
        allowed = None
        best = max(values)
    else:
        allowed = np.asarray(candidates, dtype=bool)
        flags = allowed.tolist()
        if not any(flags):
            raise LearnerError("softmax needs at least one candidate")
        best = max(itertools.compress(values, flags))
    if beta == 0.0:
        uniform = np.ones(q.shape) if allowed is None else allowed.astype(np.float64)
        uniform_probabilities: FloatArray = uniform / uniform.sum()
        return uniform_probabilities
    if beta * (max(values) - min(values)) <= _SAFE_EXPONENT:
        weights = np.exp(beta * (q - best))
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            shifted = q - best if allowed is None else np.where(allowed, q - best, -np.inf)
            weights = np.exp(beta * shifted)
    if allowed is not None:
        weights = weights * allowed  # exactly 0 for a non-candidate, unchanged otherwise
    probabilities: FloatArray = weights / weights.sum()
    return probabilities


# Below this, exp(beta * (q - best)) can neither overflow nor warn for any entry.
_SAFE_EXPONENT = 700.0


def entropy_bits(probabilities: FloatArray) -> float:
    """Eq. 3 in bits; zero probabilities (non-candidates) contribute nothing.

    The terms are added one by one, left to right, in plain floating point: the
    entropy is in every question and trial record and picks the band Kaspar says,
    so its bits must not depend on the Python that runs the game. The built-in
    sum() adds floats with compensation from Python 3.12 on (other last bits than
    3.11's), and math.fsum rounds the exact sum (other bits than either); this loop
    is what 3.11's sum() did, so sessions recorded on 3.11 replay bit for bit.
    entropy_bits_batch adds in the same order, so the simulator's entropies are
    the game's.
    """
    total = 0.0
    for p in probabilities.tolist():
        if p > 0.0:
            total += p * math.log2(p)
    return max(0.0, -total)


def choose(probabilities: FloatArray, rng: np.random.Generator) -> int:
    """Draw one action; an action of probability 0 is never drawn.

    The cumulative sum is plain additions left to right on every Python (as
    choose_batch's cumsum), never the built-in sum().
    """
    values = probabilities.tolist()
    cumulative = list(itertools.accumulate(values))
    index = bisect.bisect_right(cumulative, rng.random() * cumulative[-1])
    # Rounding can put the draw past the last step of the cumulative sum.
    last_possible = max(i for i, p in enumerate(values) if p > 0.0)
    return min(index, last_possible)


def updated_value(
    q_sa: float, reward: float, params: LearnerParams, next_max: float = 0.0
) -> float:
    """Eq. 1: Q(s,a) + alpha * (r + gamma * max_a' Q(s',a') - Q(s,a))."""
    return q_sa + params.alpha * (reward + params.gamma * next_max - q_sa)


def update(
    table: FloatArray,
    state: int,
    action: int,
    reward: float,
    params: LearnerParams,
    next_state: int | None = None,
) -> FloatArray:
    """Return a new table with Eq. 1 applied; `next_state` None means terminal.

    LearnerError if the new value is not a finite number (a reward or table beyond
    every limit): a record never holds inf, or null where JSON has no inf.
    """
    next_max = 0.0 if next_state is None else float(table[next_state].max())
    result = table.copy()
    value = updated_value(float(table[state, action]), reward, params, next_max)
    if not math.isfinite(value):
        raise LearnerError(f"Q({state}, {action}) would be {value!r}: not a finite number")
    result[state, action] = value
    return result


def softmax_batch(
    q: FloatArray, beta: FloatArray, candidates: BoolArray | None = None
) -> FloatArray:
    """Eq. 2 for many independent rows at once; `beta` has one value per row."""
    allowed = np.ones(q.shape, dtype=bool) if candidates is None else candidates
    if not allowed.any(axis=1).all():
        raise LearnerError("softmax needs at least one candidate in every row")
    with np.errstate(over="ignore", invalid="ignore"):
        best = np.where(allowed, q, -np.inf).max(axis=1, keepdims=True)
        shifted = np.where(allowed, q - best, -np.inf)
        # beta 0 is uniform over the candidates; 0 * -inf (an overflowed spread) is NaN.
        scaled = np.where(beta[:, None] == 0.0, 0.0, beta[:, None] * shifted)
        weights = np.exp(np.where(allowed, scaled, -np.inf))
    probabilities: FloatArray = weights / weights.sum(axis=1, keepdims=True)
    return probabilities


def entropy_bits_batch(probabilities: FloatArray) -> FloatArray:
    """Eq. 3 in bits for each row of probabilities, added in entropy_bits' order.

    Column by column, left to right: numpy's own sum along a row is that order
    only below eight labels (pairwise from eight on), where a row would then
    differ from the game's entropy in its last bits.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(probabilities > 0.0, probabilities * np.log2(probabilities), 0.0)
    total = np.zeros(terms.shape[0])
    for column in terms.T:
        total += column
    entropies: FloatArray = np.maximum(0.0, -total)
    return entropies


def choose_batch(probabilities: FloatArray, rng: np.random.Generator) -> NDArray[np.intp]:
    """Draw one action per row; an action of probability 0 is never drawn."""
    cumulative = np.cumsum(probabilities, axis=1)
    draws = rng.random(len(probabilities))[:, None] * cumulative[:, -1:]
    index = (cumulative <= draws).sum(axis=1)
    last_possible = probabilities.shape[1] - 1 - np.argmax(probabilities[:, ::-1] > 0.0, axis=1)
    chosen: NDArray[np.intp] = np.minimum(index, last_possible)
    return chosen


# What numpy and the standard library raise for plain data of the wrong shape.
PLAIN_DATA_ERRORS = (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError)

_BIT_GENERATORS = {
    "PCG64": np.random.PCG64,
    "PCG64DXSM": np.random.PCG64DXSM,
    "MT19937": np.random.MT19937,
    "Philox": np.random.Philox,
    "SFC64": np.random.SFC64,
}


@dataclass(slots=True)
class LearnerState:
    """A Q table and the random generator of the learner's choices.

    Both serialise to plain data (JSON-ready) and back without loss, so a
    resumed session makes the very choices it would have made.
    """

    table: FloatArray
    rng: np.random.Generator = field(default_factory=np.random.default_rng)

    @classmethod
    def fresh(
        cls, n_states: int, n_actions: int, params: LearnerParams, seed: int | None
    ) -> LearnerState:
        """A new table at the initial Q and a generator seeded with `seed` (None: fresh entropy)."""
        return cls(new_table(n_states, n_actions, params), np.random.default_rng(seed))

    def to_plain(self) -> dict[str, Any]:
        """The table and the generator's exact state as JSON-ready data."""
        # Python's float repr round-trips exactly, so JSON keeps every bit of Q.
        return {"q": self.table.tolist(), "rng": self.rng.bit_generator.state}

    @classmethod
    def from_plain(cls, data: dict[str, Any]) -> LearnerState:
        """The state `to_plain` wrote; LearnerError for anything else."""
        try:
            table = np.array(data["q"], dtype=np.float64)
            generator_state = data["rng"]
            name = generator_state["bit_generator"]
            # Only numpy's bit generators: a snapshot must not name any other callable.
            if name not in _BIT_GENERATORS:
                raise ValueError(f"bit_generator: expected one of {sorted(_BIT_GENERATORS)}")
            bit_generator = _BIT_GENERATORS[name]()
            bit_generator.state = generator_state
        except PLAIN_DATA_ERRORS as error:
            raise LearnerError(f"unusable learner state: {error!r}") from error
        if table.ndim != 2 or table.size == 0 or not np.isfinite(table).all():
            raise LearnerError(f"learner state q must be a finite 2-D table, found {data['q']!r}")
        return cls(table, np.random.Generator(bit_generator))
