"""The study replicated with the whole game: many demo sessions in simulated time.

Two implementations of one study must agree: `kasparctl simulate` runs the
learner loop alone, this runs the game on the simulated robot and reads its
session records back. Both are summarised by kasparctl.learning.study_stats.
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import msgspec

from kasparctl.config import Config
from kasparctl.game.jsonl import read_records
from kasparctl.game.records import SessionRecord, TrialRecord, UndoRecord
from kasparctl.game.session import RECORDS_FILE
from kasparctl.learning.session_stats import problems_from_trials
from kasparctl.learning.study_stats import ProblemRecord, StudyStats, summarise
from kasparctl.sim.demo import DemoOptions, run_demo
from kasparctl.sim.teacher import Teacher


def replicate(
    config: Config, games: int, first_seed: int = 0, teacher: Teacher | None = None
) -> StudyStats:
    """Play `games` sessions (seeds first_seed...) and summarise every problem in them.

    The body is still: it changes no answer and no record the summary reads, and its
    control loop would be most of the time of a game in simulated time.
    """
    still = msgspec.structs.replace(config.body, enabled=False)
    config = msgspec.structs.replace(config, body=still)
    problems: list[ProblemRecord] = []
    with tempfile.TemporaryDirectory(prefix="kaspar-replicate-") as scratch:
        for index in range(games):
            state_dir = Path(scratch) / str(index)
            options = DemoOptions(
                state_dir=state_dir,
                seed=first_seed + index,
                teacher=teacher or Teacher(),
                out=io.StringIO(),
            )
            run_demo(config, options, fast=True)
            (session_dir,) = (state_dir / "sessions").iterdir()
            records = read_records(session_dir / RECORDS_FILE).records
            start = records[0]
            assert isinstance(start, SessionRecord) and isinstance(start.plan, dict)
            plan = start.plan["plan"]
            undone = {r.trial for r in records if isinstance(r, UndoRecord)}
            trials = [r for r in records if isinstance(r, TrialRecord) and r.trial not in undone]
            problems.extend(
                problems_from_trials(
                    trials,
                    config.game.toys,
                    plan["answer_key"],
                    config.profile(plan["profile"]),
                    index,
                )
            )
    return summarise(problems)
