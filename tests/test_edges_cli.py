"""One command-line contract: a usage error exits 2 with argparse's message, a failure exits
1 with one line naming its cause and never a traceback (--debug or KASPAR_DEBUG=1 shows
it), a closed pipe exits 0 quietly, NO_COLOR and TERM=dumb are respected, and an
interactive mode refuses a closed stdin. Each probe runs the real command line in a
process of its own (a hang on the code before this work fails by its timeout).
"""

from __future__ import annotations

import os
import pty
import subprocess
import sys
from pathlib import Path

import pytest
from edge_fixtures import root  # noqa: F401  (a fixture, used by name)

from kasparctl import cli
from kasparctl.commands import install

REPO = Path(__file__).resolve().parents[1]
DEMO_CONFIG = REPO / "kasparctl" / "sim" / "demo.toml"
TIMEOUT_S = 60.0


def kasparctl(
    *arguments: str, stdin: int | None = subprocess.DEVNULL, env: dict[str, str] | None = None,
    close_stdin: bool = False,
) -> subprocess.CompletedProcess[str]:
    """The command line in a process of its own; stdin closed altogether with close_stdin."""
    command = [sys.executable, "-m", "kasparctl", *arguments]
    if close_stdin:
        # `kasparctl ... <&-`: no descriptor 0 at all.
        command = ["sh", "-c", '"$0" "$@" <&-', *command]
        stdin = None
    return subprocess.run(
        command, stdin=stdin, capture_output=True, text=True, timeout=TIMEOUT_S,
        env=(os.environ | (env or {})),
    )  # fmt: skip


USAGE_ERRORS = {
    "speed_inf": (["demo", "--speed", "inf"], "argument --speed: expected a number from 0.001 to 1e+06, found inf"),
    "speed_tiny": (["demo", "--speed", "1e-300"], "argument --speed: expected a number from 0.001 to 1e+06, found 1e-300"),
    "speed_nan": (["demo", "--speed", "nan"], "argument --speed: expected a number from 0.001 to 1e+06, found nan"),
    "seed_negative": (["demo", "--seed", "-5", "--fast"], "argument --seed: expected a whole number from 0 to 9223372036854775807, found -5"),
    "probability": (["demo", "--p-wrong-green", "2"], "argument --p-wrong-green: expected a number from 0 to 1, found 2"),
    "margin_huge": (
        ["servos", "scan", "--port", "/dev/null", "--protocol", "herkulex", "--margin-ms", "1e9"],
        "argument --margin-ms: expected a number above 0 and up to 1000 ms, found 1e9",
    ),
    "pose_name": (["pose", "record", "a b"], "argument name: expected letters, digits, _ and -, found 'a b'"),
    "pose_speed": (["pose", "play", "happy", "--speed", "-1"], "argument --speed: expected a number above 0 and up to 720 deg/s, found -1"),
    "reload_timeout": (["reload", "--pid", "1", "--timeout", "inf"], "argument --timeout: expected a number above 0 and up to 3600 s, found inf"),
    "keys_without_sim": (["run", "--keys", "/tmp/fifo"], "--keys: only with --sim (the real keyfob is configured in [keyfob])"),
    "interactive_fast": (["demo", "--interactive", "--fast"], "--interactive: needs real or --speed time, not --fast"),
    "reload_without_pid": (["reload", "--runtime-dir", "/tmp"], "--pid: expected the service's process id, or $MAINPID set"),
}


@pytest.mark.parametrize("case", USAGE_ERRORS)
def test_a_usage_error_exits_2_with_argparses_message(case: str) -> None:
    arguments, message = USAGE_ERRORS[case]
    result = kasparctl(*arguments, env={"MAINPID": ""})
    assert result.returncode == 2, result.stderr
    command = " ".join(arguments[:2]) if arguments[0] in ("servos", "pose") else arguments[0]
    assert result.stderr.splitlines()[-1] == f"kasparctl {command}: error: {message}"
    assert "Traceback" not in result.stderr


FAILURES = {
    "run_sim_stdin_closed": (
        ["run", "--sim", "--config", str(DEMO_CONFIG)],
        "error: --sim: standard input is closed, and the simulated keyfob reads the keys from "
        "it: give --keys FIFO, or run it from a terminal",
    ),
    "demo_interactive_stdin_closed": (
        ["demo", "--interactive", "--speed", "10"],
        "error: --interactive: standard input is closed, and the children's keys are read from "
        "it: run the demo from a terminal",
    ),
}


