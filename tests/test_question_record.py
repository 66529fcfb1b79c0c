"""The open question is on disk before Kaspar asks it: a "question" record, answered by
the trial record of the same number with the very same values."""

from __future__ import annotations

import io
from pathlib import Path

from kasparctl.game.jsonl import read_records
from kasparctl.game.records import QuestionRecord, TrialRecord
from kasparctl.game.session import session_dirs
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo
from kasparctl.sim.teacher import Teacher

SHARED = (
    "trial",
    "problem_trial",
    "target",
    "target_index",
    "child",
    "child_index",
    "candidates",
    "probabilities",
    "entropy",
    "band",
    "choice",
    "choice_index",
)


def test_every_trial_is_asked_first_as_a_question_record(tmp_path: Path) -> None:
    teacher = Teacher(p_wrong_green=0.1, p_wrong_red=0.1, p_no_answer=0.2)
    options = DemoOptions(state_dir=tmp_path, seed=5, teacher=teacher, out=io.StringIO())
    result = run_demo(demo_config(), options, fast=True)
    assert result.finished
    (directory,) = session_dirs(tmp_path)
    read = read_records(directory / "records.jsonl")
    assert read.warnings == []
    questions = {r.trial: r for r in read.records if isinstance(r, QuestionRecord)}
    trials = [r for r in read.records if isinstance(r, TrialRecord)]
    assert len(trials) == result.trials > 0
    assert set(questions) == {t.trial for t in trials}
    for trial in trials:
        question = questions[trial.trial]
        assert question.seq < trial.seq
        # Written before Kaspar spoke: the question ended later.
        assert question.clock <= trial.question_end
        assert {f: getattr(question, f) for f in SHARED} == {f: getattr(trial, f) for f in SHARED}
    # Between a question and its answer only presses, prompts and speech events are recorded.
    between = {
        type(r).__name__
        for t in trials
        for r in read.records
        if questions[t.trial].seq < r.seq < t.seq
    }
    assert between <= {"PressRecord", "PromptRecord", "HalRecord"}
