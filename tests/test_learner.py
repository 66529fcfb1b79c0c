"""The learner (paper, section III) against hand-computed values and its invariants."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from kasparctl.learning.learner import (
    LearnerError,
    LearnerParams,
    LearnerState,
    choose,
    choose_batch,
    entropy_bits,
    entropy_bits_batch,
    new_table,
    softmax,
    softmax_batch,
    update,
    updated_value,
)

PAPER = LearnerParams()


# --- Eq. 1 ---------------------------------------------------------------------------


def test_update_follows_eq1_with_the_papers_alpha():
    table = new_table(3, 6, PAPER)
    table = update(table, 1, 2, PAPER.reward(True), PAPER)
    assert table[1, 2] == pytest.approx(0.6)  # 0 + 0.6 * (1 - 0)
    table = update(table, 1, 2, PAPER.reward(True), PAPER)
    assert table[1, 2] == pytest.approx(0.84)  # 0.6 + 0.6 * (1 - 0.6)
    table = update(table, 1, 2, PAPER.reward(False), PAPER)
    assert table[1, 2] == pytest.approx(-0.264)  # 0.84 + 0.6 * (-1 - 0.84)
    table = update(table, 1, 4, PAPER.reward(False), PAPER)
    assert table[1, 4] == pytest.approx(-0.6)
    # Only the chosen cell moves.
    untouched = np.ones_like(table, dtype=bool)
    untouched[1, [2, 4]] = False
    assert (table[untouched] == 0.0).all()


def test_update_returns_a_new_table():
    table = new_table(1, 3, PAPER)
    updated = update(table, 0, 0, 1.0, PAPER)
    assert table[0, 0] == 0.0 and updated[0, 0] != 0.0


def test_gamma_bootstraps_on_the_next_states_best_value():
    params = LearnerParams(alpha=0.6, gamma=0.5)
    table = np.array([[0.2, 0.0], [0.8, -0.3]])
    assert update(table, 0, 0, 1.0, params, next_state=1)[0, 0] == pytest.approx(0.92)
    # 0.2 + 0.6 * (1 + 0.5 * 0.8 - 0.2); with no next state it is terminal:
    assert update(table, 0, 0, 1.0, params, next_state=None)[0, 0] == pytest.approx(0.68)
    assert updated_value(0.2, 1.0, params, next_max=0.8) == pytest.approx(0.92)


# --- Eq. 2 and 3 ---------------------------------------------------------------------


def test_softmax_with_beta_8_after_one_green():
    q = np.array([0.6, 0.0, 0.0, 0.0, 0.0, 0.0])
    p = softmax(q, 8.0)
    e = math.exp(4.8)
    assert p[0] == pytest.approx(e / (e + 5))
    assert p[1:] == pytest.approx([1 / (e + 5)] * 5)


def test_softmax_with_beta_8_after_a_green_and_a_red():
    q = np.array([0.6, -0.6, 0.0, 0.0, 0.0, 0.0])
    p = softmax(q, 8.0)
    weights = np.array([math.exp(4.8), math.exp(-4.8), 1, 1, 1, 1])
    assert p == pytest.approx(weights / weights.sum())


def test_entropy_of_known_distributions():
    assert entropy_bits(softmax(np.zeros(6), 8.0)) == pytest.approx(math.log2(6), abs=1e-15)
    assert entropy_bits(np.array([0.5, 0.5, 0.0])) == pytest.approx(1.0)
    assert entropy_bits(np.array([1.0, 0.0])) == 0.0
    p = np.array([0.7, 0.2, 0.1])
    assert entropy_bits(p) == pytest.approx(
        -(0.7 * math.log2(0.7) + 0.2 * math.log2(0.2) + 0.1 * math.log2(0.1))
    )


def test_mask_gives_exactly_zero_and_is_left_out_of_the_entropy():
    q = np.array([0.6, -0.6, 5.0, 0.0, 0.0, 0.0])
    candidates = np.array([True, True, False, True, True, True])
    p = softmax(q, 8.0, candidates)
    assert p[2] == 0.0
    weights = np.array([math.exp(4.8), math.exp(-4.8), 1, 1, 1])
    expected = weights / weights.sum()
    assert p[candidates] == pytest.approx(expected)
    assert entropy_bits(p) == pytest.approx(-(expected * np.log2(expected)).sum())
    # One candidate left: certainty.
    only = np.array([False, False, False, True, False, False])
    assert entropy_bits(softmax(q, 8.0, only)) == 0.0


def test_beta_zero_is_uniform_over_the_candidates():
    q = np.array([3.0, -2.0, 1.0, 0.0])
    candidates = np.array([True, False, True, True])
    assert softmax(q, 0.0, candidates) == pytest.approx([1 / 3, 0, 1 / 3, 1 / 3])


def test_softmax_without_candidates_is_an_error():
    with pytest.raises(LearnerError):
        softmax(np.zeros(3), 8.0, np.zeros(3, dtype=bool))


# --- parameters and state ------------------------------------------------------------


@pytest.mark.parametrize(
    ("changes", "key"),
    [
        ({"alpha": 0.0}, "alpha"),
        ({"alpha": 1.5}, "alpha"),
        ({"alpha": math.nan}, "alpha"),
        ({"beta": -1.0}, "beta"),
        ({"beta": math.inf}, "beta"),
        ({"gamma": 1.0}, "gamma"),
        ({"gamma": -0.1}, "gamma"),
        ({"reward_green": math.nan}, "reward_green"),
        ({"reward_red": -math.inf}, "reward_red"),
        ({"initial_q": math.inf}, "initial_q"),
    ],
)
def test_bad_params_name_their_key(changes, key):
    with pytest.raises(LearnerError) as caught:
        LearnerParams(**changes)
    assert caught.value.key == key
    assert isinstance(caught.value, ValueError)


def test_paper_defaults():
    assert (PAPER.alpha, PAPER.beta, PAPER.gamma) == (0.6, 8.0, 0.0)
    assert (PAPER.reward(True), PAPER.reward(False)) == (1.0, -1.0)


def _play(state: LearnerState, trials: int) -> list[int]:
    """A few guesses with the paper's learner, rewarding toy 3 only."""
    choices = []
    for trial in range(trials):
        target = trial % len(state.table)
        p = softmax(state.table[target], PAPER.beta)
        choice = choose(p, state.rng)
        state.table = update(state.table, target, choice, PAPER.reward(choice == 3), PAPER)
        choices.append(choice)
    return choices


