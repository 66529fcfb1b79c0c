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

from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from hal.errors import KasparError
from kasparctl.config import GameSettings
from kasparctl.game.problem import TargetProgress
from kasparctl.game.recovery import all_rejected, rejected_after, to_reopen
from kasparctl.learning.learner import (
    BoolArray,
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


class SimulationError(KasparError, ValueError):
    """Game settings the simulator cannot play."""


class OptionError(SimulationError):
    """A value given for an option (its name begins the message) the simulation refuses.

    The command line reports it as a usage error (exit 2).
    """


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
    *,
    recover: bool = False,
) -> list[ProblemRecord]:
    """One group's game: every target in order, each until learned or given up.

    With a TeacherModel the children answer in turn, each with their own rates.
    `recover`: the game of kasparctl.game.recovery, with a researcher who knows the
    bags: when Kaspar is confused they re-open the names learned last down to the one
    learned wrong (none if all are right), and a re-opened target is asked again
    after the current one. Without it the random stream is the one it always was.
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
    progresses = [
        TargetProgress(game.correct_answers_to_learn, game.max_trials_per_target)
        for _ in range(n_targets)
    ]
    trials: list[list[TrialRecord]] = [[] for _ in range(n_targets)]
    first_offered: list[int] = [0] * n_targets
    last_candidates: list[BoolArray] = [offered.copy() for _ in range(n_targets)]
    doubt = _Doubt(n_targets)
    fresh = [False] * n_targets  # re-opened, not yet asked again
    target: int | None = 0
    while target is not None:
        progress = progresses[target]
        # The candidates change only between targets (and when a name is re-opened).
        candidates = offered.copy()
        if not trials[target]:
            first_offered[target] = int(candidates.sum())
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
                next_state = (
                    _next_open(progresses, target)
                    if recover and progress.done
                    else _next_state(target, progress.done, n_targets)
                )
                table = update(table, target, choice, params.reward(feedback), params, next_state)
            if fresh[target]:
                # The first guess on a re-opened target follows no answer (game.fold).
                fresh[target] = False
                trial = TrialRecord(choice, feedback, entropy, correct, False, False)
            else:
                trial = TrialRecord(choice, feedback, entropy, correct)
            trials[target].append(trial)
            confused = recover and doubt.answered(target, choice, feedback, progresses, offered)
            # The game takes no re-open once every target is done: the guessing is over.
            open_left = not all(p.done for p in progresses)
            before = list(doubt.reopened)
            if confused and open_left and doubt.reopen(progresses, offered, answers):
                candidates = offered.copy()
                for index, count in enumerate(doubt.reopened):
                    fresh[index] = fresh[index] or count > before[index]
        last_candidates[target] = candidates
        if progress.learned is not None:
            doubt.learned(target)
            if game.exclude_learned:
                offered[progress.learned] = False
        target = _next_open(progresses, target) if recover else _after(target, n_targets)
    return [
        ProblemRecord(
            group=group,
            target=index,
            answer=int(answers[index]),
            trials=tuple(trials[index]),
            learned=progresses[index].learned,
            final_q=tuple(float(q) for q in table[index]),
            entropy_after=entropy_bits(softmax(table[index], params.beta, last_candidates[index])),
            candidates=first_offered[index],
            reopened=doubt.reopened[index],
        )
        for index in range(n_targets)
    ]


class _Doubt:
    """The recovery rules of kasparctl.game.recovery, as the simulated game keeps them."""

    def __init__(self, n_targets: int) -> None:
        self.rejected: list[list[int]] = [[] for _ in range(n_targets)]
        self.order: list[int] = []
        self.confused: int | None = None
        self.reopened = [0] * n_targets

    def answered(
        self,
        target: int,
        choice: int,
        feedback: bool | None,
        progresses: Sequence[TargetProgress],
        offered: BoolArray,
    ) -> bool:
        """Count the answer; whether Kaspar is newly confused about `target`."""
        if feedback is not None:
            self.rejected[target] = rejected_after(self.rejected[target], choice, feedback)
        if progresses[target].done and self.confused == target:
            self.confused = None
        if self.confused == target:
            return False
        elsewhere = feedback is True and any(
            i != target and p.learned == choice for i, p in enumerate(progresses)
        )
        stuck = not progresses[target].done and all_rejected(
            offered.tolist(), self.rejected[target]
        )
        if elsewhere or stuck:
            self.confused = None if progresses[target].done else target
            return True
        return False

    def learned(self, target: int) -> None:
        self.order.append(target)

    def reopen(
        self, progresses: list[TargetProgress], offered: BoolArray, answers: Sequence[int]
    ) -> bool:
        """The researcher's re-opens; whether they gave any."""
        learned = [(t, progresses[t].learned) for t in self.order]
        count = to_reopen([(t, label) for t, label in learned if label is not None], answers)
        for _ in range(count):
            target = self.order.pop()
            label = progresses[target].learned
            assert label is not None
            progress = progresses[target]
            progress.learned, progress.streak, progress.streak_label = None, 0, None
            offered[label] = True
            self.reopened[target] += 1
        if count:
            self.confused = None
        return count > 0


def _after(target: int, n_targets: int) -> int | None:
    return target + 1 if target + 1 < n_targets else None


def _next_open(progresses: Sequence[TargetProgress], current: int) -> int | None:
    """The next target asked: the first not done (a re-opened one comes back)."""
    return next(
        (i for i, p in enumerate(progresses) if i != current and not p.done),
        None if progresses[current].done else current,
    )


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
    *,
    recover: bool = False,
) -> list[ProblemRecord]:
    """`groups` groups playing `game`, every problem of each."""
    return [
        record
        for records in iter_groups(groups, game, params, teacher, seed, recover=recover)
        for record in records
    ]


def iter_groups(
    groups: int,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    seed: int | None,
    *,
    recover: bool = False,
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
            rng = np.random.default_rng(stream)
            yield simulate_group(game, params, teacher, rng, group, recover=recover)


def summarise_study(
    groups: int,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher | TeacherModel,
    seed: int | None,
    *,
    recover: bool = False,
) -> StudyStats:
    """The statistics of simulate_study, accumulated group by group in constant memory."""
    return summarise_groups(iter_groups(groups, game, params, teacher, seed, recover=recover))


def summarise_groups(groups: Iterable[list[ProblemRecord]]) -> StudyStats:
    """The statistics of each group's problems (iter_groups), held a batch at a time."""
    accumulator = StatsAccumulator()
    batch: list[ProblemRecord] = []
    for records in groups:
        batch.extend(records)
        if len(batch) >= 4096:
            accumulator.add(batch)
            batch = []
    accumulator.add(batch)
    return accumulator.result()
