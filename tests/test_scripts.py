"""The uncertainty scripts: the paper's three levels by default, the varied five, and the
line that says why Kaspar is sure."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kasparctl.game.scripts import (
    LAST_ONE,
    NO_IDEA,
    NO_IDEA_TOLERANCE,
    SCRIPTS,
    SURE_LEFT,
    ScriptError,
    script,
)

PAPER, VARIED = SCRIPTS["paper"], SCRIPTS["varied"]


def test_the_paper_script_has_the_papers_three_levels_and_fixed_words() -> None:
    assert PAPER.levels == ("no_idea", "idea_not_sure", "sure")
    assert PAPER.fixed and not PAPER.says_why
    assert PAPER.bands[0].max == 0.5  # paper: below 0.5 bits Kaspar says it is sure
    assert VARIED.levels == ("no_idea", "unsure", "idea_not_sure", "fairly_sure", "sure")
    assert not VARIED.fixed and VARIED.says_why


@pytest.mark.parametrize(
    ("entropy", "n", "paper", "varied"),
    [
        (2.585, 6, NO_IDEA, NO_IDEA),  # paper: log2(6) at the start of every problem
        (math.log2(6), 6, NO_IDEA, NO_IDEA),
        (1.58, 3, NO_IDEA, NO_IDEA),  # three names left, all equal: still no idea
        (1.0, 2, NO_IDEA, NO_IDEA),
        (2.32, 6, "idea_not_sure", "unsure"),  # one red among six
        (1.5, 6, "idea_not_sure", "idea_not_sure"),  # paper: around 1.5 an idea, not sure
        (0.99, 6, "idea_not_sure", "fairly_sure"),
        (0.5, 6, "idea_not_sure", "fairly_sure"),
        (0.3, 6, "sure", "sure"),  # paper: below 0.5 sure
        (0.0, 6, "sure", "sure"),
        (0.0, 1, "sure", "sure"),  # one name left: nothing to be unsure about
    ],
)
def test_levels(entropy: float, n: int, paper: str, varied: str) -> None:
    assert PAPER.level(entropy, n) == paper
    assert VARIED.level(entropy, n) == varied


def test_impossible_entropies_are_named() -> None:
    with pytest.raises(ScriptError, match=r"expected an entropy <= log2\(6\) = 2.5850 bits"):
        PAPER.level(2.7, 6)
    with pytest.raises(ScriptError, match=r"expected an entropy >= 0 bits, found -0\.5"):
        PAPER.level(-0.5, 6)
    with pytest.raises(ScriptError, match="expected an entropy >= 0 bits, found nan"):
        PAPER.level(math.nan, 6)
    with pytest.raises(ScriptError, match="expected at least 1 candidate, found 0"):
        PAPER.level(0.0, 0)
    with pytest.raises(ScriptError, match="expected a script, one of paper, varied, found 'x'"):
        script("x")


@settings(max_examples=400, deadline=None)
@given(data=st.data(), n=st.integers(min_value=1, max_value=12))
def test_every_entropy_has_exactly_one_level(data: st.DataObject, n: int) -> None:
    entropy = data.draw(st.floats(min_value=0.0, max_value=math.log2(n)), label="entropy")
    for chosen in SCRIPTS.values():
        level = chosen.level(entropy, n)
        assert level in chosen.levels
        if level == NO_IDEA:
            assert n > 1 and entropy >= math.log2(n) - NO_IDEA_TOLERANCE
        else:
            assert [band.name for band in chosen.bands if band.contains(entropy)] == [level]


def test_the_words_agree_with_the_state() -> None:
    """The varied script says why it is sure: one name left, or the others were wrong;
    'sure' only once the children said green to it. The paper's says its level."""
    assert VARIED.line_key("sure", 1, confirmed=False) == LAST_ONE
    assert VARIED.line_key("sure", 2, confirmed=False) == SURE_LEFT
    assert VARIED.line_key("sure", 4, confirmed=True) == "uncertainty.sure"
    assert VARIED.line_key("unsure", 5, confirmed=False) == "uncertainty.unsure"
    assert PAPER.line_key("sure", 1, confirmed=False) == "uncertainty.sure"
    assert PAPER.line_key("idea_not_sure", 5, confirmed=False) == "uncertainty.idea_not_sure"


def test_the_varied_bands_are_the_ones_sessions_recorded_before_scripts() -> None:
    """Sessions planned without a script resume with the same band names."""
    assert [(b.name, b.min, b.max) for b in VARIED.bands] == [
        ("sure", 0.0, 0.5),
        ("fairly_sure", 0.5, 1.0),
        ("idea_not_sure", 1.0, 2.0),
        ("unsure", 2.0, math.inf),
    ]
