"""The game's state and every reader of its records, moved on together and held equal.

`Readers.apply(record)` applies a record as the game does (GameState.apply, the
function a resume replays), and hands it to each reader: the one reading of the
records (kasparctl.game.fold.Reading) told the session's limit of guesses, as
the game knows it, and one not told it (as the research and the live view
read); the live view's fold, with and without the limit. After every record it
asserts they agree on what is learned (with which name), given up, re-opened,
whether Kaspar is confused (about which target), what an undo takes back, the
answer the next guess follows, and each trial's flags as the game recorded them.

A reader not told the limit reads a give-up when the game moves on from the
target: until then (the answer that gave the target up, to the next question)
it may only lag by that give-up, and is otherwise the same.

`research_agrees` then reads the session as the research does (the trials CSV's
rows, the report's problems) and holds every row to the same reading.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from msgspec import UNSET
from msgspec.structs import replace

from kasparctl.config import GameSettings
from kasparctl.game.fold import Facts, Guess, Reading
from kasparctl.game.records import STATE_CHANGING, AnyRecord, TrialRecord
from kasparctl.game.state import GameState
from kasparctl.learning.learner import LearnerParams
from kasparctl.learning.study_stats import count_errors
from kasparctl.research.catalogue import load_session
from kasparctl.research.conditions import by_condition
from kasparctl.research.tidy import toy_columns, trial_rows
from kasparctl.service.status import recovery_words
from kasparctl.view.fold import SessionFold
from kasparctl.view.model import SessionView


def game_facts(state: GameState) -> dict[str, Any]:
    """What GameState says of the shared facts."""
    undo = state.undo
    what = None
    if undo is not None:
        what = ("reopen", undo.reopened) if isinstance(undo.reopened, int) else ("answer", undo.trial)
    return {
        "learned": {i: p.learned for i, p in enumerate(state.progress) if p.learned is not None},
        "given_up": {i for i, p in enumerate(state.progress) if p.given_up},
        "confused": state.confused if isinstance(state.confused, int) else None,
        "undo": what,
        "previous": None if state.previous is None else (state.target, *state.previous),
        "away": set() if state.away is UNSET else set(state.away),
    }


def read_facts(facts: Facts) -> dict[str, Any]:
    """What a Reading says of the same facts."""
    undo, previous = facts.undo, facts.previous
    what = None
    if undo is not None:
        what = (undo.what, undo.target if undo.what == "reopen" else undo.trial)
    return {
        "learned": facts.learned,
        "given_up": set(facts.given_up),
        "confused": None if facts.confused is None else facts.confused.target,
        "undo": what,
        "previous": None
        if previous is None
        else (previous.target, previous.label, previous.green),
        "away": set(facts.away),
    }


def told_the_give_up(blind: Facts, targets: set[int]) -> Facts:
    """What a reader not told the limit reads once the game has moved on from `targets`."""
    for target in targets:
        blind = blind.with_target(replace(blind.target(target), given_up=True))
    previous = blind.previous
    if previous is not None and previous.target in targets:
        blind = replace(blind, previous=None)
    return blind.settled()


def view_agrees(view: SessionView, facts: Facts, game: GameSettings) -> None:
    """The live view shows what `facts` say."""
    confused = facts.confused
    if confused is None:
        assert view.confused is None, view.confused
    else:
        assert view.confused is not None and view.confused.startswith(
            f"{game.targets[confused.target]}: "
        ), (view.confused, confused)
    shown = {item.target: item.toy for item in view.learned}
    assert shown == {game.targets[t]: game.toys[label] for t, label in facts.learned.items()}
    assert set(view.given_up) == {game.targets[t] for t in facts.given_up}
    assert view.reopens == facts.reopens


@dataclass
class Readers:
    """The game's state and the readers of its records, as one session goes on."""

    game: GameSettings
    params: LearnerParams
    seed: int | None
    plan: dict[str, Any]
    state: GameState = field(init=False)
    reading: Reading = field(init=False)
    blind: Reading = field(init=False)
    view: SessionFold = field(init=False)
    blind_view: SessionFold = field(init=False)
    # Trial -> how it read when it was answered (with the limit), and the game's
    # confusion just before it.
    guesses: dict[int, Guess] = field(default_factory=dict)
    records: list[AnyRecord] = field(default_factory=list)
    lagged: int = 0  # records after which the reader without the limit lagged a give-up

    def __post_init__(self) -> None:
        """No records yet."""
        self.state = GameState.new(self.game, self.params, self.seed)
        limit = self.game.max_trials_per_target
        self.reading, self.blind = Reading(limit), Reading()
        self.view, self.blind_view = SessionFold(self.plan, limit), SessionFold(self.plan)

    def apply(self, record: AnyRecord) -> None:
        """Apply `record` everywhere, then hold every reader to the game's state."""
        confused_before = self.state.confused
        self.records.append(record)
        if isinstance(record, STATE_CHANGING):
            self.state.apply(record, self.game)
        guess = self.reading.apply(record)
        blind_guess = self.blind.apply(record)
        self.view.apply(record)
        self.blind_view.apply(record)
        where = f"after record {record.seq} ({type(record).__name__})"
        facts, blind = self.reading.facts, self.blind.facts
        assert read_facts(facts) == game_facts(self.state), where
        if self.state.learned_order is not UNSET:
            assert list(facts.learned_order) == self.state.learned_targets(), where
        # STATUS= says what the state says.
        words = recovery_words(self.state, self.game)
        assert (words is None) == (facts.confused is None), where
        view_agrees(self.view.view, facts, self.game)
        if isinstance(record, TrialRecord):
            assert guess is not None and blind_guess == guess, where
            # The flags the game wrote (score_answer, from its state) are the ones read.
            assert (guess.perseverative, guess.win_shift) == (
                record.perseverative,
                record.win_shift,
            ), where
            assert guess.confused == (confused_before == record.target_index), where
            answer = self.view.view.answers[-1]
            assert (answer.perseverative, answer.win_shift) == (
                guess.perseverative,
                guess.win_shift,
            ), where
            self.guesses[record.trial] = guess
        late = facts.given_up - blind.given_up
        assert blind.given_up <= facts.given_up, where
        if late:
            # Only the target still asked, or one re-opened with no guesses left (given up
            # at once, read so at the farewell).
            spent = {t for t in late if blind.target(t).reopened}
            assert late - spent <= {blind.asking}, where
            assert told_the_give_up(blind, late) == facts, where
            self.lagged += 1
        else:
            assert blind == facts, where
        view_agrees(self.blind_view.view, blind, self.game)


