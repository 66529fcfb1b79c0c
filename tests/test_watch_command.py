"""`kasparctl watch` without a terminal: the picture once, a replay and a live session as
plain text, and its errors."""

from __future__ import annotations

import io
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from still_body import still_body

from kasparctl.cli import main
from kasparctl.game.session import session_dirs
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo, with_variant
from kasparctl.sim.teacher import Teacher

KASPARCTL = [sys.executable, "-m", "kasparctl"]


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A state directory with one finished pilot session."""
    state_dir = tmp_path_factory.mktemp("state")
    options = DemoOptions(state_dir=state_dir, seed=4, teacher=Teacher(0.1, 0.1), out=io.StringIO())
    with still_body():  # as a test's games (tests/still_body.py)
        assert run_demo(with_variant(demo_config(), "pilot"), options, fast=True).finished
    return state_dir


def test_once_prints_the_picture_as_text(
    finished: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["watch", "--state-dir", str(finished), "--once"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0] == "═" * 80 and "FINISHED" in lines[1]
    assert "entropy" in out and "ANSWERS" in out and "LEARNED 3" in out


def test_a_replay_without_a_terminal_prints_each_picture_to_the_end(
    finished: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (directory,) = session_dirs(finished)
    assert main(["watch", "--replay", str(directory), "--speed", "1000"]) == 0
    frames = capsys.readouterr().out.split("═" * 80 + "\n")[1:]
    assert len(frames) > 10
    assert "IDLE" in frames[0].splitlines()[0] and "FINISHED" in frames[-1].splitlines()[0]
    assert "records  end" in frames[-1]


def test_errors_name_what_is_wrong(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    assert main(["watch", "--state-dir", str(tmp_path), "--replay", "nope"]) == 1
    err = capsys.readouterr().err
    assert "nope: no session to replay" in err and str(tmp_path / "sessions" / "nope") in err
    with pytest.raises(SystemExit) as usage:
        main(["watch", "--state-dir", str(tmp_path), "--replay", "x", "--speed", "0"])
    assert usage.value.code == 2
    assert capsys.readouterr().err == (
        "kasparctl watch: error: argument --speed: expected a number above 0 and up to 1e+06, "
        "found 0\n"
    )
    monkeypatch.setenv("KASPAR_CONFIG", str(tmp_path / "missing.toml"))
    assert main(["watch"]) == 1
    assert "no state directory: give --state-dir DIR" in capsys.readouterr().err


def test_following_without_a_terminal_prints_each_new_picture(tmp_path: Path) -> None:
    """A pipe gets plain text: a picture each time the records change, none in between."""
    watch = subprocess.Popen(
        [*KASPARCTL, "watch", "--state-dir", str(tmp_path)],
        stdout=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert watch.stdout is not None
        assert watch.stdout.readline() == "═" * 80 + "\n"
        assert "No session yet" in watch.stdout.readline() + watch.stdout.readline()
        subprocess.run(
            [
                *KASPARCTL,
                "demo",
                "--fast",
                "--variant",
                "pilot",
                "--seed",
                "3",
                "--state-dir",
                str(tmp_path),
            ],
            check=True,
            capture_output=True,
        )
        for line in watch.stdout:
            if "FINISHED" in line:
                break
        watch.send_signal(signal.SIGTERM)
        assert watch.wait(timeout=10) == 130  # unwound like Ctrl-C
    finally:
        if watch.poll() is None:
            watch.kill()
            watch.wait()
