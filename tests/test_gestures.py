"""The gesture recogniser: pure, so every rule is checked at exact times."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hal.errors import InvalidArgument, SettingsError
from hal.keyfob.gestures import (
    ANSWER,
    ANSWER_OR_LONG,
    ANSWERS_ONLY,
    EVERYTHING,
    RESEARCHER_GESTURES,
    Gesture,
    GestureKind,
    GestureNeeds,
    GestureRecognizer,
    GestureTimings,
    held_gestures,
)

T = GestureTimings(long_press=1.0, double_press=0.4, bounce=0.03, both_window=0.3)
P, L, D, B, C = (
    GestureKind.PRESS,
    GestureKind.LONG,
    GestureKind.DOUBLE,
    GestureKind.BOTH,
    GestureKind.COMMAND,
)


def run(recogniser: GestureRecognizer, script: list[tuple[float, str, bool]], end: float) -> list[Gesture]:
    out: list[Gesture] = []
    for at, button, down in script:
        out += recogniser.key(button, down, at)
    out += recogniser.advance(end)
    return out


def summary(gestures: list[Gesture]) -> list[tuple[GestureKind, str, float, float]]:
    return [(g.kind, g.button, round(g.at, 6), round(g.decided, 6)) for g in gestures]


def test_press_only_button_is_delivered_at_key_down():
    r = GestureRecognizer(T, ANSWERS_ONLY)
    assert summary(r.key("green", True, 5.0)) == [(P, "green", 5.0, 5.0)]
    assert r.key("green", False, 5.1) == []
    assert r.advance(99.0) == []


def test_press_only_with_both_waits_for_the_chord_window_or_the_release():
    needs = GestureNeeds(green=ANSWER, red=ANSWER, both=True)
    r = GestureRecognizer(T, needs)
    assert r.key("green", True, 1.0) == []
    assert r.next_deadline() == pytest.approx(1.3)
    assert summary(r.advance(1.3)) == [(P, "green", 1.0, 1.3)]
    r.key("green", False, 1.5)
    r.advance(2.0)
    # Released before the window ends: delivered when the release is certain.
    assert run(r, [(3.0, "red", True), (3.1, "red", False)], 3.5) == [
        Gesture(P, "red", 3.0, pytest.approx(3.13))
    ]


def test_press_with_long_meaning_waits_for_the_release_plus_bounce():
    r = GestureRecognizer(T, GestureNeeds(green=ANSWER_OR_LONG, red=ANSWER, both=False))
    assert r.key("green", True, 0.0) == []
    assert r.key("green", False, 0.2) == []
    assert r.next_deadline() == pytest.approx(0.23)
    assert summary(r.advance(0.23)) == [(P, "green", 0.0, 0.23)]


def test_long_press_is_delivered_when_the_threshold_is_reached_not_at_release():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    r.key("green", True, 10.0)
    assert r.next_deadline() == pytest.approx(11.0)
    assert r.advance(10.999) == []
    assert summary(r.advance(11.0)) == [(L, "green", 10.0, 11.0)]
    # Nothing more when it is finally let go, however late.
    assert run(r, [(14.0, "green", False)], 20.0) == []


def test_double_press_is_delivered_at_the_second_key_down_with_the_first_time():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    gestures = run(
        r, [(0.0, "red", True), (0.1, "red", False), (0.35, "red", True), (0.45, "red", False)], 5.0
    )
    assert summary(gestures) == [(D, "red", 0.0, 0.35)]


def test_single_press_of_a_double_button_waits_out_the_window():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    r.key("red", True, 0.0)
    r.key("red", False, 0.1)
    assert r.advance(0.49) == []
    assert summary(r.advance(0.5)) == [(P, "red", 0.0, 0.5)]


def test_second_press_after_the_window_is_another_press():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    script = [(0.0, "red", True), (0.1, "red", False), (0.6, "red", True), (0.7, "red", False)]
    assert [g.kind for g in run(r, script, 5.0)] == [P, P]


def test_bounce_is_one_press():
    r = GestureRecognizer(T, ANSWERS_ONLY)
    script = [
        (0.0, "green", True),
        (0.004, "green", False),
        (0.008, "green", True),
        (0.150, "green", False),
        (0.160, "green", True),  # bounce on the release as well
        (0.170, "green", False),
    ]
    assert summary(run(r, script, 2.0)) == [(P, "green", 0.0, 0.0)]


def test_bounce_at_the_start_of_a_long_hold_is_still_a_long_press():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    script = [(0.0, "green", True), (0.002, "green", False), (0.004, "green", True)]
    assert summary(run(r, script, 1.0)) == [(L, "green", 0.0, 1.0)]


def test_bounce_is_not_mistaken_for_a_double_press():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    script = [(0.0, "red", True), (0.1, "red", False), (0.12, "red", True), (0.2, "red", False)]
    assert [g.kind for g in run(r, script, 5.0)] == [P]


def test_both_held_is_delivered_after_the_threshold_and_hides_the_single_buttons():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    gestures = run(r, [(0.0, "green", True), (0.2, "red", True)], 1.2)
    assert summary(gestures) == [(B, "both", 0.0, 1.2)]
    assert run(r, [(2.0, "green", False), (2.1, "red", False)], 5.0) == []


def test_both_let_go_early_is_the_first_buttons_press_then_the_seconds():
    # A child squeezing the keyfob meant the button that went down first.
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    script = [(0.0, "red", True), (0.1, "green", True), (0.3, "red", False), (0.4, "green", False)]
    assert summary(run(r, script, 5.0)) == [(P, "red", 0.0, 0.4), (P, "green", 0.1, 0.4)]
    # And the buttons work normally afterwards.
    assert [g.kind for g in run(r, [(6.0, "green", True), (6.1, "green", False)], 7.0)] == [P]


def test_both_held_names_the_button_that_went_down_first():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    (gesture,) = run(r, [(0.0, "red", True), (0.2, "green", True)], 1.2)
    assert (gesture.kind, gesture.first) == (B, "red")


def test_a_hold_asked_for_by_the_game_replaces_the_keyfobs_long_press():
    # The one-keyfob researcher: holds of 3 s; a child's 1.5 s hold is only a press.
    r = GestureRecognizer(T, held_gestures(3.0))
    assert summary(run(r, [(0.0, "green", True), (1.5, "green", False)], 2.0)) == [
        (P, "green", 0.0, 1.53)
    ]
    assert summary(run(r, [(5.0, "red", True)], 8.0)) == [(L, "red", 5.0, 8.0)]
    run(r, [(9.0, "red", False)], 10.0)
    assert summary(run(r, [(11.0, "green", True), (11.1, "red", True)], 14.1)) == [
        (B, "both", 11.0, 14.1)
    ]
    run(r, [(15.0, "green", False), (15.0, "red", False)], 16.0)
    # No double press on one keyfob: a double tap is two presses.
    double = [(20.0, "red", True), (20.1, "red", False), (20.2, "red", True), (20.3, "red", False)]
    assert [(g.kind, g.at) for g in run(r, double, 21.0)] == [(P, 20.0), (P, 20.2)]


def test_a_hold_no_longer_than_the_windows_is_refused():
    with pytest.raises(SettingsError, match=r"expected a hold longer than 0\.4 s"):
        GestureRecognizer(T, held_gestures(0.4))
    with pytest.raises(SettingsError, match=r"found 0\.2"):
        GestureRecognizer(T).set_needs(held_gestures(0.2))


def test_repress_during_an_aborted_chord_is_still_the_mash():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    script = [
        (0.0, "green", True),
        (0.1, "red", True),
        (0.3, "green", False),
        (0.5, "green", True),
        (0.6, "red", False),
        (0.7, "green", False),
    ]
    # One squeeze, whatever the fingers did inside it: green (first) then red.
    assert summary(run(r, script, 5.0)) == [(P, "green", 0.0, 0.7), (P, "red", 0.1, 0.7)]


def test_second_button_outside_the_window_is_its_own_press():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    script = [(0.0, "green", True), (0.5, "red", True), (0.6, "red", False)]
    gestures = run(r, script, 1.0)
    # Red's single press waits out its double-press window (0.6 + 0.4).
    assert set(summary(gestures)) == {(P, "red", 0.5, 1.0), (L, "green", 0.0, 1.0)}


def test_without_both_a_chord_is_two_presses():
    r = GestureRecognizer(T, ANSWERS_ONLY)
    gestures = run(r, [(0.0, "green", True), (0.05, "red", True)], 2.0)
    assert [(g.kind, g.button) for g in gestures] == [(P, "green"), (P, "red")]


def test_command_keys_fire_at_key_down():
    r = GestureRecognizer(T, RESEARCHER_GESTURES, commands=("pause",))
    assert summary(r.key("pause", True, 3.0)) == [(C, "pause", 3.0, 3.0)]
    assert run(r, [(3.5, "pause", False)], 9.0) == []


def test_unknown_button_is_a_programming_error():
    with pytest.raises(InvalidArgument, match="unknown button 'blue'") as caught:
        GestureRecognizer(T).key("blue", True, 0.0)
    assert isinstance(caught.value, ValueError)


def test_reset_keeps_complete_presses_and_drops_holds():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    r.key("red", True, 0.0)
    r.key("red", False, 0.1)
    r.advance(0.2)
    r.key("green", True, 0.2)
    assert summary(r.reset()) == [(P, "red", 0.0, 0.2)]
    assert r.held() == ()
    assert r.advance(10.0) == []


def test_needs_change_applies_from_the_next_key_down():
    r = GestureRecognizer(T, RESEARCHER_GESTURES)
    r.key("green", True, 0.0)
    r.set_needs(ANSWERS_ONLY)
    r.key("green", False, 0.2)
    assert [g.kind for g in r.advance(0.3)] == [P]
    assert [g.decided for g in r.key("green", True, 1.0)] == [1.0]


def test_key_with_no_needs_is_silent():
    r = GestureRecognizer(T, GestureNeeds(green=frozenset(), red=EVERYTHING, both=False))
    assert run(r, [(0.0, "green", True), (2.0, "green", False)], 5.0) == []


def test_timings_are_checked():
    with pytest.raises(SettingsError, match="expected 0 < bounce < double_press < long_press"):
        GestureTimings(long_press=0.3, double_press=0.4)
    with pytest.raises(SettingsError, match="expected 0 < both_window < long_press"):
        GestureTimings(both_window=1.0)


events = st.lists(
    st.tuples(st.floats(0.0005, 1.5), st.sampled_from(["green", "red"]), st.booleans()),
    max_size=40,
)


@settings(max_examples=300, deadline=None)
@given(events, st.sampled_from([RESEARCHER_GESTURES, ANSWERS_ONLY, GestureNeeds()]))
def test_any_sequence_gives_well_formed_gestures(script, needs):
    r = GestureRecognizer(T, needs)
    now, out, downs = 0.0, [], 0
    for gap, button, down in script:
        now += gap
        out += r.key(button, down, now)
        downs += down
    out += r.advance(now + 10.0)
    assert len(out) <= downs
    for gesture in out:
        assert gesture.at <= gesture.decided
    decided = [g.decided for g in out]
    assert decided == sorted(decided)
    assert r.next_deadline() is None or r.held()


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.07, 2.0), min_size=1, max_size=20))
def test_answers_only_gives_one_press_per_clean_press(gaps):
    r = GestureRecognizer(T, ANSWERS_ONLY)
    now, out = 0.0, []
    for gap in gaps:
        out += r.key("green", True, now)
        out += r.key("green", False, now + gap / 2)
        now += gap
    out += r.advance(now + 5.0)
    assert [g.kind for g in out] == [P] * len(gaps)
    assert all(g.decided == g.at for g in out)