def research_agrees(directory: Path, readers: Readers) -> None:
    """The session read back as the research reads it: every trial row and the report's
    problems say what the records read when each trial was answered."""
    session = load_session(directory)
    rows = list(trial_rows(session, toy_columns([session])))
    trials = [r for r in readers.records if isinstance(r, TrialRecord)]
    assert [row["trial"] for row in rows] == [t.trial for t in trials]
    for row in rows:
        guess = readers.guesses[row["trial"]]
        assert (
            row["perseverative"],
            row["win_shift"],
            row["error_cause"],
            row["confused"],
            row["reopened"],
        ) == (guess.perseverative, guess.win_shift, guess.cause, guess.confused, guess.reopened)
        # Who answered: the seat, and the child credited, as the records read.
        assert (row["seat"], row["credited_child_number"]) == (guess.seat, guess.credited + 1)
    counted = [row for row in rows if not row["undone"]]
    (condition,) = by_condition([session], lambda _: readers.params)
    errors = [count_errors(problem.record.trials) for problem in condition.problems]
    assert sum(e.perseverative for e in errors) == sum(row["perseverative"] for row in counted)
    assert sum(e.win_shift for e in errors) == sum(row["win_shift"] for row in counted)
    stats = condition.stats
    assert stats.win_shifts == sum(row["win_shift"] for row in counted)
    assert stats.problems_learned == len(readers.reading.facts.learned)
