"""When a target counts as learned: the rule the game and the simulator share.

A target (a bag, or a location in the pilot) is one problem. It is learned
once the children have answered green to the same label a number of times in
a row (GameSettings.correct_answers_to_learn, 2 by default: the pilot's
minimum of 2 trials per association), and it is given up, left to the
researcher, after GameSettings.max_trials_per_target guesses.

Pure and tiny on purpose: it knows nothing of the learner, the robot or the
simulator, so the game and the simulator cannot drift apart on this rule.
"""

from __future__ import annotations

from dataclasses import dataclass

from hal.errors import KasparError


class ProblemError(KasparError, ValueError):
    """A guess recorded on a problem that is already over, or unusable limits."""


@dataclass(slots=True)
class TargetProgress:
    """Progress on one target. Labels are action indices (columns of the Q table)."""

    correct_answers_to_learn: int = 2
    max_trials: int = 30
    trials: int = 0
    # Greens in a row for `streak_label`; a red, a green for another label or an
    # unanswered guess starts the count again.
    streak: int = 0
    streak_label: int | None = None
    learned: int | None = None

    def __post_init__(self) -> None:
        """Refuse limits no target could meet."""
        if self.correct_answers_to_learn < 1:
            raise ProblemError(
                f"correct_answers_to_learn: expected >= 1, found {self.correct_answers_to_learn}"
            )
        if self.max_trials < self.correct_answers_to_learn:
            raise ProblemError(
                f"max_trials: expected >= correct_answers_to_learn "
                f"({self.correct_answers_to_learn}), found {self.max_trials}"
            )

    @property
    def done(self) -> bool:
        """Learned or given up: no more guesses on this target."""
        return self.learned is not None or self.trials >= self.max_trials

    @property
    def given_up(self) -> bool:
        """Not learned within max_trials guesses: left to the researcher."""
        return self.learned is None and self.trials >= self.max_trials

    def record(self, label: int, feedback: bool | None) -> bool:
        """Count one guess of `label` with its answer (None: nobody answered).

        Returns True when this guess made the target learned. An unanswered
        guess still counts as a trial (Kaspar did point and speak), and it breaks
        the streak: "in a row" means on consecutive guesses.
        """
        if self.done:
            raise ProblemError(
                f"the target is already {'learned' if self.learned is not None else 'given up'} "
                f"after {self.trials} trials"
            )
        self.trials += 1
        if feedback is True:
            self.streak = self.streak + 1 if label == self.streak_label else 1
            self.streak_label = label
        else:
            self.streak = 0
            self.streak_label = None
        if self.streak >= self.correct_answers_to_learn:
            self.learned = label
            return True
        return False
