"""The live view in a real terminal (tmux), beside a running demo, through a SIGKILL and a
resume; the demo drawn by the view; a replay stepped with keys.

What the screen shows is checked against what the records hold: the step, the target,
the child, every candidate's probability as recorded, and the entropy.
"""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from tmux_pane import Tmux

from kasparctl.game.jsonl import read_records
from kasparctl.game.records import AnyRecord, QuestionRecord, SessionEvent, SessionRecord
from kasparctl.game.session import RECORDS_FILE, session_dirs

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(shutil.which("tmux") is None, reason="needs tmux (.ci/run installs it)"),
]

KASPARCTL = [sys.executable, "-m", "kasparctl"]
TITLE = re.compile(
    r"^(?P<target>\S.*?) · try (?P<try>\d+) · trial (?P<trial>\d+) · (?P<child>.+?)  "
    r"(?P<state>asking|asked|✓ green|✗ red|answer undone)",
    re.MULTILINE,
)


@pytest.fixture
def tmux():
    pane = Tmux(80, 24)
    yield pane
    pane.close()


def demo(state_dir: Path, *more: str) -> subprocess.Popen[bytes]:
    """A demo of the pilot (straight to the guesses), ten times faster than real time."""
    return subprocess.Popen(
        [
            *KASPARCTL,
            "demo",
            "--variant",
            "pilot",
            "--speed",
            "10",
            "--seed",
            "5",
            "--state-dir",
            str(state_dir),
            *more,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )


def records(state_dir: Path) -> list[AnyRecord]:
    (directory,) = session_dirs(state_dir)
    return read_records(directory / RECORDS_FILE).records


def open_question(screen: str) -> bool:
    match = TITLE.search(screen)
    return match is not None and match["state"] == "asking"


def check_question(screen: str, state_dir: Path, after_seq: int = 0) -> QuestionRecord:
    """The screen shows the question as recorded: step, target, child, probabilities, entropy."""
    match = TITLE.search(screen)
    assert match is not None, screen
    written = records(state_dir)
    questions = [r for r in written if isinstance(r, QuestionRecord)]
    toys = questions[0].candidates  # the first question offers every toy, in the game's order
    asked = [q for q in questions if q.trial == int(match["trial"]) and q.seq > after_seq]
    assert asked, f"trial {match['trial']} after seq {after_seq} is not recorded:\n{screen}"
    question = asked[-1]
    lines = screen.splitlines()
    assert "STEP 4 GUESSING" in lines[0], screen
    assert (match["target"], match["child"], int(match["try"])) == (
        question.target,
        question.child,
        question.problem_trial,
    )
    for toy in question.candidates:
        rows = [line for line in lines if line.startswith(f"  {toy} ")]
        assert len(rows) == 1, f"{toy}:\n{screen}"
        assert f" {question.probabilities[toys.index(toy)]:.3f}" in rows[0], screen
    assert f"entropy {question.entropy:.2f} of" in screen, screen
    return question


def check_on_screen(tmux: Tmux, state_dir: Path, after_seq: int = 0) -> QuestionRecord:
    """Wait for an open question on screen and check it (again, if caught mid-draw)."""
    failure: AssertionError | None = None
    for _attempt in range(5):
        screen = tmux.wait_for(open_question, what="an open question")
        try:
            return check_question(screen, state_dir, after_seq)
        except AssertionError as error:
            failure = error
    raise AssertionError(f"the screen never matched the records: {failure}")


def test_watch_beside_a_demo_through_a_sigkill_a_torn_line_and_the_resume(
    tmp_path: Path, tmux: Tmux
) -> None:
    state_dir = tmp_path / "state"  # not there yet: the view waits for it
    tmux.start([*KASPARCTL, "watch", "--state-dir", str(state_dir)])
    tmux.wait_for(lambda s: "does not exist yet" in s, what="the wait for the state directory")
    first = demo(state_dir)
    try:
        before = check_on_screen(tmux, state_dir)
        first.send_signal(signal.SIGKILL)
        first.wait()
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    # A power cut in the middle of a line: the view says so and carries on.
    (directory,) = session_dirs(state_dir)
    with open(directory / RECORDS_FILE, "ab") as log:
        log.write(b'{"kind":"prompt","seq":')
    tmux.wait_for(lambda s: "1 line(s) not read" in s, what="the torn line")
    assert not tmux.dead()
    second = demo(state_dir)
    try:
        tmux.wait_for(lambda s: "resumed 1x" in s, what="the resume")
        resumed = next(
            r
            for r in records(state_dir)
            if isinstance(r, SessionRecord) and r.event is SessionEvent.RESUMED
        )
        after = check_on_screen(tmux, state_dir, after_seq=resumed.seq)
        assert after.trial >= before.trial
        assert "line(s) not read" not in tmux.screen()  # the resume moved the torn line aside
    finally:
        second.kill()
        second.wait()
    tmux.keys("q")
    tmux.wait_for(lambda _s: tmux.dead(), what="the view to quit on q")


def test_demo_view_draws_the_game_and_prints_the_summary_after_q(
    tmp_path: Path, tmux: Tmux
) -> None:
    state_dir = tmp_path / "state"
    tmux.start(
        [
            *KASPARCTL,
            "demo",
            "--view",
            "--variant",
            "pilot",
            "--speed",
            "20",
            "--seed",
            "8",
            "--state-dir",
            str(state_dir),
        ]
    )
    check_on_screen(tmux, state_dir)
    tmux.wait_for(lambda s: "the demo is finished.  q quits" in s, seconds=60, what="the end")
    screen = tmux.screen()
    assert "FINISHED" in screen.splitlines()[0] and re.search(r"learned 3\b", screen)
    tmux.keys("q")
    screen = tmux.wait_for(lambda s: "guesses," in s and tmux.dead(), what="the summary")
    assert "toys learned" in screen and str(state_dir) in screen.replace("\n", "")


def test_demo_view_without_a_terminal_prints_the_transcript(tmp_path: Path) -> None:
    result = subprocess.run(
        [*KASPARCTL, "demo", "--view", "--fast", "--seed", "2", "--state-dir", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2 and "--view: needs real or --speed time" in result.stderr
    result = subprocess.run(
        [
            *KASPARCTL,
            "demo",
            "--view",
            "--speed",
            "1000",
            "--variant",
            "pilot",
            "--seed",
            "2",
            "--state-dir",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert "stdout is not a terminal" in result.stderr and "Kaspar:" in result.stdout


def test_replay_paused_and_stepped_with_keys(tmp_path: Path, tmux: Tmux) -> None:
    finished = subprocess.run(
        [
            *KASPARCTL,
            "demo",
            "--fast",
            "--variant",
            "pilot",
            "--seed",
            "4",
            "--state-dir",
            str(tmp_path),
        ],
        capture_output=True,
        check=True,
    )
    assert finished.returncode == 0
    (directory,) = session_dirs(tmp_path)
    total = len(records(tmp_path))
    tmux.start([*KASPARCTL, "watch", "--replay", directory.name, "--state-dir", str(tmp_path)])
    tmux.wait_for(lambda s: f"/{total} records  x1" in s, what="the replay's start")
    tmux.keys("Space")
    paused = tmux.wait_for(lambda s: "paused" in s.splitlines()[-1], what="the pause")
    shown = int(re.search(r"replay (\d+)/", paused)[1])  # type: ignore[index]
    tmux.keys("Right", "Right")
    tmux.wait_for(lambda s: f"replay {shown + 2}/{total} records  paused" in s, what="two steps")
    tmux.keys("Left")
    tmux.wait_for(lambda s: f"replay {shown + 1}/{total} records  paused" in s, what="a step back")
    tmux.keys("G")
    screen = tmux.wait_for(lambda s: f"replay {total}/{total} records  end" in s, what="the end")
    assert "FINISHED" in screen.splitlines()[0]
    tmux.keys("q")
    tmux.wait_for(lambda _s: tmux.dead(), what="the replay to quit on q")
