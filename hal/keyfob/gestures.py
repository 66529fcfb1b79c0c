"""Key downs and ups in, gestures out: a pure recogniser driven by the caller's clock.

The recogniser never reads a clock and never waits. The caller feeds key
changes with their times (`key`), and calls `advance(now)` when `next_deadline()`
is reached, which is how a long press is delivered the moment its threshold
passes rather than at the release.

Latency is the price of meaning. A button's press can be delivered at its
key-down only when nothing else could still become of it, so each button
declares what the game listens for (GestureNeeds):

  needs of the button        a press is delivered
  press only                 at key-down (at key-down + both_window if `both`)
  press + long               at the release, + bounce
  press + double (+ long)    at the release + double_press, if no second press came

Long, double and both are delivered as soon as they are certain: long and
both when the hold reaches long_press, double at the second key-down. Every
gesture carries `at`, the time of the key-down that began it, so reaction
times are measured from the child's press, not from the recogniser's decision.
The game may ask for a longer hold than the keyfob's long_press
(GestureNeeds.long_press: a researcher's hold on the children's keyfob is 3 s).

Both buttons: held together for long_press they are one gesture, BOTH, which
names the button that went down first (`first`). Let go sooner, they are what a
child squeezing the keyfob meant: the first button's press, then the second's,
each at its own key-down (the game takes the first as the answer).

Contact bounce: a release followed by a press within `bounce` is one hold;
this costs `bounce` on presses decided at the release. Autorepeat (value 2)
is not a key change at all and is dropped by the reader before it gets here.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import StrEnum

import structlog

from hal.errors import InvalidArgument, SettingsError

log = structlog.get_logger("kaspar.gestures")

GREEN = "green"
RED = "red"
BOTH = "both"
CHORD = (GREEN, RED)


class GestureKind(StrEnum):
    """What a gesture is; the value is what session records show."""

    PRESS = "press"
    LONG = "long"
    DOUBLE = "double"
    BOTH = "both"
    # An extra key of a keypad, mapped to a researcher command: delivered at key-down.
    COMMAND = "command"


@dataclass(frozen=True, slots=True)
class Gesture:
    """One gesture, once it is certain; times are the caller's clock, in seconds."""

    kind: GestureKind
    # "green", "red", "both", or the researcher command name of an extra key.
    button: str
    # Clock time of the key-down that began the gesture (the first one of a double).
    at: float
    # Clock time at which the recogniser was certain; `decided - at` is its latency.
    decided: float
    # BOTH: the button that went down first ("green" or "red"); None for the others.
    first: str | None = None
    # With one keyfob per child (hal.keyfob.seats): the seat whose keyfob it came from.
    seat: int | None = None


ANSWER = frozenset({GestureKind.PRESS})
ANSWER_OR_LONG = frozenset({GestureKind.PRESS, GestureKind.LONG})
EVERYTHING = frozenset({GestureKind.PRESS, GestureKind.LONG, GestureKind.DOUBLE})


@dataclass(frozen=True, slots=True)
class GestureNeeds:
    """What the game listens for on each button; fewer needs, faster presses."""

    green: frozenset[GestureKind] = EVERYTHING
    red: frozenset[GestureKind] = EVERYTHING
    # Green and red held together for long_press (the researcher's stop).
    both: bool = True
    # How long a hold must last to be LONG (or BOTH); None: the keyfob's long_press.
    # Must be longer than the keyfob's double_press (GestureTimings' order).
    long_press: float | None = None

    def of(self, button: str) -> frozenset[GestureKind]:
        """The gestures listened for on `button`; a command key only ever gives its press."""
        if button == GREEN:
            return self.green
        if button == RED:
            return self.red
        return ANSWER


# Every gesture on both buttons with the keyfob's own long press (tests, bring-up).
RESEARCHER_GESTURES = GestureNeeds(green=ANSWER_OR_LONG, red=EVERYTHING, both=True)
# Children's answers only (the researcher's commands on a device of their own, or on a
# keypad's extra keys): every key-down is a press, delivered at once; a chord is two.
ANSWERS_ONLY = GestureNeeds(green=ANSWER, red=ANSWER, both=False)


def held_gestures(hold_s: float, *, green: bool = True, red: bool = True, both: bool = True) -> (
    GestureNeeds
):
    """The one-keyfob needs: presses, and holds of `hold_s` (long green, long red, both).

    No double press: a double tap is what children do. Presses wait for the release.
    """
    return GestureNeeds(
        green=ANSWER_OR_LONG if green else ANSWER,
        red=ANSWER_OR_LONG if red else ANSWER,
        both=both,
        long_press=hold_s,
    )


@dataclass(frozen=True, slots=True)
class GestureTimings:
    """The recogniser's thresholds in seconds (KeyfobSettings carries the configured ones).

    Raises SettingsError unless 0 < bounce < double_press < long_press and
    0 < both_window < long_press.
    """

    long_press: float = 1.0
    double_press: float = 0.4
    bounce: float = 0.03
    both_window: float = 0.3

    def __post_init__(self) -> None:
        """Check the order of the thresholds; SettingsError otherwise."""
        if not 0 < self.bounce < self.double_press < self.long_press:
            raise SettingsError("expected 0 < bounce < double_press < long_press")
        if not 0 < self.both_window < self.long_press:
            raise SettingsError("expected 0 < both_window < long_press")


