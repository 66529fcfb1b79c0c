"""A game that recovers from a wrongly learned name: the rules, pure.

One false green can make Kaspar learn a wrong name; in the names game that name is
then withdrawn from every later bag, so the bag it really belongs to can never be
learned (its guesses run to the limit and it is given up). Nobody would be told.
These rules notice it and let the researcher undo it:

- **Confused.** After an answer, Kaspar is confused about the target when every
  name still offered has been answered red there (`ALL_REJECTED`: the right one is
  gone, or a child pressed red for it), or when a name learned for another target
  was answered green here (`LEARNED_ELSEWHERE`, where learned names stay offered).
  It says so once per target, and asks the researcher (a ConfusedRecord). Only
  about a target still asked: an answer that made the target learned or given up
  confuses nobody, and a confusion ends once its target is done (the one rule of
  kasparctl.game.fold, which every reader of the records applies).
- **Re-open.** The researcher's "reopen" makes the name learned last learned no
  more: it is offered again, its target is asked again once the current one is
  done (a ReopenRecord; again re-opens the one before). Their undo takes it back.
- **Alert.** With an answer key in the plan, a name withdrawn while it is the right
  toy of a target still open is recorded (an AlertRecord): that target cannot be
  learned right unless a name is re-opened. The learner never sees the key.

Pure: no I/O and no clock. The game writes what these return (record first) and
GameState.apply makes them the state's, live and on a resume alike. Only sessions
planned with recovery (plan.json "recovery") track what was rejected; the ones
planned before play as they did.
"""

from __future__ import annotations

from collections.abc import Sequence

import msgspec
from msgspec import UNSET, UnsetType

from kasparctl.config import GameSettings
from kasparctl.game.records import AlertRecord, ConfusedRecord, ReopenRecord, TrialRecord
from kasparctl.game.state import GameState

# The version of these rules a session is planned with (plan.json "recovery").
RECOVERY_VERSION = 1
ALL_REJECTED = "all_rejected"
LEARNED_ELSEWHERE = "learned_elsewhere"
RIGHT_TOY_WITHDRAWN = "right_toy_withdrawn"


def rejected_after(before: Sequence[int], choice: int, green: bool) -> list[int]:
    """The labels whose last answer on a target is red, after `choice` was answered."""
    rest = [label for label in before if label != choice]
    return sorted([*rest, choice]) if not green else rest


def all_rejected(offered: Sequence[bool], rejected: Sequence[int]) -> bool:
    """Every label still offered has been answered red (and at least one is offered)."""
    names = [label for label, on in enumerate(offered) if on]
    return bool(names) and set(names) <= set(rejected)


def confusion(
    state: GameState, record: TrialRecord, settings: GameSettings
) -> ConfusedRecord | None:
    """Whether Kaspar is confused after `record`, applied to `state` (None: it is not,
    it said so already for this target, the answer made the target done, or the session
    was planned without recovery)."""
    if record.rejected is UNSET:
        return None
    target = record.target_index
    if state.confused == target:
        return None  # said once, until a name is re-opened or the target is done
    if state.progress[target].done:
        return None  # nothing more is asked about it (kasparctl.game.fold.standing)
    reason, name, learned_for = None, None, None
    if record.green:
        elsewhere = [
            i
            for i, progress in enumerate(state.progress)
            if i != target and progress.learned == record.choice_index
        ]
        if elsewhere:
            reason, name = LEARNED_ELSEWHERE, record.choice
            learned_for = settings.targets[elsewhere[-1]]
    if reason is None and all_rejected(state.offered, record.rejected):
        reason = ALL_REJECTED
    if reason is None:
        return None
    reopen = reopen_record(state, settings, ignore_done=True)
    confused = ConfusedRecord(
        trial=record.trial,
        target=record.target,
        target_index=target,
        reason=reason,
        rejected=[settings.toys[label] for label in record.rejected],
        reopen_target=None if reopen is None else reopen.target,
        reopen_name=None if reopen is None else reopen.name,
    )
    if name is not None and learned_for is not None:
        return msgspec.structs.replace(confused, name=name, learned_for=learned_for)
    return confused


def alerts(
    state: GameState, record: TrialRecord, settings: GameSettings, answer_key: Sequence[str]
) -> list[AlertRecord]:
    """The targets still open whose right toy `record` just withdrew (it was learned for
    another target), with `state` after the record; none without an answer key."""
    if not answer_key or record.rejected is UNSET or not record.learned:
        return []
    label = record.choice_index
    if state.offered[label]:
        return []  # learned names are not withdrawn in this game
    toy = settings.toys[label]
    return [
        AlertRecord(
            alert=RIGHT_TOY_WITHDRAWN,
            trial=record.trial,
            target=settings.targets[target],
            target_index=target,
            toy=toy,
            learned_for=record.target,
        )
        for target, progress in enumerate(state.progress)
        if not progress.done and target < len(answer_key) and answer_key[target] == toy
    ]


def reopen_record(
    state: GameState, settings: GameSettings, *, ignore_done: bool = False
) -> ReopenRecord | None:
    """The re-open of the name learned last; None when none is learned, or every target
    is done (the guessing is over: nothing would ask it again)."""
    learned = state.learned_targets()
    if not learned or (state.all_done and not ignore_done):
        return None
    target = learned[-1]
    label = state.progress[target].learned
    assert label is not None  # learned_targets lists learned targets only
    return _reopen(settings, state.trials, target, label)


def taken_back(state: GameState, settings: GameSettings) -> ReopenRecord | None:
    """The undo of the last re-open, when the last thing the researcher can undo is one."""
    undo = state.undo
    if undo is None or undo.reopened is UNSET:
        return None
    target = undo.reopened
    label = undo.progress.learned
    assert label is not None  # a re-opened target was learned
    return _reopen(settings, undo.trial, target, label, taken_back=True)


def _reopen(
    settings: GameSettings,
    trial: int,
    target: int,
    label: int,
    taken_back: bool | UnsetType = UNSET,  # unset, as a re-open is written
) -> ReopenRecord:
    return ReopenRecord(
        trial=trial,
        target=settings.targets[target],
        target_index=target,
        name=settings.toys[label],
        name_index=label,
        taken_back=taken_back,
    )


def to_reopen(learned: Sequence[tuple[int, int]], answers: Sequence[int]) -> int:
    """How many re-opens a researcher who knows the bags gives: down to the last name
    learned wrong (`learned` in order, (target, label); `answers` the right labels);
    0 when every learned name is right."""
    for depth, (target, label) in enumerate(reversed(learned), start=1):
        if answers[target] != label:
            return depth
    return 0
