"""The records read one way: the game's state, STATUS=, the live view and the research agree.

The disagreements issue 23 found, each reproduced on a whole simulated game: Kaspar
confused about a bag it has given up (STATUS= said no, the view kept drawing it), and
the report counting as a win-shift the first guess on a bag after its name was
re-opened (the CSV's win_shift column did not).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import msgspec
import pytest

from kasparctl.cli import main
from kasparctl.config import Config
from kasparctl.game.records import (
    STATE_CHANGING,
    AnyRecord,
    QuestionRecord,
    ReopenRecord,
    TrialRecord,
)
from kasparctl.game.session import Session
from kasparctl.game.state import GameState
from kasparctl.service.status import recovery_words
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo
from kasparctl.sim.teacher import Teacher
from kasparctl.view.fold import SessionFold


def played(state_dir: Path, config: Config, seed: int, teacher: Teacher) -> Path:
    result = run_demo(
        config,
        DemoOptions(state_dir=state_dir, seed=seed, teacher=teacher, out=io.StringIO()),
        fast=True,
    )
    assert result.finished
    return state_dir


def session_records(state_dir: Path) -> tuple[dict[str, Any], list[AnyRecord]]:
    (directory,) = (state_dir / "sessions").iterdir()
    session, _ = Session.open(directory)
    records = session.records()
    session.close()
    return session.plan, records


def with_limit(limit: int) -> Config:
    config = demo_config()
    game = msgspec.structs.replace(config.game, max_trials_per_target=limit)
    return msgspec.structs.replace(config, game=game)


# -- Kaspar confused about a bag given up -------------------------------------------------


@pytest.fixture(scope="module")
def given_up(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`max_trials_per_target = 9`, `demo --p-wrong-red 1.0 --seed 3`: every right guess is
    answered red, so every bag is confused about, then given up."""
    return played(
        tmp_path_factory.mktemp("given-up"), with_limit(9), 3, Teacher(p_wrong_red=1.0)
    )


def test_status_and_the_view_agree_on_the_confusion_after_a_give_up(given_up: Path) -> None:
    """Told the session's limit (as the game is), the view reads the give-up at its answer."""
    config = with_limit(9)
    plan, records = session_records(given_up)
    state = GameState.new(config.game, config.profile(plan["plan"]["profile"]), plan["seed"])
    fold = SessionFold(plan, limit=9)
    seen_give_up = False
    for record in records:
        if isinstance(record, STATE_CHANGING):
            state.apply(record, config.game)
        fold.apply(record)
        seen_give_up = seen_give_up or any(p.given_up for p in state.progress)
        status = recovery_words(state, config.game)
        shown = fold.view.confused
        assert (status is None) == (shown is None), (record.seq, status, shown)
        if isinstance(state.confused, int) and shown is not None:
            assert shown.startswith(f"{config.game.targets[state.confused]}: ")
    assert seen_give_up, "the children's reds gave a bag up"


def test_without_the_limit_the_view_sees_the_give_up_when_the_next_bag_is_asked(
    given_up: Path,
) -> None:
    """Before, the view drew bag 1 CONFUSED all through bag 2."""
    plan, records = session_records(given_up)
    fold = SessionFold(plan)
    gave_up: str | None = None
    for record in records:
        fold.apply(record)
        if isinstance(record, TrialRecord) and record.problem_trial == 9:
            gave_up = record.target  # the answer that gave the bag up
        elif isinstance(record, QuestionRecord) and gave_up is not None:
            assert record.target != gave_up
            assert gave_up in fold.view.given_up
            confused = fold.view.confused
            assert confused is None or not confused.startswith(f"{gave_up}: "), record.seq
            gave_up = None
    assert fold.view.given_up == with_limit(9).game.targets  # every bag, in order


# -- the first guess after a re-open ----------------------------------------------------------

# Children who now and then press green for a wrong guess: with seed 4 the demo learns a
# name wrong, Kaspar is confused, the researcher re-opens it, and the re-opened bag's
# first guess is another toy than the one its green had taught.
FOOLED = Teacher(p_wrong_green=0.15)


@pytest.fixture(scope="module")
def reopened(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return played(tmp_path_factory.mktemp("reopened"), demo_config(), 4, FOOLED)


def test_the_report_counts_the_win_shifts_the_csv_marks(reopened: Path, tmp_path: Path) -> None:
    _, records = session_records(reopened)
    reopen = next(r for r in records if isinstance(r, ReopenRecord))
    trials = [r for r in records if isinstance(r, TrialRecord)]
    learned = next(t for t in trials if t.learned and t.target_index == reopen.target_index)
    again = next(
        t for t in trials if t.target_index == reopen.target_index and t.trial > reopen.trial
    )
    # The case: a green, then (after the re-open and other bags) another toy on this bag.
    assert learned.green and again.choice_index != learned.choice_index
    out = tmp_path / "trials.csv"
    assert main(["export", "--state-dir", str(reopened), "--csv", str(out)]) == 0
    rows = [row for row in csv.DictReader(out.open(newline="")) if row["undone"] == "FALSE"]
    row = next(row for row in rows if int(row["trial"]) == again.trial)
    assert row["win_shift"] == "FALSE"  # it follows no guess: the green was taken back
    assert main(["report", "--state-dir", str(reopened), "--out", str(tmp_path / "report")]) == 0
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    for column, count in (("win_shift", "win_shifts"), ("perseverative", "perseverative_errors")):
        marked = sum(row[column] == "TRUE" for row in rows)
        assert summary["all"][count] == marked, column