def test_state_round_trips_through_json_with_identical_future_choices():
    state = LearnerState.fresh(3, 6, PAPER, seed=7)
    _play(state, 10)
    restored = LearnerState.from_plain(json.loads(json.dumps(state.to_plain())))
    assert np.array_equal(restored.table, state.table)
    assert restored.table.tobytes() == state.table.tobytes()
    assert _play(restored, 25) == _play(state, 25)
    assert np.array_equal(restored.table, state.table)


@pytest.mark.parametrize(
    "data",
    [
        {},
        {"q": [[0.0]]},
        {"q": [[0.0, math.nan]], "rng": np.random.default_rng(1).bit_generator.state},
        {"q": [0.0, 1.0], "rng": np.random.default_rng(1).bit_generator.state},
        {"q": [[0.0]], "rng": {"bit_generator": "NoSuchGenerator"}},
    ],
)
def test_unusable_state_is_a_learner_error(data):
    with pytest.raises(LearnerError):
        LearnerState.from_plain(data)


# --- scalar and batch forms agree ------------------------------------------------------


def test_batch_forms_agree_with_scalar_forms():
    rng = np.random.default_rng(3)
    rows = 200
    q = rng.normal(0, 1.5, (rows, 6))
    beta = rng.uniform(0, 20, rows)
    candidates = rng.random((rows, 6)) < 0.7
    candidates[np.arange(rows), rng.integers(6, size=rows)] = True
    batch = softmax_batch(q, beta, candidates)
    scalar = np.array([softmax(q[i], float(beta[i]), candidates[i]) for i in range(rows)])
    np.testing.assert_allclose(batch, scalar, rtol=1e-12, atol=1e-300)
    assert (batch[~candidates] == 0.0).all()
    np.testing.assert_allclose(
        entropy_bits_batch(batch), [entropy_bits(p) for p in scalar], rtol=1e-12, atol=1e-15
    )
    # The batch draw takes the same random stream, one number per row in order.
    batch_choices = choose_batch(scalar, np.random.default_rng(11))
    scalar_rng = np.random.default_rng(11)
    assert list(batch_choices) == [choose(p, scalar_rng) for p in scalar]


