"""Simulated groups of children teaching Kaspar, one guess at a time.

This path calls the learner exactly as the game does (one Q row per target,
softmax over the candidates, the entropy Kaspar speaks, choose, the answer,
Eq. 1) and applies the shared rule of kasparctl.game.problem, so its statistics are
what the game would show with these teachers. kasparctl.sim.sweep is the fast
vectorised twin for parameter sweeps; the tests hold the two together.

Variants (GameSettings.variant):
- "pilot": each location is its own problem over all the toys (the paper's
  study: 3 locations and 6 toys per group);
- "names": one bag per toy; Kaspar stays on a bag until it is learned (or
  given up), and a learned name is no longer offered for the later bags.

Reproducible: one seed gives identical records. Each group draws from its own
stream spawned from the seed, so group g is the same whatever the number of
groups run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

import numpy as np

from kasparctl.config import GameSettings
from kasparctl.game.problem import TargetProgress
from kasparctl.learning.learner import (
    LearnerParams,
    choose,
    entropy_bits,
    new_table,
    softmax,
    update,
)
from kasparctl.learning.study_stats import ProblemRecord, StatsAccumulator, StudyStats, TrialRecord
from kasparctl.sim.teacher import Teacher, TeacherModel

PILOT_LOCATIONS = ("location 1", "location 2", "location 3")


class SimulationError(ValueError):
    """Game settings the simulator cannot play."""


def pilot_game(**changes: object) -> GameSettings:
    """The paper's pilot: 3 locations, the 6 default toys, 2 greens in a row to learn."""
    settings: dict[str, object] = {"variant": "pilot", "locations": PILOT_LOCATIONS}
    settings.update(changes)
    return GameSettings(**settings)  # type: ignore[arg-type]


def playable(game: GameSettings) -> GameSettings:
    """Check a game the simulator is asked to play; a pilot without locations gets the paper's 3."""
    if game.variant == "pilot" and not game.locations:
        game = pilot_game(
            toys=game.toys,
            correct_answers_to_learn=game.correct_answers_to_learn,
            max_trials_per_target=game.max_trials_per_target,
        )
    if len(game.toys) < 1:
        raise SimulationError("game.toys: expected at least 1 toy, found none")
    if game.correct_answers_to_learn < 1:
        raise SimulationError(
            f"game.correct_answers_to_learn: expected >= 1, found {game.correct_answers_to_learn}"
        )
    if game.max_trials_per_target < game.correct_answers_to_learn:
        raise SimulationError(
            f"game.max_trials_per_target: expected >= {game.correct_answers_to_learn}, "
            f"found {game.max_trials_per_target}"
        )
    return game


def draw_answer_key(game: GameSettings, rng: np.random.Generator) -> tuple[int, ...]:
    """The correct toy of each target: a shuffle of the toys over the bags, or
    distinct toys for the pilot's locations (any toys if there are more locations)."""
    n_toys, n_targets = len(game.toys), len(game.targets)
    if game.variant == "names":
        return tuple(int(toy) for toy in rng.permutation(n_toys))
    return tuple(int(toy) for toy in rng.choice(n_toys, size=n_targets, replace=n_targets > n_toys))


def simulate_group(
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    rng: np.random.Generator,
    group: int = 0,
    answers: Sequence[int] | None = None,
) -> list[ProblemRecord]:
    """One group's game: every target in order, each until learned or given up.

    With a TeacherModel the children answer in turn, each with their own rates.
    """
    n_targets, n_toys = len(game.targets), len(game.toys)
    if answers is None:
        answers = draw_answer_key(game, rng)
    if len(answers) != n_targets:
        raise SimulationError(
            f"answers: expected {n_targets} (one per target), found {len(answers)}"
        )
    table = new_table(n_targets, n_toys, params)
    offered = np.ones(n_toys, dtype=bool)
    turn = 0
    records: list[ProblemRecord] = []
    for target in range(n_targets):
        # The candidates change only between targets, when a name is learned.
        candidates = offered.copy()
        progress = TargetProgress(game.correct_answers_to_learn, game.max_trials_per_target)
        trials: list[TrialRecord] = []
        while not progress.done:
            probabilities = softmax(table[target], params.beta, candidates)
            entropy = entropy_bits(probabilities)
            choice = choose(probabilities, rng)
            correct = choice == answers[target]
            feedback = (
                teacher.answer(correct, rng, turn)
                if isinstance(teacher, TeacherModel)
                else teacher.answer(correct, rng)
            )
            turn += 1
            progress.record(choice, feedback)
            if feedback is not None:
                table = update(
                    table,
                    target,
                    choice,
                    params.reward(feedback),
                    params,
                    _next_state(target, progress.done, n_targets),
                )
            trials.append(TrialRecord(choice, feedback, entropy, correct))
        if progress.learned is not None and game.exclude_learned:
            offered[progress.learned] = False
        records.append(
            ProblemRecord(
                group=group,
                target=target,
                answer=int(answers[target]),
                trials=tuple(trials),
                learned=progress.learned,
                final_q=tuple(float(q) for q in table[target]),
                entropy_after=entropy_bits(softmax(table[target], params.beta, candidates)),
                candidates=int(candidates.sum()),
            )
        )
    return records


def _next_state(target: int, done: bool, n_targets: int) -> int | None:
    """s_{t+1} of Eq. 1 is the target of the next guess; None after the last one.

    Only matters when gamma > 0 (the paper's value is taken as 0).
    """
    if not done:
        return target
    return target + 1 if target + 1 < n_targets else None


def simulate_study(
    groups: int,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    seed: int | None,
    on_group: Callable[[int], None] | None = None,
) -> list[ProblemRecord]:
    """`groups` groups playing `game`; `on_group(g)` after each, for a progress bar."""
    return [
        record
        for records in iter_groups(groups, game, params, teacher, seed, on_group)
        for record in records
    ]


def iter_groups(
    groups: int,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    seed: int | None,
    on_group: Callable[[int], None] | None = None,
) -> Iterator[list[ProblemRecord]]:
    """Each group's problems in turn, as simulate_study plays them, never held together."""
    if groups < 1:
        raise SimulationError(f"groups: expected >= 1, found {groups}")
    game = playable(game)
    root = np.random.SeedSequence(seed)
    # Spawned a block at a time: the same streams as spawning all at once, in bounded memory.
    block = 4096
    for start in range(0, groups, block):
        for offset, stream in enumerate(root.spawn(min(block, groups - start))):
            group = start + offset
            yield simulate_group(game, params, teacher, np.random.default_rng(stream), group)
            if on_group is not None:
                on_group(group)


def summarise_study(
    groups: int,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    seed: int | None,
    on_group: Callable[[int], None] | None = None,
) -> StudyStats:
    """The statistics of simulate_study, accumulated group by group in constant memory."""
    accumulator = StatsAccumulator()
    batch: list[ProblemRecord] = []
    for records in iter_groups(groups, game, params, teacher, seed, on_group):
        batch.extend(records)
        if len(batch) >= 4096:
            accumulator.add(batch)
            batch = []
    accumulator.add(batch)
    return accumulator.result()
