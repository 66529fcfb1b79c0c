"""`simulate --design TARGET`: a learner profile for a target number of guesses per game.

Children perceive how long Kaspar takes to learn the game's names, and alpha and
beta alone barely change it: with no prior knowledge the right toy is still found
among the toys left, about half-way through them, whatever the learner. What does
change it is how many greens in a row Kaspar needs (correct_answers_to_learn). So
the search runs over the greens first, and over alpha and beta within each only
to fine-tune, keeping every candidate coherent: Kaspar may come back to a toy just
answered red, or leave one just answered green, no more often than the paper's
learner does in the same game (within the simulation's error). The answer is the
coherent candidate whose mean guesses per game is nearest the target.

The candidates play in kasparctl.sim.studies (vectorised whole groups), every one
with the same seed, so their differences are the settings', not the draws'.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np

from kasparctl.config import GameSettings
from kasparctl.learning.learner import LearnerParams
from kasparctl.sim.simulate import OptionError, playable
from kasparctl.sim.studies import GroupTable, concatenate, simulate_groups
from kasparctl.sim.teacher import Teacher, TeacherModel

# The greens to learn tried, and the alpha and beta within each (the paper's among them).
GREENS = (1, 2, 3, 4, 5, 6)
ALPHAS = (0.4, 0.6, 0.8, 1.0)
BETAS = (6.0, 8.0, 10.0, 12.0)
# Groups per candidate: the mean guesses per names game to about +-0.2 (sd about 6).
DEFAULT_DESIGN_GROUPS = 4000
# A candidate is coherent while its exploratory rates stay within this many standard
# errors of the paper learner's (a rate of counted events: sd about sqrt(rate / trials)).
COHERENCE_SE = 3.0


@dataclass(frozen=True)
class Figures:
    """What children would see of one learner in one game, over the simulated groups."""

    guesses_per_game: float
    guesses_per_game_sd: float
    trials_per_problem: float
    # Per guess: the same toy again right after a right red; another right after a right green.
    repeat_red_rate: float
    leave_green_rate: float
    given_up: int

    @classmethod
    def of(cls, table: GroupTable) -> Figures:
        """The figures of a table of groups (every problem, learned or given up)."""
        per_game = table.trials.sum(axis=1)
        trials = float(per_game.sum())
        repeats = float((table.perseverative - table.perseverative_after_wrong).sum())
        leaves = float((table.win_shift - table.win_shift_after_wrong).sum())
        return cls(
            guesses_per_game=float(per_game.mean()),
            guesses_per_game_sd=float(per_game.std(ddof=1)) if len(per_game) > 1 else 0.0,
            trials_per_problem=trials / table.trials.size,
            repeat_red_rate=repeats / trials,
            leave_green_rate=leaves / trials,
            given_up=int((table.learned < 0).sum()),
        )

    def plain(self) -> dict[str, Any]:
        """JSON-ready."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Candidate:
    """One learner tried: its greens to learn, alpha and beta, and its figures."""

    correct_answers_to_learn: int
    alpha: float
    beta: float
    figures: Figures

    def plain(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "correct_answers_to_learn": self.correct_answers_to_learn,
            "alpha": self.alpha,
            "beta": self.beta,
            **self.figures.plain(),
        }