@dataclass(slots=True)
class _Key:
    needs: frozenset[GestureKind] = frozenset()
    long_after: float = 1.0  # the hold that makes a long press, fixed at key-down
    down_at: float | None = None  # start of the current hold; None when up
    consumed: bool = False  # the current hold has produced (or forfeited) its gesture
    release_at: float | None = None  # a release not yet confirmed (bounce gap)
    press_due: float | None = None  # press-only key waiting out both_window
    first_at: float | None = None  # a complete press waiting for a possible second
    first_up: float | None = None


@dataclass(slots=True)
class _Chord:
    first: str
    first_at: float
    second_at: float
    long_after: float
    fired: bool = False
    broken: bool = False  # one of the two was let go
    # Let go early: the presses it stands for, each delivered once its key is up.
    pending: list[tuple[str, float]] = field(default_factory=list)


@dataclass
class GestureRecognizer:
    """Pure state machine; see the module docstring for the rules."""

    timings: GestureTimings = field(default_factory=GestureTimings)
    needs: GestureNeeds = field(default_factory=GestureNeeds)
    commands: Iterable[str] = ()
    _keys: dict[str, _Key] = field(init=False)
    _chord: _Chord | None = field(init=False, default=None)
    _now: float = field(init=False, default=float("-inf"))

    def __post_init__(self) -> None:
        """Give every button and command key its idle state; SettingsError for a hold that
        is not longer than the double-press and chord windows."""
        self.commands = frozenset(self.commands)
        self._keys = {name: _Key() for name in (*CHORD, *sorted(self.commands))}
        self._check(self.needs)

    def set_needs(self, needs: GestureNeeds) -> None:
        """Takes effect at each button's next key-down; a gesture in progress keeps its rules.

        SettingsError for a hold (needs.long_press) not longer than the double-press
        and chord windows.
        """
        self._check(needs)
        self.needs = needs

    def _check(self, needs: GestureNeeds) -> None:
        hold = needs.long_press
        shortest = max(self.timings.double_press, self.timings.both_window)
        if hold is not None and not hold > shortest:
            raise SettingsError(
                f"expected a hold longer than {shortest} s (the double-press and chord "
                f"windows), found {hold}"
            )

    @property
    def buttons(self) -> tuple[str, ...]:
        """Green, red, then the command keys in name order."""
        return tuple(self._keys)

    def held(self) -> tuple[str, ...]:
        """The buttons down right now (a release inside the bounce gap still counts as down)."""
        return tuple(name for name, key in self._keys.items() if key.down_at is not None)

    def key(self, button: str, down: bool, at: float) -> list[Gesture]:
        """A key change of `button` at clock time `at`; returns the gestures now certain.

        Times never go back: an `at` before the last one seen is taken as that one.
        Raises InvalidArgument for a button the recogniser was not built with.
        """
        if button not in self._keys:
            raise InvalidArgument(
                f"unknown button {button!r}; expected one of {', '.join(self._keys)}"
            )
        out = self.advance(at)
        at = self._now
        key = self._keys[button]
        if down:
            self._down(button, key, at, out)
        else:
            self._up(key, at)
        out.extend(self.advance(at))
        return out

    def next_deadline(self) -> float | None:
        """The clock time at which `advance` may have something to deliver."""
        due = [deadline for _, deadline in self._deadlines()]
        return min(due) if due else None

    def advance(self, now: float) -> list[Gesture]:
        """Deliver every gesture whose time has come by `now`, in time order."""
        self._now = max(self._now, now)
        out: list[Gesture] = []
        while True:
            due = self._deadlines()
            ready = [(deadline, action) for action, deadline in due if deadline <= self._now]
            if not ready:
                return out
            deadline, action = min(ready, key=lambda item: item[0])
            self._fire(action, deadline, out)

    def reset(self) -> list[Gesture]:
        """The keyfob is gone: holds are dropped, complete presses still count."""
        out: list[Gesture] = []
        for name, key in self._keys.items():
            if key.first_at is not None:
                out.append(self._gesture(GestureKind.PRESS, name, key.first_at, self._now))
            self._keys[name] = _Key()
        if self._chord is not None and not self._chord.fired:
            log.info("gesture dropped", reason="keyfob lost while both were held")
        self._chord = None
        return out

    # -- key changes --------------------------------------------------------

    def _down(self, name: str, key: _Key, at: float, out: list[Gesture]) -> None:
        if key.release_at is not None:
            # Bounce: the release did not happen; the hold goes on.
            key.release_at = None
            return
        if key.down_at is not None:
            return  # a second down without an up: the reader missed an up; keep the hold
        if key.first_at is not None and GestureKind.DOUBLE in key.needs:
            first = key.first_at
            key.first_at = key.first_up = None
            key.down_at, key.consumed = at, True
            out.append(self._gesture(GestureKind.DOUBLE, name, first, at))
            return
        key.needs = self.needs.of(name)
        key.long_after = self._long_after()
        key.down_at, key.consumed, key.press_due = at, False, None
        if self._chord is not None and name in CHORD:
            key.consumed = True  # pressed again during a chord: still part of the mash
            return
        if self._starts_chord(name, at):
            return
        if not key.needs:
            key.consumed = True
        elif key.needs == ANSWER:
            if self.needs.both and name in CHORD:
                key.press_due = at + self.timings.both_window
            else:
                key.consumed = True
                out.append(self._gesture(self._press_kind(name), name, at, at))

    def _starts_chord(self, name: str, at: float) -> bool:
        if not self.needs.both or name not in CHORD or self._chord is not None:
            return False
        other = self._keys[RED if name == GREEN else GREEN]
        if (
            other.down_at is None
            or other.consumed
            or other.release_at is not None
            or at - other.down_at > self.timings.both_window
        ):
            return False
        first = RED if name == GREEN else GREEN
        self._chord = _Chord(
            first=first, first_at=other.down_at, second_at=at, long_after=self._long_after()
        )
        for chord_key in (self._keys[GREEN], self._keys[RED]):
            chord_key.consumed, chord_key.press_due = True, None
        return True

    def _long_after(self) -> float:
        override = self.needs.long_press
        return override if override is not None else self.timings.long_press

    def _up(self, key: _Key, at: float) -> None:
        if key.down_at is not None and key.release_at is None:
            key.release_at = at

    # -- deadlines ----------------------------------------------------------

    def _deadlines(self) -> list[tuple[tuple[str, str], float]]:
        timings = self.timings
        due: list[tuple[tuple[str, str], float]] = []
        for name, key in self._keys.items():
            if key.release_at is not None:
                due.append((("release", name), key.release_at + timings.bounce))
                continue
            if key.down_at is not None and not key.consumed:
                if GestureKind.LONG in key.needs:
                    due.append((("long", name), key.down_at + key.long_after))
                if key.press_due is not None:
                    due.append((("press_due", name), key.press_due))
            if key.first_up is not None:
                due.append((("single", name), key.first_up + timings.double_press))
        chord = self._chord
        if chord is not None and not chord.fired and not chord.broken and self._chord_held():
            due.append((("both", BOTH), chord.second_at + chord.long_after))
        return due

    def _chord_held(self) -> bool:
        return all(self._keys[name].release_at is None for name in CHORD)

    def _fire(self, action: tuple[str, str], deadline: float, out: list[Gesture]) -> None:
        kind, name = action
        if kind == "both":
            assert self._chord is not None
            chord = self._chord
            chord.fired = True
            out.append(
                Gesture(GestureKind.BOTH, BOTH, chord.first_at, deadline, first=chord.first)
            )
            return
        key = self._keys[name]
        if kind == "release":
            released = key.release_at if key.release_at is not None else deadline
            self._release(name, key, released, out)
        elif kind == "long":
            key.consumed = True
            assert key.down_at is not None
            out.append(self._gesture(GestureKind.LONG, name, key.down_at, deadline))
        elif kind == "press_due":
            key.consumed, key.press_due = True, None
            assert key.down_at is not None
            out.append(self._gesture(GestureKind.PRESS, name, key.down_at, deadline))
        elif kind == "single":
            assert key.first_at is not None
            if GestureKind.PRESS in key.needs:
                out.append(self._gesture(GestureKind.PRESS, name, key.first_at, deadline))
            key.first_at = key.first_up = None

    def _release(self, name: str, key: _Key, released: float, out: list[Gesture]) -> None:
        down_at, consumed = key.down_at, key.consumed
        key.down_at, key.release_at, key.press_due, key.consumed = None, None, None, False
        chord = self._chord
        if chord is not None and name in CHORD:
            if not chord.fired and not chord.broken:
                # Let go before the hold: a child squeezing both buttons, who meant the
                # first one. Its press, then the second's, once both are up.
                chord.pending = [
                    (chord.first, chord.first_at),
                    (RED if chord.first == GREEN else GREEN, chord.second_at),
                ]
            chord.broken = True
            if all(self._keys[other].down_at is None for other in CHORD):
                self._chord = None
                for button, at in chord.pending:
                    if GestureKind.PRESS in self._keys[button].needs:
                        out.append(self._gesture(GestureKind.PRESS, button, at, released))
            return
        if consumed or down_at is None:
            return
        if GestureKind.DOUBLE in key.needs:
            key.first_at, key.first_up = down_at, released
        elif GestureKind.PRESS in key.needs:
            decided = released + self.timings.bounce
            out.append(self._gesture(self._press_kind(name), name, down_at, decided))

    def _press_kind(self, name: str) -> GestureKind:
        return GestureKind.COMMAND if name in self.commands else GestureKind.PRESS

    @staticmethod
    def _gesture(kind: GestureKind, button: str, at: float, decided: float) -> Gesture:
        return Gesture(kind=kind, button=button, at=at, decided=decided)
