"""A demo killed with SIGKILL at many points resumes and finishes, losing no trial."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from kasparctl.game.jsonl import read_records
from kasparctl.game.records import (
    PoseRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    TrialRecord,
)
from kasparctl.game.session import RECORDS_FILE

KILLS_WANTED = 22
POLL_S = 0.001  # how often the records are counted while waiting for the next one


def record_count(state_dir: Path) -> int:
    sessions = state_dir / "sessions"
    if not sessions.is_dir():
        return 0
    return sum(
        (d / RECORDS_FILE).read_bytes().count(b"\n")
        for d in sessions.iterdir()
        if (d / RECORDS_FILE).exists()
    )


def start_demo(state_dir: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "kasparctl",
            "demo",
            "--speed",
            "400",
            "--seed",
            "7",
            "--state-dir",
            str(state_dir),
            "--json",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.slow  # 22 demos started and killed, one after another
def test_sigkill_at_many_points_then_resume_finishes_without_losing_a_trial(tmp_path: Path) -> None:
    kills: list[int] = []
    kill_at = 1
    summary = None
    for _attempt in range(60):
        process = start_demo(tmp_path)
        deadline = time.monotonic() + 120
        while process.poll() is None and time.monotonic() < deadline:
            if len(kills) < KILLS_WANTED and record_count(tmp_path) >= kill_at:
                # The stimulus: 0 to 12 ms after the record, so kills land at different
                # moments (mid-speech, mid-motion, between a record and its snapshot).
                time.sleep((kill_at % 5) * 0.003)
                os.kill(process.pid, signal.SIGKILL)
                process.wait()
                kills.append(record_count(tmp_path))
                kill_at = record_count(tmp_path) + 2
                break
            time.sleep(POLL_S)  # the wait for the next record on disk
        else:
            out, err = process.communicate(timeout=120)
            assert process.returncode == 0, err
            summary = json.loads(out.strip().splitlines()[-1])
            break
    assert summary is not None, "the demo never finished"
    assert len(kills) >= 20, kills
    print("killed after records:", kills)
    assert summary["finished"] is True and summary["resumed"] is True and summary["learned"] == 6

    (session_dir,) = (tmp_path / "sessions").iterdir()
    read = read_records(session_dir / RECORDS_FILE)
    records = read.records
    assert read.warnings == []
    assert [r.seq for r in records] == list(range(1, len(records) + 1))
    trials = [r for r in records if isinstance(r, TrialRecord)]
    assert [t.trial for t in trials] == list(range(1, summary["trials"] + 1))
    resumes = [
        r for r in records if isinstance(r, SessionRecord) and r.event is SessionEvent.RESUMED
    ]
    assert len(resumes) >= 20
    steps = [r.to for r in records if isinstance(r, StepRecord)]
    assert steps == ["placing", "teaching", "revealing", "guessing", "farewell", "finished"]
    # Every bag was taught in every round exactly once, whatever was interrupted.
    rounds = [(r.round, r.bag) for r in records if isinstance(r, PoseRecord)]
    assert rounds == [(k, b) for k in range(3) for b in range(6)]
