"""A simulated group of children answering Kaspar's guesses.

The pilot's children made 3 mistakes in 202 trials, all of them greens for a
wrong guess; the model lets a simulation add such mistakes, the opposite ones,
and guesses nobody answers. An unanswered guess counts as a trial (Kaspar
pointed and spoke) but gives the learner nothing to update, and it breaks a
streak of greens (see kasparctl.game.problem).

How children press is another matter (Messiness): they hold a button, tap it
twice, squeeze both, press before Kaspar has finished asking. None of it
changes what they mean; the game must take the meaning and nothing more.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class TeacherError(ValueError):
    """A teacher probability outside [0, 1]; `key` names it."""

    def __init__(self, message: str, key: str) -> None:
        """The message says what is wrong; `key` names the probability."""
        super().__init__(message)
        self.key = key


@dataclass(frozen=True, slots=True)
class Teacher:
    """How often the children give a wrong green, a wrong red, or no answer."""

    p_wrong_green: float = 0.0
    p_wrong_red: float = 0.0
    p_no_answer: float = 0.0

    def __post_init__(self) -> None:
        """Refuse a probability outside [0, 1], naming it."""
        for name in ("p_wrong_green", "p_wrong_red", "p_no_answer"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise TeacherError(f"expected a probability in [0, 1], found {value!r}", name)

    @property
    def honest(self) -> bool:
        """Every guess answered, and answered right."""
        return self.p_wrong_green == 0.0 and self.p_wrong_red == 0.0 and self.p_no_answer == 0.0

    def answer(self, correct: bool, rng: np.random.Generator) -> bool | None:
        """True for green, False for red, None when nobody answers.

        An honest teacher draws nothing, and any other teacher draws exactly two
        numbers per guess: the vectorised simulator (kasparctl.sim.sweep) follows the
        same rule, so the two paths take the same random stream for one problem.
        """
        if self.honest:
            return correct
        no_answer_draw, mistake_draw = rng.random(2)
        if no_answer_draw < self.p_no_answer:
            return None
        p_mistake = self.p_wrong_red if correct else self.p_wrong_green
        return (not correct) if mistake_draw < p_mistake else correct


# A messy hold lasts this long (s): often past the 3 s of a researcher's hold.
HOLD_S = (0.6, 5.0)
# A squeeze of both buttons lasts this long (s).
SQUEEZE_S = (0.15, 4.0)
# An early press comes this long (s) after Kaspar starts asking.
EARLY_S = (0.2, 3.0)


@dataclass(frozen=True, slots=True)
class Messiness:
    """How often, per answer, children press in ways a keyfob must survive.

    p_hold: the button held (HOLD_S); p_double: pressed twice quickly; p_both: both
    buttons squeezed, the meant one first (SQUEEZE_S); p_early: pressed while Kaspar
    is still asking (EARLY_S after it starts), then again once asked if need be.
    """

    p_hold: float = 0.0
    p_double: float = 0.0
    p_both: float = 0.0
    p_early: float = 0.0

    def __post_init__(self) -> None:
        """Refuse a probability outside [0, 1], naming it."""
        for name in ("p_hold", "p_double", "p_both", "p_early"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise TeacherError(f"expected a probability in [0, 1], found {value!r}", name)

    @property
    def tidy(self) -> bool:
        """Every press a clean, single press after the question."""
        return not (self.p_hold or self.p_double or self.p_both or self.p_early)

    def action(self, button: str, rng: np.random.Generator) -> str:
        """The keyfob action for an answer `button`: a press, a hold, a double or a squeeze.

        A tidy group draws nothing (the children's random stream is as it was).
        """
        if self.tidy:
            return button
        kind, length = rng.random(2)
        if kind < self.p_both:
            return f"chord {button} {SQUEEZE_S[0] + length * (SQUEEZE_S[1] - SQUEEZE_S[0]):.3f}"
        if kind < self.p_both + self.p_double:
            return f"double {button}"
        if kind < self.p_both + self.p_double + self.p_hold:
            return f"hold {button} {HOLD_S[0] + length * (HOLD_S[1] - HOLD_S[0]):.3f}"
        return button

    def early(self, rng: np.random.Generator) -> float | None:
        """Seconds after Kaspar starts asking that an eager child presses, or None."""
        if self.tidy or self.p_early == 0.0:
            return None
        when, draw = (float(value) for value in rng.random(2))
        return EARLY_S[0] + when * (EARLY_S[1] - EARLY_S[0]) if draw < self.p_early else None
