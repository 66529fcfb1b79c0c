"""Sessions the game never wrote: every research command on them ends with a result or one
named error, never a traceback.

Hypothesis writes plans and record files from well-typed but arbitrary values (lists of
odd lengths, indices out of range, huge and negative numbers, formula-like text) and
damaged lines; each command runs in-process, so any exception fails the test.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from kasparctl.cli import main

TEXT = st.text(
    alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=12
) | st.sampled_from(["=1+1", "@x", "-3", "lion", "", " "])
NUMBER = st.floats(allow_nan=False, allow_infinity=False, width=32) | st.integers(-5, 40)
SMALL = st.integers(-2, 8)


def floats(size: int) -> st.SearchStrategy[list[float]]:
    return st.lists(st.floats(-3, 3, allow_nan=False), min_size=size, max_size=size)


@st.composite
def trial(draw: st.DrawFn, number: int) -> dict[str, Any]:
    width = draw(st.integers(1, 7))
    candidates = draw(st.lists(TEXT, min_size=0, max_size=7))
    return {
        "kind": "trial",
        "seq": number,
        "time": "2026-03-02T09:41:07.118+00:00",
        "clock": 1.0,
        "trial": draw(st.integers(-1, 30)),
        "problem_trial": draw(SMALL),
        "step": "guessing",
        "target": draw(TEXT),
        "target_index": draw(SMALL),
        "child": draw(TEXT),
        "child_index": draw(SMALL),
        "candidates": candidates,
        "probabilities": draw(floats(width)),
        "entropy": draw(st.floats(-1, 4, allow_nan=False)),
        "band": draw(st.none() | st.sampled_from(["sure", "unsure", "odd"])),
        "spoken": draw(st.lists(TEXT, max_size=2)),
        "choice": draw(TEXT),
        "choice_index": draw(st.integers(-1, 7)),
        "feedback": draw(st.sampled_from(["green", "red"])),
        "question_end": 0.0,
        "feedback_at": 1.0,
        "reaction_time": draw(st.floats(-1, 100, allow_nan=False)),
        "reward": draw(st.floats(-2, 2, allow_nan=False)),
        "q_before": draw(floats(width)),
        "q_after": draw(floats(draw(st.sampled_from([width, width, width + 1])))),
        "learner_rng": {},
        "perseverative": draw(st.booleans()),
        "win_shift": draw(st.booleans()),
        "correct": draw(st.none() | st.booleans()),
        "feedback_right": draw(st.none() | st.booleans()),
        "learned": draw(st.booleans()),
    }


@st.composite
def other(draw: st.DrawFn, number: int) -> dict[str, Any]:
    kind = draw(st.sampled_from(["undo", "step", "prompt", "press", "session"]))
    base = {"kind": kind, "seq": number, "time": "", "clock": 0.0}
    if kind == "undo":
        return {**base, "trial": draw(st.integers(-1, 30))}
    if kind == "step":
        return {**base, "to": draw(st.sampled_from(["guessing", "finished", "stopped", "x"]))}
    if kind == "prompt":
        return {**base, "line": draw(TEXT), "waited": 8.0}
    if kind == "press":
        return {**base, "button": "green", "at": 1.0, "extra": draw(st.booleans()), "trial": draw(SMALL)}
    return {**base, "event": "resumed"}


@st.composite
def session(draw: st.DrawFn) -> tuple[dict[str, Any], list[bytes]]:
    plan = {
        "session": draw(TEXT) or "s",
        "created": draw(st.sampled_from(["2026-03-02T09:41:07.118+00:00", "", "yesterday"])),
        "group": draw(TEXT),
        "variant": draw(st.sampled_from(["names", "pilot", ""])),
        "plan": {
            "profile": "paper",
            "speak_uncertainty": draw(st.booleans()),
            "children": draw(st.lists(TEXT, max_size=3)),
            "participants": draw(st.lists(TEXT, max_size=3)),
            "answer_key": draw(st.lists(TEXT, max_size=4)),
        },
    }
    lines = []
    for number in range(1, draw(st.integers(0, 25)) + 1):
        record = draw(st.one_of(trial(number), other(number)))
        lines.append(json.dumps(record).encode())
    lines += draw(st.lists(st.sampled_from([b"\x00\xff", b"[1]", b"{", b'{"kind": "hug"}']), max_size=2))
    return plan, lines


@pytest.mark.slow
# Control characters in labels have no glyph in the font: drawn as boxes, which is fine.
@pytest.mark.filterwarnings("ignore:Glyph")
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sessions=st.lists(session(), min_size=1, max_size=3))
def test_no_session_makes_a_research_command_raise(tmp_path: Path, sessions: list[Any]) -> None:
    state = tmp_path / "state"
    shutil.rmtree(state, ignore_errors=True)
    for index, (plan, lines) in enumerate(sessions):
        directory = state / "sessions" / f"2026030{index}T000000-G"
        directory.mkdir(parents=True)
        (directory / "plan.json").write_text(json.dumps(plan))
        (directory / "records.jsonl").write_bytes(b"".join(line + b"\n" for line in lines))
    out = tmp_path / "out"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    commands = [
        ["sessions", "--state-dir", str(state), "--json"],
        ["export", "--state-dir", str(state), "--csv", str(out / "t.csv"), "--events", str(out / "e.csv")],
        ["report", "--state-dir", str(state), "--out", str(out / "r"), "--bootstrap", "100"],
        ["fit-teacher", "--state-dir", str(state), "--out", str(out / "t.toml")],
    ]
    for argv in commands:
        # A result (0) or one named error (1); an exception fails the test by itself.
        assert main(argv) in (0, 1), argv