@pytest.mark.parametrize("case", FAILURES)
def test_an_interactive_mode_refuses_a_closed_stdin_with_one_line(case: str, tmp_path: Path) -> None:
    arguments, line = FAILURES[case]
    result = kasparctl(*arguments, "--state-dir", str(tmp_path / "state"), close_stdin=True)
    assert result.returncode == 1
    assert result.stderr == line + "\n"


def test_say_into_a_missing_directory_is_one_line(tmp_path: Path) -> None:
    wav = tmp_path / "missing" / "hello.wav"
    result = kasparctl("say", "--engine", "espeak-ng", "--wav", str(wav), "hello")
    assert result.returncode == 1
    assert result.stderr == f"error: --wav {wav}: no such directory: {wav.parent}\n"


@pytest.mark.usefixtures("root")
def test_a_state_directory_without_permission_is_one_line(
    tmp_path: Path, without_override: list[str]
) -> None:
    """As a user who may not enter the service's 0700 state directory (root without the
    capability to override permissions: as `kasparctl` without sudo)."""
    locked = tmp_path / "var-lib-kaspar"
    locked.mkdir(mode=0o700)
    os.chown(locked, 65534, 65534)
    no_override = without_override
    for arguments, line in [
        (["demo", "--fast", "--state-dir", str(locked / "state")],
         f"error: {locked / 'state'}: cannot use the state directory: Permission denied"),
        (["sessions", "--state-dir", str(locked)],
         f"error: {locked / 'sessions'}: permission denied (the state directory is private to "
         "the robot's service user: run as that user, or with sudo)"),
    ]:  # fmt: skip
        result = subprocess.run(
            [*no_override, sys.executable, "-m", "kasparctl", *arguments],
            capture_output=True, text=True, timeout=TIMEOUT_S,
        )  # fmt: skip
        assert result.returncode == 1, result.stderr
        assert result.stderr.strip().splitlines() == [line]


def test_a_failure_is_one_line_and_debug_shows_the_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def broken(arguments: object) -> int:
        raise KeyError("a bug")

    monkeypatch.setattr(install, "run", broken)
    assert cli.main(["install", "--print"]) == 1
    err = capsys.readouterr().err
    assert err == (
        "error: KeyError: 'a bug' (a bug: run it again with --debug, or with KASPAR_DEBUG=1, "
        "for the traceback, and report it)\n"
    )
    assert cli.main(["--debug", "install", "--print"]) == 1
    assert "Traceback (most recent call last)" in capsys.readouterr().err
    monkeypatch.setenv("KASPAR_DEBUG", "1")
    assert cli.main(["install", "--print"]) == 1
    assert "Traceback (most recent call last)" in capsys.readouterr().err


def test_a_missing_file_is_one_line_naming_it(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    missing = tmp_path / "nowhere.txt"

    def reads(arguments: object) -> int:
        missing.read_text()
        return 0

    monkeypatch.setattr(install, "run", reads)
    assert cli.main(["install", "--print"]) == 1
    assert capsys.readouterr().err == f"error: {missing}: no such file or directory\n"


@pytest.mark.parametrize("timing", [["--fast"], ["--speed", "20"]])
def test_a_closed_pipe_exits_0_quietly(timing: list[str], tmp_path: Path) -> None:
    """`kasparctl demo ... | head -1`: the reader goes away after one line; the demo ends
    there (in real time too: it does not play on unheard for minutes)."""
    process = subprocess.Popen(
        [sys.executable, "-m", "kasparctl", "demo", *timing, "--seed", "1",
         "--state-dir", str(tmp_path / "state")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    assert process.stdout is not None and process.stderr is not None
    process.stdout.readline()
    process.stdout.close()
    try:
        _, err = process.communicate(timeout=TIMEOUT_S)
    finally:
        if process.poll() is None:
            process.kill()  # played on unheard (as before this work): fail, leave no orphan
            process.communicate()
    assert process.returncode == 0
    assert err.decode() == ""


def test_no_color_and_a_dumb_terminal_get_no_colour() -> None:
    from kasparctl.log import configure_logging

    leader, follower = pty.openpty()
    with os.fdopen(follower, "w", closefd=True) as terminal:
        for environment, coloured in [({}, True), ({"NO_COLOR": "1"}, False), ({"TERM": "dumb"}, False)]:
            with pytest.MonkeyPatch.context() as patch:
                patch.delenv("NO_COLOR", raising=False)
                patch.setenv("TERM", "xterm")
                for name, value in environment.items():
                    patch.setenv(name, value)
                configure_logging("info", "console", stream=terminal)
                import structlog

                structlog.get_logger("test").warning("hello", colour=str(coloured))
                terminal.flush()
                line = os.read(leader, 4096)
            assert (b"\x1b[" in line) is coloured, (environment, line)
    os.close(leader)