@dataclass(frozen=True)
class DesignAnswer:
    """The profile found for the target, beside the paper's learner in the same game."""

    target: float
    context: dict[str, Any]
    paper: Candidate
    best: Candidate
    coherent: int
    tried: int

    def plain(self) -> dict[str, Any]:
        """One JSON object: the target, the profile found, the paper's figures."""
        return {
            **self.context,
            "target": self.target,
            "profile": self.best.plain(),
            "paper": self.paper.plain(),
            "coherent": self.coherent,
            "tried": self.tried,
        }

    def text(self) -> str:
        """The profile as kaspar.toml lines, its figures beside the paper learner's."""
        best, paper = self.best, self.paper
        context = self.context
        lines = [
            f"target: {self.target:g} guesses per game ({context['variant']}, "
            f"{context['toys']} toys, {context['groups']} groups per candidate, "
            f"seed {context['seed']})",
            f"{self.coherent} of {self.tried} candidates coherent (they repeat a red or "
            "leave a green no more often than the paper's learner)",
            "",
            "[learner.profiles.designed]",
            f"correct_answers_to_learn = {best.correct_answers_to_learn}",
            f"alpha = {best.alpha:g}",
            f"beta = {best.beta:g}",
            "",
            f"{'':30} {'designed':>12} {'paper':>12}",
        ]
        rows: tuple[tuple[str, Callable[[Candidate], str]], ...] = (
            ("greens to learn", lambda c: f"{c.correct_answers_to_learn}"),
            ("guesses per game", lambda c: f"{c.figures.guesses_per_game:.2f}"),
            ("guesses per game, sd", lambda c: f"{c.figures.guesses_per_game_sd:.2f}"),
            ("trials per problem", lambda c: f"{c.figures.trials_per_problem:.2f}"),
            ("repeats a red (per guess)", lambda c: f"{100 * c.figures.repeat_red_rate:.2f}%"),
            ("leaves a green (per guess)", lambda c: f"{100 * c.figures.leave_green_rate:.2f}%"),
            ("problems given up", lambda c: f"{c.figures.given_up}"),
        )
        for label, cell in rows:
            lines.append(f"{label:30} {cell(best):>12} {cell(paper):>12}")
        miss = best.figures.guesses_per_game - self.target
        if abs(miss) > 0.05 * self.target:
            lines += ["", f"the nearest coherent learner is {miss:+.2f} guesses from the target"]
        return "\n".join(lines)


def figures(
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    groups: int,
    seed: int,
) -> Figures:
    """One learner's figures in `game`, over `groups` simulated groups."""
    rng = np.random.default_rng(seed)
    return Figures.of(concatenate(list(simulate_groups(groups, game, params, teacher, rng))))


def design(
    target: float,
    game: GameSettings,
    base: LearnerParams,
    teacher: Teacher | TeacherModel,
    groups: int,
    seed: int,
) -> DesignAnswer:
    """The coherent learner whose mean guesses per game in `game` is nearest `target`.

    `base` gives gamma, the rewards and Q0 (kept); the paper's alpha and beta with the
    game's own greens to learn set the coherence limits. OptionError for a target no
    game can have.
    """
    if not (math.isfinite(target) and target > 0):
        raise OptionError(f"--design: expected a number of guesses above 0, found {target!r}")
    paper_params = dataclasses.replace(base, alpha=0.6, beta=8.0)
    paper = Candidate(
        game.correct_answers_to_learn, 0.6, 8.0,
        figures(game, paper_params, teacher, groups, seed),
    )  # fmt: skip
    limits = _limits(paper.figures, groups)
    tried = 0
    coherent: list[Candidate] = []
    for greens in GREENS:
        if greens > game.max_trials_per_target:
            break
        shaped = playable(msgspec.structs.replace(game, correct_answers_to_learn=greens))
        for alpha in ALPHAS:
            for beta in BETAS:
                params = dataclasses.replace(base, alpha=alpha, beta=beta)
                found = figures(shaped, params, teacher, groups, seed)
                tried += 1
                if found.repeat_red_rate <= limits[0] and found.leave_green_rate <= limits[1]:
                    coherent.append(Candidate(greens, alpha, beta, found))
    if not coherent:
        coherent = [paper]
    best = min(coherent, key=lambda c: (abs(c.figures.guesses_per_game - target),
                                        abs(c.alpha - 0.6) + abs(c.beta - 8.0) / 10))  # fmt: skip
    context = {
        "variant": game.variant,
        "toys": len(game.toys),
        "groups": groups,
        "seed": seed,
    }
    return DesignAnswer(target, context, paper, best, len(coherent), tried)


def _limits(paper: Figures, groups: int) -> tuple[float, float]:
    """The highest repeat-a-red and leave-a-green rates a coherent learner may have."""
    trials = paper.guesses_per_game * groups
    return (
        paper.repeat_red_rate + COHERENCE_SE * math.sqrt(max(paper.repeat_red_rate, 1.0 / trials)
                                                         / trials),
        paper.leave_green_rate + COHERENCE_SE * math.sqrt(max(paper.leave_green_rate, 1.0 / trials)
                                                          / trials),
    )  # fmt: skip
