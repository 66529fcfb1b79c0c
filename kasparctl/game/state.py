"""What a session has reached, changed only by applying its own records.

The game writes a record (fsynced) and then applies it to this state; a
resumed session applies the records written after its last snapshot with the
very same function. So the live path and the resume path cannot disagree, and
the snapshot is only a cache of what the records already say.

Records that change the state: step, pose, trial, undo, confused, reopen, and
a command that paused or resumed (kasparctl.game.records.STATE_CHANGING). Every other kind
(presses, prompts, faults, HAL events) is history only. The snapshot is this
struct as JSON, encoded and decoded by kasparctl.game.session.

What every reader of the records also asks (the answer a guess follows for its
flags, whether Kaspar is confused) follows the rules of kasparctl.game.fold,
which the live view, STATUS= and the research read the records with.
"""

from __future__ import annotations

import dataclasses
import statistics
from typing import Any

import msgspec
import numpy as np
from msgspec import UNSET, UnsetType

from hal.errors import KasparError
from kasparctl.config import GameSettings
from kasparctl.game import fold
from kasparctl.game.problem import TargetProgress
from kasparctl.game.records import (
    STATE_CHANGING,
    AnyRecord,
    CommandRecord,
    Confirmation,
    ConfusedRecord,
    PoseRecord,
    Record,
    ReopenRecord,
    RotationRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.stages import STEPS
from kasparctl.learning.learner import BoolArray, LearnerParams, LearnerState
from kasparctl.vocabulary import Command

__all__ = ["STEPS", "GameState", "StateError", "UndoEntry", "far_from", "median_pose", "restore"]


class StateError(KasparError, ValueError):
    """A record that does not fit the state it is applied to, or a damaged snapshot."""


class UndoEntry(msgspec.Struct, frozen=True):
    """What the last answer changed, as it was before: what a double red puts back."""

    trial: int
    q_row: list[float]
    progress: TargetProgress
    offered: list[bool]
    turn: int
    target: int
    previous: tuple[int, bool] | None
    # Fields added later are UNSET unless the state had them (older snapshots read and
    # save unchanged). A re-open rather than an answer: the target re-opened, whose
    # `progress` is above (kasparctl.game.recovery).
    reopened: int | UnsetType = UNSET
    learned_order: list[int] | UnsetType = UNSET
    confused: int | UnsetType | None = UNSET
    # The labels rejected on `target` before the answer.
    rejected: list[int] | UnsetType = UNSET


class GameState(msgspec.Struct, eq=False):
    """A session's progress: the step, the learner, each target's progress, the taught poses."""

    step: str  # "idle", one of STEPS, "finished" or "stopped"
    learner: LearnerState
    progress: list[TargetProgress]
    # Labels still offered: a learned name is withdrawn from the other bags.
    offered: list[bool]
    trials: int = 0  # trials recorded in this session; the next one is trials + 1
    turn: int = 0  # children answer in rotation: child (turn % group size)
    target: int = 0  # the target Kaspar is guessing
    # The answer the next guess on the current target follows (choice, green), for the
    # paper's perseverative-error and win-shift flags (kasparctl.game.fold.flags).
    previous: tuple[int, bool] | None = None
    # target -> joints: where Kaspar points (the median of every pose shown for it).
    poses: dict[str, dict[str, float]] = msgspec.field(default_factory=dict)
    teach_round: int = 0
    teach_bag: int = 0
    # What the last child answer changed, so the researcher's undo can take it back.
    undo: UndoEntry | None = None
    paused: bool = False
    # Fields added later are UNSET until used, so older snapshots read and save unchanged.
    # target -> every pose shown for it, in order (pose records with a rule).
    shown_poses: dict[str, list[dict[str, float]]] | UnsetType = UNSET
    # The step a stopped session was stopped in: where it carries on if reopened.
    stopped_from: str | UnsetType = UNSET
    # Recovery (kasparctl.game.recovery), set by the records of sessions planned with it:
    # per target, the labels whose last answer there is red;
    rejected: list[list[int]] | UnsetType = UNSET
    # the targets learned, in the order they were learned (a re-open takes the last);
    learned_order: list[int] | UnsetType = UNSET
    # the target Kaspar said it is confused about, until it is done or a name re-opened.
    confused: int | UnsetType | None = UNSET
    # The children the researcher took out of step 4's rotation (kasparctl.game.rotation).
    away: list[int] | UnsetType = UNSET

    @classmethod
    def new(cls, settings: GameSettings, params: LearnerParams, seed: int | None) -> GameState:
        """The state of a session that has not started: a fresh learner seeded with `seed`."""
        n_targets, n_labels = len(settings.targets), len(settings.toys)
        return cls(
            step="idle",
            learner=LearnerState.fresh(n_targets, n_labels, params, seed),
            progress=[
                TargetProgress(settings.correct_answers_to_learn, settings.max_trials_per_target)
                for _ in range(n_targets)
            ],
            offered=[True] * n_labels,
        )

    # -- questions the game asks ------------------------------------------------

    @property
    def candidates(self) -> BoolArray:
        """The labels still offered, as the learner's candidate mask."""
        return np.array(self.offered, dtype=bool)

    @property
    def all_done(self) -> bool:
        """Every target learned or given up: step 4 is over."""
        return all(progress.done for progress in self.progress)

    def first_open_target(self) -> int | None:
        """The first target neither learned nor given up, if any."""
        return next((i for i, progress in enumerate(self.progress) if not progress.done), None)

    def learned_targets(self) -> list[int]:
        """The learned targets, the one learned last at the end (index order before recovery)."""
        if self.learned_order is not UNSET:
            return list(self.learned_order)
        return [i for i, progress in enumerate(self.progress) if progress.learned is not None]

    def bags_taught(self, settings: GameSettings) -> bool:
        """Whether every target has a taught pose (step 2 can end)."""
        return all(target in self.poses for target in settings.targets)

    # -- the one mutator --------------------------------------------------------

    def apply(self, record: Record, settings: GameSettings) -> None:
        """Change the state as `record` says; a record that changes nothing is ignored."""
        if isinstance(record, StepRecord):
            self._apply_step(record.to)
        elif isinstance(record, PoseRecord):
            self._apply_pose(record, settings)
        elif isinstance(record, TrialRecord):
            self._apply_trial(record, settings)
        elif isinstance(record, UndoRecord):
            self._apply_undo(record)
        elif isinstance(record, ConfusedRecord):
            self.confused = fold.standing(record.target_index, self._done())
        elif isinstance(record, ReopenRecord):
            if record.taken_back is True:
                self._apply_reopen_taken_back(record)
            else:
                self._apply_reopen(record)
        elif isinstance(record, RotationRecord):
            self._apply_rotation(record)
        elif (
            isinstance(record, CommandRecord) and record.applied and record.command is Command.PAUSE
        ):
            self.paused = record.confirm == Confirmation.PAUSE

    def _apply_rotation(self, record: RotationRecord) -> None:
        away = set() if self.away is UNSET else set(self.away)
        if record.event == "away":
            away.add(record.child_index)
        elif record.event == "back":
            away.discard(record.child_index)
        if record.event != "skipped" or self.away is not UNSET:
            self.away = sorted(away)
        self.turn = record.turn

    def _done(self) -> list[bool]:
        return [progress.done for progress in self.progress]

    def _apply_step(self, step: str) -> None:
        if step == "stopped" and self.step in STEPS:
            self.stopped_from = self.step
        elif step in STEPS and self.step == "stopped":
            self.stopped_from = UNSET  # reopened
        self.step = step
        asked = self.progress[self.target] if 0 <= self.target < len(self.progress) else None
        if step == "guessing" and (asked is None or asked.done):
            # The target asked stays asked until it is done (a re-opened one waits its
            # turn, after a stop too): the game leaves a target only once it is done.
            open_target = self.first_open_target()
            self.target = self.target if open_target is None else open_target

    def _apply_pose(self, record: PoseRecord, settings: GameSettings) -> None:
        target = settings.targets[record.bag]
        if record.rule is UNSET:
            # Recorded before the median rule: the last round's pose was the one used.
            self.poses[target] = dict(record.pose)
        else:
            if self.shown_poses is UNSET:
                self.shown_poses = {}
            shown = self.shown_poses.setdefault(target, [])
            shown.append(dict(record.pose))
            self.poses[target] = median_pose(shown)
        if record.check_again is True:
            return  # the same bag is asked once more
        self.teach_bag = record.bag + 1
        if self.teach_bag >= len(settings.targets):
            self.teach_bag = 0
            self.teach_round += 1

    def _apply_trial(self, record: TrialRecord, settings: GameSettings) -> None:
        target, choice = record.target_index, record.choice_index
        if target != self.target:
            raise StateError(
                f"trial {record.trial}: for target {target}, state is at {self.target}"
            )
        self.undo = UndoEntry(
            trial=record.trial,
            q_row=self.learner.table[target].tolist(),
            progress=dataclasses.replace(self.progress[target]),
            offered=list(self.offered),
            turn=self.turn,
            target=self.target,
            previous=self.previous,
            # Planned with recovery: what the answer may change, as it was.
            **(_recovery_before(self, target) if record.rejected is not UNSET else {}),
        )
        self.learner.table[target] = np.array(record.q_after, dtype=np.float64)
        # The generator as it was after this guess's draw, so a resume draws on from there.
        self.learner.rng.bit_generator.state = record.learner_rng
        self.trials = record.trial
        self.turn += 1
        progress = self.progress[target]
        learned_now = progress.record(choice, record.green)
        self.previous = fold.followed(choice, record.green, progress.done)
        if record.rejected is not UNSET:
            # Planned with recovery: what was rejected here, and the order names are learned.
            if self.rejected is UNSET:
                self.rejected = [[] for _ in self.progress]
            self.rejected[target] = list(record.rejected)
            if learned_now:
                order = [i for i in self.learned_targets() if i != target]
                self.learned_order = [*order, target]
        if self.confused is not UNSET:
            self.confused = fold.standing(self.confused, self._done())
        if progress.done:
            if learned_now and settings.exclude_learned:
                self.offered[choice] = False
            next_target = self.first_open_target()
            self.target = self.target if next_target is None else next_target

    def _apply_undo(self, record: UndoRecord) -> None:
        undo = self.undo
        if undo is None or undo.trial != record.trial or undo.reopened is not UNSET:
            raise StateError(f"undo of trial {record.trial}: it is not the last answer")
        self.learner.table[undo.target] = np.array(undo.q_row, dtype=np.float64)
        self.progress[undo.target] = dataclasses.replace(undo.progress)
        self.offered = list(undo.offered)
        self.turn = undo.turn
        self.target = undo.target
        self.previous = undo.previous
        if undo.rejected is not UNSET and self.rejected is not UNSET:
            self.rejected[undo.target] = list(undo.rejected)
        if undo.learned_order is not UNSET:
            self.learned_order = list(undo.learned_order)
        if undo.confused is not UNSET:
            self.confused = undo.confused
        self.undo = None

    def _apply_reopen(self, record: ReopenRecord) -> None:
        """The name learned last is learned no more: offered again, its target open again."""
        learned = self.learned_targets()
        target, label = record.target_index, record.name_index
        if not learned or learned[-1] != target or self.progress[target].learned != label:
            raise StateError(
                f"re-open of target {target} ({record.name}): it is not the one learned last"
            )
        self.undo = UndoEntry(
            trial=record.trial,
            q_row=self.learner.table[self.target].tolist(),
            progress=dataclasses.replace(self.progress[target]),
            offered=list(self.offered),
            turn=self.turn,
            target=self.target,
            previous=self.previous,
            reopened=target,
            learned_order=learned,
            confused=self.confused,
        )
        progress = self.progress[target]
        progress.learned, progress.streak, progress.streak_label = None, 0, None
        self.offered[label] = True
        self.learned_order = learned[:-1]
        self.confused = None

    def _apply_reopen_taken_back(self, record: ReopenRecord) -> None:
        undo = self.undo
        if undo is None or undo.reopened != record.target_index:
            raise StateError(f"undo of the re-open of target {record.target_index}: not the last")
        self.progress[record.target_index] = dataclasses.replace(undo.progress)
        self.offered = list(undo.offered)
        if undo.learned_order is not UNSET:
            self.learned_order = list(undo.learned_order)
        if undo.confused is not UNSET:
            self.confused = undo.confused
        self.undo = None


def _recovery_before(state: GameState, target: int) -> dict[str, Any]:
    """What a recovery-era answer may change besides the rest: for its undo entry."""
    return {
        "learned_order": state.learned_targets(),
        "confused": None if state.confused is UNSET else state.confused,
        "rejected": [] if state.rejected is UNSET else list(state.rejected[target]),
    }


def median_pose(shown: list[dict[str, float]]) -> dict[str, float]:
    """Where Kaspar points for a bag: each joint's median over every pose shown for it.

    One pose shown wrongly among three is outvoted; each joint stays within the range
    every shown pose kept (a median lies between shown values).
    """
    joints = dict.fromkeys(joint for pose in shown for joint in pose)
    return {
        joint: float(statistics.median(pose[joint] for pose in shown if joint in pose))
        for joint in joints
    }


def far_from(pose: dict[str, float], shown: list[dict[str, float]], limit_deg: float) -> list[str]:
    """The joints of `pose` further than `limit_deg` from the median of the poses `shown`."""
    if not shown or limit_deg <= 0:
        return []
    middle = median_pose(shown)
    return [j for j, deg in pose.items() if j in middle and abs(deg - middle[j]) > limit_deg]


def restore(
    snapshot: GameState | None,
    later_records: list[AnyRecord],
    settings: GameSettings,
    params: LearnerParams,
    seed: int | None,
) -> GameState:
    """The state a session had reached: its snapshot plus the records written after it."""
    state = snapshot if snapshot is not None else GameState.new(settings, params, seed)
    for record in later_records:
        if isinstance(record, STATE_CHANGING):
            state.apply(record, settings)
    return state
