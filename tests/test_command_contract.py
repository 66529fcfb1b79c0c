"""One contract for every `kasparctl` subcommand, run through kasparctl.cli.main.

- A bad argument is a usage error: exit 2 and one line, `kasparctl CMD: error: ...`,
  naming the option. Every subcommand has its rows below (a new one must add its own),
  and every option that takes a value is probed with an empty one.
- Every option's value is parsed by one of the shared types (commands/arguments.py),
  or by a fixed choice, or is declared free text here.
- A failing operation exits 1 with one line and no traceback; with --debug, the
  traceback comes first and the same line last.
- Every exception class of hal/ and kasparctl/ derives from hal.errors.KasparError, and
  the command line tells a project error, a system error and a bug apart by that base.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Iterator
from pathlib import Path

import pytest

from hal.errors import KasparError
from kasparctl import cli
from kasparctl.commands import arguments, install

REPO = Path(__file__).resolve().parents[1]


def leaves(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """Every subcommand that runs ("servos scan", not "servos"), with its parser."""
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not actions:
        yield " ".join(path), parser
        return
    for name, child in actions[0].choices.items():
        yield from leaves(child, (*path, name))


SUBCOMMANDS = dict(leaves(cli.build_parser()))

# Per subcommand: arguments that are wrong, and the option (or argument) the line names.
BAD_ARGUMENTS: dict[str, list[tuple[list[str], str]]] = {
    "check": [(["--config", ""], "--config")],
    "simulate": [
        (["--compare", "alpha=0.1,0.2"], "--compare"),  # only with --power
        (["--power"], "--power"),
        (["--seed", "12345678901234567890"], "--seed"),  # the seed demo refuses too
        (["--profile", "quick"], "--profile"),
        (["--alpha", "2"], "--alpha"),
        (["--teacher", "t.toml", "--p-wrong-green", "0.1"], "--teacher"),
        (["--recover", "--sweep", "alpha=0.5"], "--recover"),
        (["--sweep", "gamma=0:1:0.1"], "--sweep"),
        (["--power", "--compare", "teacher=a"], "--compare"),
        (["--power", "--compare", "profile=paper,quick"], "--compare"),
        (["--paired"], "--paired"),
        (["--order-effect", "1"], "--order-effect"),
    ],
    "demo": [
        (["--seed", "12345678901234567890"], "--seed"),
        (["--interactive", "--fast"], "--interactive"),
        (["--view", "--fast"], "--view"),
        (["--speed", "2", "--fast"], "--fast"),
        (["--teacher", "t.toml", "--p-wrong-red", "0.1"], "--teacher"),
        (["--p-researcher-pause", "1.5"], "--p-researcher-pause"),
        (["--p-researcher-undo", "-1"], "--p-researcher-undo"),
    ],
    "run": [(["--keys", "/tmp/fifo"], "--keys")],
    "reload": [(["--runtime-dir", "/tmp"], "--pid"), (["--pid", "0"], "--pid")],
    "install": [([], "--print")],
    "servos scan": [
        (["--port", "/dev/null"], "--protocol"),
        (["--port", "/dev/null", "--protocol", "herkulex", "--ids", "300"], "--ids"),
        (["--port", "/dev/null", "--protocol", "herkulex", "--baud", "12"], "--baud"),
    ],
    "servos read": [([], "--config")],
    "port-name": [([], "device"), (["ttyACM0", "--sysfs", ""], "--sysfs")],
    "servos set-voltage": [([], "--config")],
    "servos set-id": [
        (["--port", "/dev/null"], "--new-id"),
        (["--port", "/dev/null", "--new-id", "254"], "--new-id"),
        (["--port", "/dev/null", "--new-id", "3", "--id", "x"], "--id"),
    ],
    "servos calibrate": [
        ([], "--config"),
        (["--config", "k.toml", "--joints", "a", "--group", "b"], "--group"),
    ],
    "pose record": [(["a b"], "name"), (["happy", "--sim-hand", "smile"], "--sim-hand")],
    "pose play": [([], "name"), (["happy", "--duration", "-1"], "--duration")],
    "pose list": [(["--config", ""], "--config")],
    "behaviour check": [(["--config", ""], "--config")],
    "behaviour play": [(["wave", "--strength", "2"], "--strength"), (["a b"], "name")],
    "behaviour record": [(["wave", "--joints", ","], "--joints")],
    "say": [([], "TEXT"), (["--language", "english!", "hi"], "--language")],
    "sessions": [(["--state-dir", ""], "--state-dir")],
    "export": [([], "--csv")],
    "report": [(["--out", "r", "--bootstrap", "5"], "--bootstrap"), (["--out", "r", "--seed", "-1"], "--seed")],
    "watch": [(["--speed", "0"], "--speed")],
    "replicate": [
        (["--readings"], "--readings"),
        (["--paper", "some-session"], "--paper"),
        (["--paper", "--readings", "--profile", "slow"], "--readings"),
        (["--studies", "5"], "--studies"),
        (["--seed", "-1"], "--seed"),
    ],
    "fit-teacher": [([], "--out")],
    "import": [
        (["content", "--out", "o"], "--robot"),
        (["content", "--robot", "kaspar-2", "--out", "o"], "--robot"),
        (["content", "--robot", "kaspar-3"], "--out"),
    ],
    "keyfob list": [(["--sys", ""], "--sys")],
    "keyfob learn": [(["researcher", "1", "--timeout", "0"], "--timeout"), (["nobody", "1"], "role")],
    "plan": [
        (["--conditions", "a,b", "--robots", "A", "--out", "o"], "--groups"),
        (["--groups", "4", "--conditions", "fast/loud,slow", "--robots", "A", "--out", "o"],
         "--conditions"),
        (["--groups", "4", "--conditions", "fast,slow", "--robots", "A,B,C",
          "--robot-plan", "condition", "--out", "o"], "--robot-plan"),
    ],
}

# Options whose value is any text: names the configuration defines (a profile, a group,
# a condition, a phrase key) or what Kaspar says.
FREE_TEXT = {
    ("simulate", "--profile"),
    ("replicate", "--profile"),
    ("replicate", "--condition"),
    ("fit-teacher", "--condition"),
    ("servos calibrate", "--group"),
    ("pose record", "--group"),
    ("behaviour record", "--group"),
    ("say", "text"),
    ("say", "--key"),
    ("keyfob learn", "device"),
}


# What a subcommand cannot be parsed without (so that what follows it is the only fault).
REQUIRED = {
    "install": ["--print"],
    "servos scan": ["--port", "/dev/null", "--protocol", "maestro"],
    "servos read": ["--config", "k.toml"],
    "servos set-id": ["--port", "/dev/null", "--new-id", "3"],
    "port-name": ["ttyACM0"],
    "servos set-voltage": ["--config", "k.toml"],
    "servos calibrate": ["--config", "k.toml"],
    "pose record": ["happy"],
    "pose play": ["happy"],
    "behaviour play": ["wave"],
    "behaviour record": ["wave"],
    "say": ["hello"],
    "export": ["--csv", "-"],
    "report": ["--out", "r"],
    "fit-teacher": ["--out", "-"],
    "import": ["content", "--robot", "kaspar-3", "--out", "o"],
    "keyfob learn": ["researcher", "1"],
    "plan": ["--conditions", "a,b", "--robots", "A", "--out", "o"],
}


def usage(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """The exit code of the command line and what it said on stderr (stdout must be empty)."""
    try:
        code = cli.main(argv)
    except SystemExit as stop:  # argparse's own, from inside main
        code = int(stop.code or 0)
    captured = capsys.readouterr()
    assert captured.out == "", captured.out
    return code, captured.err


@pytest.fixture(autouse=True)
def _no_debug_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(cli.DEBUG_ENV, raising=False)
    monkeypatch.delenv("MAINPID", raising=False)
    monkeypatch.delenv("RUNTIME_DIRECTORY", raising=False)
    monkeypatch.delenv("KASPAR_CONFIG", raising=False)


def test_every_subcommand_has_its_bad_arguments_and_its_failure() -> None:
    assert set(BAD_ARGUMENTS) == set(SUBCOMMANDS)
    assert set(FAILURES) | set(CANNOT_FAIL) == set(SUBCOMMANDS)


@pytest.mark.parametrize(
    ("command", "tail", "option"),
    [(command, tail, option) for command, rows in BAD_ARGUMENTS.items() for tail, option in rows],
)
def test_a_bad_argument_exits_2_with_one_line_naming_it(
    command: str, tail: list[str], option: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, err = usage([*command.split(), *tail], capsys)
    assert code == 2, err
    (line,) = err.splitlines()
    assert line.startswith(f"kasparctl {command}: error: ") and option in line, line


def _valued(parser: argparse.ArgumentParser) -> Iterator[argparse.Action]:
    """The options and positionals of a parser that take a value."""
    for action in parser._actions:
        if action.nargs == 0 or isinstance(action, argparse._SubParsersAction):
            continue
        yield action


def _name(action: argparse.Action) -> str:
    return action.option_strings[0] if action.option_strings else action.dest


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_value_is_parsed_by_a_shared_type_or_a_choice(command: str) -> None:
    for action in _valued(SUBCOMMANDS[command]):
        where = (command, _name(action))
        if action.type is None:
            assert action.choices is not None or where in FREE_TEXT, where
        else:
            assert action.type.__module__ == arguments.__name__, (where, action.type)


def test_every_seed_follows_the_one_seed_rule(capsys: pytest.CaptureFixture[str]) -> None:
    seeds = {
        command: action.type
        for command, parser in SUBCOMMANDS.items()
        for action in _valued(parser)
        if "--seed" in action.option_strings
    }
    assert set(seeds) == {"simulate", "demo", "replicate", "report", "plan"}
    assert all(kind is arguments.seed for kind in seeds.values())
    assert arguments.seed(str(arguments.SEED_LIMIT)) == 2**63 - 1
    for refused in ("-1", str(2**63), "1.5"):
        with pytest.raises(argparse.ArgumentTypeError):
            arguments.seed(refused)


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_an_empty_value_or_an_unknown_option_is_a_usage_error(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    for action in _valued(SUBCOMMANDS[command]):
        if action.type is None and action.choices is None:
            continue  # free text: an empty one is the room's to refuse
        value = [action.option_strings[0], ""] if action.option_strings else [""]
        code, err = usage([*command.split(), *value], capsys)
        assert code == 2, (command, value, err)
        (line,) = err.splitlines()
        assert line.startswith(f"kasparctl {command}: error: argument ") and (
            _name(action) in line or str(action.metavar) in line
        ), line
    code, err = usage([*command.split(), *REQUIRED.get(command, []), "--no-such-option"], capsys)
    assert code == 2
    (line,) = err.splitlines()
    assert line == "kasparctl: error: unrecognized arguments: --no-such-option", line


def _failures(tmp: Path) -> dict[str, tuple[list[str], str]]:
    """Per subcommand: an operation that fails without any hardware, and what its line names."""
    missing, nowhere = str(tmp / "missing.toml"), str(tmp / "nowhere")
    config = ["--config", missing]
    return {
        "check": (config, missing),
        "simulate": (config, missing),
        "demo": ([*config, "--fast", "--state-dir", str(tmp / "state")], missing),
        "run": ([*config, "--sim", "--keys", str(tmp / "keys")], missing),
        "reload": (["--pid", "4194303", "--runtime-dir", str(tmp)], "cannot ask process 4194303"),
        "servos scan": (["--port", nowhere, "--protocol", "maestro"], nowhere),
        "servos read": (config, missing),
        "servos set-id": (["--port", nowhere, "--new-id", "3"], nowhere),
        "port-name": (["ttyACM0", "--sysfs", nowhere], "ttyACM0 is not a Maestro"),
        "servos set-voltage": (config, missing),
        "servos calibrate": (config, missing),
        "pose record": (["happy", *config], missing),
        "pose play": (["happy", *config], missing),
        "pose list": (config, missing),
        "behaviour check": (config, missing),
        "behaviour play": (["wave", *config], missing),
        "behaviour record": (["wave", *config], missing),
        "say": ([*config, "hello"], missing),
        "sessions": (["--state-dir", nowhere], nowhere),
        "export": (["--state-dir", nowhere, "--csv", "-"], nowhere),
        "report": (["--state-dir", nowhere, "--out", str(tmp / "report")], nowhere),
        "watch": (config, missing),
        "replicate": (["--state-dir", nowhere, "--studies", "100"], nowhere),
        "fit-teacher": (["--state-dir", nowhere, "--out", "-"], nowhere),
        "import": ([nowhere, "--robot", "kaspar-3", "--out", str(tmp / "out"), *config], missing),
        "keyfob learn": (["researcher", "event999", *config], "event999"),
        "plan": (["--groups", "4", "--conditions", "fast,slow", "--robots", "A", *config,
                  "--out", str(tmp / "plan")], missing),
    }


FAILURES = set(_failures(Path("/")))
CANNOT_FAIL = {
    "install": "it prints a text and reads nothing",
    "keyfob list": "it lists what sysfs has, or says there is nothing",
}
# Failures a subcommand reports itself, as lines for the journal at error priority
# (systemd runs `kasparctl reload` as ExecReload): no exception reaches the command line.
REPORTED_BY_THE_COMMAND = {"reload"}


@pytest.mark.parametrize("command", sorted(FAILURES))
def test_a_failure_exits_1_with_one_line_and_debug_shows_the_traceback(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tail, named = _failures(tmp_path)[command]
    code, err = usage([*command.split(), *tail], capsys)
    assert code == 1, err
    (line,) = err.splitlines()
    assert "error: " in line and named in line, line
    code, debugged = usage(["--debug", *command.split(), *tail], capsys)
    assert code == 1
    assert debugged.splitlines()[-1] == line
    if command not in REPORTED_BY_THE_COMMAND:
        assert debugged.startswith("Traceback (most recent call last)"), debugged


def test_a_bug_is_named_as_one_and_says_how_to_see_its_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def broken(arguments: object) -> int:
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(install, "run", broken)
    code, err = usage(["install", "--print"], capsys)
    assert code == 1
    assert err == f"error: ZeroDivisionError: division by zero ({arguments.BUG_HINT})\n"


@pytest.mark.parametrize(
    ("error", "line"),
    [
        (KasparError("thing.toml: key: expected a number,\n  found 'x'"),
         "thing.toml: key: expected a number, found 'x'"),
        (FileNotFoundError(2, "No such file or directory", "/a/b"),
         "/a/b: no such file or directory"),
        (AssertionError("should not be"), f"AssertionError: should not be ({arguments.BUG_HINT})"),
        (NotImplementedError("later"), f"NotImplementedError: later ({arguments.BUG_HINT})"),
    ],
)  # fmt: skip
def test_describe_tells_the_projects_errors_the_systems_and_bugs_apart_by_their_base(
    error: BaseException, line: str
) -> None:
    assert arguments.describe(error) == line


def _project_modules() -> Iterator[str]:
    for package in ("hal", "kasparctl"):
        for path in sorted((REPO / package).rglob("*.py")):
            parts = list(path.relative_to(REPO).with_suffix("").parts)
            if parts[-1] == "__main__":
                continue  # running it is all it does
            if parts[-1] == "__init__":
                parts.pop()
            yield ".".join(parts)


def test_every_exception_class_of_the_project_derives_from_the_one_base() -> None:
    outside = []
    found = 0
    for name in _project_modules():
        module = importlib.import_module(name)
        for value in vars(module).values():
            if (
                isinstance(value, type)
                and issubclass(value, BaseException)
                and value.__module__ == name
            ):
                found += 1
                if not issubclass(value, KasparError):
                    outside.append(f"{name}.{value.__name__}")
    assert found > 40, "the project's exception classes were not found"
    # The learner imports nothing of the project (docs/architecture.md); where a person's
    # value reaches it, the room that passed it turns a LearnerError into its own error.
    assert outside == ["kasparctl.learning.learner.LearnerError"]


@pytest.mark.parametrize("line", [["sessions", "--help"], ["--debug", "sessions", "--help"]])
def test_a_subcommand_named_on_the_line_imports_no_other_subcommand(line: list[str]) -> None:
    """A command pays only for its own room: `sessions` starts without the game's demo."""
    import subprocess
    import sys

    probe = (
        "import sys; from kasparctl import cli\n"
        f"try: cli.main({line!r})\n"
        "except SystemExit: pass\n"
        "print(sorted(m for m in sys.modules if m.startswith('kasparctl.commands.')))"
    )
    shown = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=REPO
    ).stdout.splitlines()[-1]
    assert "kasparctl.commands.sessions" in shown
    others = {f"kasparctl.commands.{m}" for m in cli.COMMAND_MODULES} - {
        "kasparctl.commands.sessions"
    }
    assert not [m for m in others if f"'{m}'" in shown], shown


def test_a_line_naming_no_known_subcommand_is_told_every_one(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit) as exited:
        cli.main(["frob"])
    assert exited.value.code == 2
    said = capsys.readouterr().err
    assert all(cli._subcommand(m) in said for m in cli.COMMAND_MODULES), said


@pytest.mark.parametrize("module", cli.COMMAND_MODULES)
def test_each_module_registers_the_subcommand_the_line_is_matched_by(module: str) -> None:
    """A subcommand whose module the line cannot find would still run, but pay for all."""
    parser = cli.build_parser(cli._subcommand(module))
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    assert list(actions[0].choices) == [cli._subcommand(module)]