@pytest.mark.parametrize("labels", [2, 6, 7, 8, 9, 12])
def test_batch_entropy_adds_in_the_scalar_order_at_any_width(labels):
    """The same bits as entropy_bits wherever numpy's log2 is math.log2 (nearly every
    number): numpy's own row sum is pairwise from eight labels on, another order."""
    rng = np.random.default_rng(labels)
    p = rng.dirichlet(np.full(labels, 0.5), size=400)
    p[:, -1] = 0.0  # a label not offered
    p /= p.sum(axis=1, keepdims=True)
    same_log = np.array([[np.log2(v) == math.log2(v) for v in row if v > 0.0] for row in p])
    rows = p[same_log.all(axis=1)]
    assert len(rows) > 300
    assert entropy_bits_batch(rows).tolist() == [entropy_bits(row) for row in rows]


# --- properties ------------------------------------------------------------------------

finite_q = st.floats(min_value=-1e308, max_value=1e308, allow_nan=False, allow_infinity=False)
betas = st.floats(min_value=0.0, max_value=1e6, allow_nan=False)


@st.composite
def rows_and_candidates(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    n = draw(st.integers(min_value=1, max_value=8))
    q = draw(hnp.arrays(np.float64, n, elements=finite_q))
    candidates = draw(hnp.arrays(np.bool_, n))
    candidates[draw(st.integers(min_value=0, max_value=n - 1))] = True
    return q, candidates


@settings(max_examples=300, deadline=None)
@given(rows_and_candidates(), betas)
def test_probabilities_are_a_distribution_over_the_candidates(row, beta):
    q, candidates = row
    p = softmax(q, beta, candidates)
    assert not np.isnan(p).any()
    assert (p[~candidates] == 0.0).all()
    assert (p >= 0.0).all()
    assert p[candidates].sum() == pytest.approx(1.0, abs=1e-12)


@settings(max_examples=300, deadline=None)
@given(rows_and_candidates(), betas)
def test_entropy_is_between_zero_and_log2_of_the_candidates(row, beta):
    q, candidates = row
    h = entropy_bits(softmax(q, beta, candidates))
    assert not math.isnan(h)
    assert 0.0 <= h <= math.log2(candidates.sum()) + 1e-9


@settings(max_examples=300, deadline=None)
@given(rows_and_candidates(), betas, st.integers(min_value=0, max_value=2**32))
def test_choose_never_picks_a_masked_action(row, beta, seed):
    q, candidates = row
    p = softmax(q, beta, candidates)
    rng = np.random.default_rng(seed)
    assert all(candidates[choose(p, rng)] for _ in range(20))


@settings(max_examples=200, deadline=None)
@given(rows_and_candidates(), st.floats(min_value=1e-300, max_value=1e6), st.integers(0, 2**32))
def test_batch_forms_keep_the_properties(row, beta, seed):
    q, candidates = row
    p = softmax_batch(q[None, :], np.array([beta]), candidates[None, :])
    assert not np.isnan(p).any()
    assert (p[0, ~candidates] == 0.0).all()
    assert p.sum() == pytest.approx(1.0, abs=1e-12)
    assert 0.0 <= entropy_bits_batch(p)[0] <= math.log2(candidates.sum()) + 1e-9
    assert candidates[choose_batch(p, np.random.default_rng(seed))[0]]


def test_batch_beta_zero_with_extreme_q_is_uniform():
    # Regression: 0 * -inf made this row NaN when the Q spread overflowed.
    p = softmax_batch(np.array([[1e308, -1e308, 0.0]]), np.array([0.0]))
    np.testing.assert_allclose(p, [[1 / 3, 1 / 3, 1 / 3]])


def test_batch_row_without_candidates_is_an_error_as_in_the_scalar_form():
    with pytest.raises(LearnerError, match="at least one candidate"):
        softmax_batch(np.zeros((2, 3)), np.array([8.0, 8.0]), np.array([[True, False, False], [False] * 3]))
