"""What a session has reached, changed only by applying its own records.

The game writes a record (fsynced) and then applies it to this state; a
resumed session applies the records written after its last snapshot with the
very same function. So the live path and the resume path cannot disagree, and
the snapshot is only a cache of what the records already say.

Records that change the state: "step", "pose", "trial", "undo", and a
"command" that paused or resumed. Every other kind (presses, prompts, faults,
HAL events) is history only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kasparctl.config import GameSettings
from kasparctl.game.problem import TargetProgress
from kasparctl.learning.learner import PLAIN_DATA_ERRORS, LearnerParams, LearnerState

# The game's steps in order; the pilot variant starts at "guessing".
STEPS = ("placing", "teaching", "revealing", "guessing", "farewell")
STATE_CHANGING = frozenset({"step", "pose", "trial", "undo", "command"})


class StateError(ValueError):
    """A record that does not fit the state it is applied to (a corrupt or foreign log)."""


@dataclass(slots=True)
class GameState:
    step: str  # "idle", one of STEPS, "finished" or "stopped"
    learner: LearnerState
    progress: list[TargetProgress]
    # Labels still offered: a learned name is withdrawn from the other bags.
    offered: list[bool]
    trials: int = 0  # trials recorded in this session; the next one is trials + 1
    turn: int = 0  # children answer in rotation: child (turn % group size)
    target: int = 0  # the target Kaspar is guessing
    # The previous answered guess on the current target, for the paper's
    # perseverative-error and win-shift flags.
    previous: tuple[int, bool] | None = None
    poses: dict[str, dict[str, float]] = field(default_factory=dict)  # target -> joint degrees
    teach_round: int = 0
    teach_bag: int = 0
    # What the last child answer changed, so a double red can take it back.
    undo: dict[str, Any] | None = None
    paused: bool = False

    @classmethod
    def new(cls, game: GameSettings, params: LearnerParams, seed: int | None) -> GameState:
        n_targets, n_labels = len(game.targets), len(game.toys)
        return cls(
            step="idle",
            learner=LearnerState.fresh(n_targets, n_labels, params, seed),
            progress=[
                TargetProgress(game.correct_answers_to_learn, game.max_trials_per_target)
                for _ in range(n_targets)
            ],
            offered=[True] * n_labels,
        )

    # -- questions the game asks ------------------------------------------------

    @property
    def candidates(self) -> np.ndarray:
        return np.array(self.offered, dtype=bool)

    @property
    def all_done(self) -> bool:
        return all(progress.done for progress in self.progress)

    def first_open_target(self) -> int | None:
        return next((i for i, progress in enumerate(self.progress) if not progress.done), None)

    # -- the one mutator --------------------------------------------------------

    def apply(self, record: dict[str, Any], game: GameSettings) -> None:
        kind = record.get("kind")
        if kind == "step":
            self._apply_step(str(record["to"]))
        elif kind == "pose":
            self._apply_pose(record, game)
        elif kind == "trial":
            self._apply_trial(record, game)
        elif kind == "undo":
            self._apply_undo(record)
        elif kind == "command" and record.get("applied") and record.get("command") == "pause":
            self.paused = record.get("confirm") == "pause"

    def _apply_step(self, step: str) -> None:
        self.step = step
        if step == "guessing":
            open_target = self.first_open_target()
            self.target = self.target if open_target is None else open_target

    def _apply_pose(self, record: dict[str, Any], game: GameSettings) -> None:
        bag = int(record["bag"])
        self.poses[game.targets[bag]] = {str(k): float(v) for k, v in record["pose"].items()}
        self.teach_bag = bag + 1
        if self.teach_bag >= len(game.targets):
            self.teach_bag = 0
            self.teach_round += 1

    def _apply_trial(self, record: dict[str, Any], game: GameSettings) -> None:
        target, choice = int(record["target_index"]), int(record["choice_index"])
        green = record["feedback"] == "green"
        if target != self.target:
            raise StateError(
                f"trial {record.get('trial')}: for target {target}, state is at {self.target}"
            )
        self.undo = {
            "trial": int(record["trial"]),
            "q_row": self.learner.table[target].tolist(),
            "progress": _progress_plain(self.progress[target]),
            "offered": list(self.offered),
            "turn": self.turn,
            "target": self.target,
            "previous": self.previous,
        }
        self.learner.table[target] = np.array(record["q_after"], dtype=np.float64)
        # The generator as it was after this guess's draw, so a resume draws on from there.
        self.learner.rng.bit_generator.state = record["learner_rng"]
        self.trials = int(record["trial"])
        self.turn += 1
        progress = self.progress[target]
        learned_now = progress.record(choice, green)
        self.previous = (choice, green)
        if progress.done:
            if learned_now and game.exclude_learned:
                self.offered[choice] = False
            self.previous = None
            next_target = self.first_open_target()
            self.target = self.target if next_target is None else next_target

    def _apply_undo(self, record: dict[str, Any]) -> None:
        if self.undo is None or self.undo["trial"] != int(record["trial"]):
            raise StateError(f"undo of trial {record.get('trial')}: it is not the last answer")
        undo = self.undo
        target = int(undo["target"])
        self.learner.table[target] = np.array(undo["q_row"], dtype=np.float64)
        self.progress[target] = TargetProgress(**undo["progress"])
        self.offered = list(undo["offered"])
        self.turn = int(undo["turn"])
        self.target = target
        self.previous = None if undo["previous"] is None else tuple(undo["previous"])  # type: ignore[assignment]
        self.undo = None

    # -- plain data -------------------------------------------------------------

    def to_plain(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "learner": self.learner.to_plain(),
            "progress": [_progress_plain(p) for p in self.progress],
            "offered": list(self.offered),
            "trials": self.trials,
            "turn": self.turn,
            "target": self.target,
            "previous": None if self.previous is None else list(self.previous),
            "poses": {target: dict(pose) for target, pose in self.poses.items()},
            "teach_round": self.teach_round,
            "teach_bag": self.teach_bag,
            # Built by _apply_trial from fresh lists and never changed in place.
            "undo": None if self.undo is None else dict(self.undo),
            "paused": self.paused,
        }

    @classmethod
    def from_plain(cls, data: dict[str, Any]) -> GameState:
        try:
            previous = data["previous"]
            if previous is not None and len(previous) != 2:
                raise ValueError(f"previous: expected [choice, green], found {previous!r}")
            if not isinstance(data["poses"], dict):
                raise TypeError(f"poses: expected a table, found {data['poses']!r}")
            return cls(
                step=str(data["step"]),
                learner=LearnerState.from_plain(data["learner"]),
                progress=[TargetProgress(**p) for p in data["progress"]],
                offered=[bool(x) for x in data["offered"]],
                trials=int(data["trials"]),
                turn=int(data["turn"]),
                target=int(data["target"]),
                previous=None if previous is None else (int(previous[0]), bool(previous[1])),
                poses={str(k): dict(v) for k, v in data["poses"].items()},
                teach_round=int(data["teach_round"]),
                teach_bag=int(data["teach_bag"]),
                undo=data["undo"],
                paused=bool(data["paused"]),
            )
        except PLAIN_DATA_ERRORS as error:
            # (LearnerError is a ValueError: a bad learner table or generator lands here too.)
            raise StateError(f"unusable game state snapshot: {error!r}") from error


def _progress_plain(progress: TargetProgress) -> dict[str, Any]:
    # dataclasses.asdict deep-copies field by field: too slow for a snapshot per record.
    return {
        "correct_answers_to_learn": progress.correct_answers_to_learn,
        "max_trials": progress.max_trials,
        "trials": progress.trials,
        "streak": progress.streak,
        "streak_label": progress.streak_label,
        "learned": progress.learned,
    }


def restore(
    snapshot: dict[str, Any] | None,
    later_records: list[dict[str, Any]],
    game: GameSettings,
    params: LearnerParams,
    seed: int | None,
) -> GameState:
    """The state a session had reached: its snapshot plus the records written after it."""
    state = (
        GameState.from_plain(snapshot)
        if snapshot is not None
        else GameState.new(game, params, seed)
    )
    for record in later_records:
        if record.get("kind") in STATE_CHANGING:
            state.apply(record, game)
    return state
