"""A simulated group of children answering Kaspar's guesses.

The pilot's children made 3 mistakes in 202 trials, all of them greens for a
wrong guess; the model lets a simulation add such mistakes, the opposite ones,
and guesses nobody answers. An unanswered guess counts as a trial (Kaspar
pointed and spoke) but gives the learner nothing to update, and it breaks a
streak of greens (see kasparctl.game.problem).
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
