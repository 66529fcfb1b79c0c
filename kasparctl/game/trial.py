"""One guess of step 4, as arithmetic: plan the question, then score the answer.

Pure: no I/O, no asyncio, no clock. The game (kasparctl.game.machine) plans a
trial, speaks and points as the plan says, waits for the children, and has
the answer scored into the trial record it writes; GameState.apply then makes
the record's values the learner's. So what the learner does can be tested
without a robot, and the live game, a resume and a replay share one rule.

The choice is drawn from a copy of the learner's generator: the generator
moves on only when the trial is recorded (its state after the draw is in the
record), so a pause or a crash before the answer asks the very same question
again.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from msgspec import UNSET

from kasparctl.config import GameSettings, SessionPlan
from kasparctl.game.fold import flags
from kasparctl.game.phrases import PhraseBook
from kasparctl.game.records import Button, QuestionRecord, TrialRecord
from kasparctl.game.recovery import rejected_after
from kasparctl.game.scripts import Script
from kasparctl.game.state import GameState
from kasparctl.learning.learner import (
    FloatArray,
    LearnerParams,
    choose,
    entropy_bits,
    softmax,
    update,
)


@dataclass(frozen=True, slots=True)
class TrialPlan:
    """The question of one trial: who answers, where Kaspar points, what it guesses."""

    trial: int  # the trial's number in the session
    problem_trial: int  # its number on this target
    target: int
    target_name: str
    child: str  # a first name from the plan, or "child one"...
    child_index: int
    candidates: tuple[str, ...]  # the toys still offered, in the game's order
    probabilities: FloatArray  # Eq. 2 over every toy, 0 for those not offered
    entropy: float  # Eq. 3, bits
    band: str | None  # how sure Kaspar says it is; None when the plan keeps it silent
    # The phrase key of the uncertainty line (the band's, or why it is sure); None if silent.
    uncertainty_line: str | None
    choice: int
    toy: str
    # The learner's generator after the draw: it moves on only once the trial is recorded.
    learner_rng: dict[str, Any]
    # The toy drawn is the one Kaspar thinks likeliest: neither its words nor its body
    # may look sure before naming another.
    likeliest: bool = True


@dataclass(frozen=True, slots=True)
class Answer:
    """What happened while Kaspar asked: its words, when it finished, and the children's key."""

    spoken: tuple[str, ...]
    question_end: float
    button: Button
    pressed_at: float
    # Pressed in the question's last words (before question_end): taken as the answer.
    in_question: bool = False


def plan_trial(
    state: GameState,
    params: LearnerParams,
    settings: GameSettings,
    session_plan: SessionPlan,
    group_size: int,
    book: PhraseBook,
    script: Script,
) -> TrialPlan:
    """The next question of the session at `state`; `state` itself is not changed.

    How sure Kaspar says it is comes from `script`; a child without a first name is
    called by the book's names.child.
    """
    target = state.target
    child_index = state.turn % group_size
    candidates = state.candidates
    probabilities = softmax(state.learner.table[target], params.beta, candidates)
    entropy = entropy_bits(probabilities)
    # Draw from a copy: see the module's docstring.
    rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = state.learner.rng.bit_generator.state
    choice = choose(probabilities, rng)
    offered = int(candidates.sum())
    band = script.level(entropy, offered) if session_plan.says_uncertainty else None
    progress = state.progress[target]
    confirmed = progress.streak > 0 and progress.streak_label == choice
    favourite = bool(probabilities[choice] >= probabilities.max())
    return TrialPlan(
        trial=state.trials + 1,
        problem_trial=state.progress[target].trials + 1,
        target=target,
        target_name=settings.targets[target],
        child=(
            session_plan.children[child_index]
            if session_plan.children
            else book.fill("names.child", number=str(child_index + 1))
        ),
        child_index=child_index,
        candidates=tuple(
            toy for toy, offered in zip(settings.toys, state.offered, strict=True) if offered
        ),
        probabilities=probabilities,
        entropy=entropy,
        band=band,
        uncertainty_line=None if band is None else script.line_key(
            band, offered, confirmed, favourite
        ),
        choice=choice,
        toy=settings.toys[choice],
        learner_rng=dict(rng.bit_generator.state),
        likeliest=favourite,
    )


def question_record(plan: TrialPlan) -> QuestionRecord:
    """The record of the question `plan` asks, written before Kaspar asks it."""
    return QuestionRecord(
        trial=plan.trial,
        problem_trial=plan.problem_trial,
        target=plan.target_name,
        target_index=plan.target,
        child=plan.child,
        child_index=plan.child_index,
        candidates=list(plan.candidates),
        probabilities=plan.probabilities.tolist(),
        entropy=plan.entropy,
        band=plan.band,
        choice=plan.toy,
        choice_index=plan.choice,
    )


def score_answer(
    plan: TrialPlan,
    answer: Answer,
    state: GameState,
    params: LearnerParams,
    settings: GameSettings,
    session_plan: SessionPlan,
    *,
    recovery: bool = False,
) -> TrialRecord:
    """The trial record of `plan` answered with `answer`, for the session at `state`.

    `recovery` (a session planned with it, kasparctl.game.recovery): the record also
    says which labels stand rejected on this target after the answer.

    The learner's reward and Q after (Eq. 1, towards the next open target once
    this one is done), the paper's perseverative and win-shift flags, and, where
    the plan has an answer key, whether the guess and the children were right.
    The key is read only here, for the research record: the learner never sees it.
    """
    target, choice = plan.target, plan.choice
    green = answer.button == "green"
    reward = params.reward(green)
    progress_after = dataclasses.replace(state.progress[target])
    progress_after.record(choice, green)
    next_target = target if not progress_after.done else next_open_target(state, target)
    q_after = update(state.learner.table, target, choice, reward, params, next_target)[target]
    perseverative, win_shift = flags(state.previous, choice)
    answer_key = session_plan.answer_key
    correct = None if not answer_key else settings.toys.index(answer_key[target]) == choice
    return TrialRecord(
        trial=plan.trial,
        problem_trial=plan.problem_trial,
        step="guessing",
        target=plan.target_name,
        target_index=target,
        child=plan.child,
        child_index=plan.child_index,
        candidates=list(plan.candidates),
        probabilities=plan.probabilities.tolist(),
        entropy=plan.entropy,
        band=plan.band,
        spoken=list(answer.spoken),
        choice=plan.toy,
        choice_index=choice,
        feedback=answer.button,
        question_end=answer.question_end,
        feedback_at=answer.pressed_at,
        reaction_time=answer.pressed_at - answer.question_end,
        reward=reward,
        q_before=state.learner.table[target].tolist(),
        q_after=q_after.tolist(),
        learner_rng=plan.learner_rng,
        perseverative=perseverative,
        win_shift=win_shift,
        correct=correct,
        feedback_right=None if correct is None else correct == green,
        learned=progress_after.learned is not None,
        in_question=True if answer.in_question else UNSET,
        rejected=_rejected(state, target, choice, green) if recovery else UNSET,
    )


def _rejected(state: GameState, target: int, choice: int, green: bool) -> list[int]:
    before = [] if state.rejected is UNSET else state.rejected[target]
    return rejected_after(before, choice, green)


def next_open_target(state: GameState, current: int) -> int | None:
    """s_{t+1} of Eq. 1 once a target is done: the next one not done, if any."""
    return next((i for i, p in enumerate(state.progress) if i != current and not p.done), None)
