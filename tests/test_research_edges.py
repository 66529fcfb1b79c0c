"""The research commands at their edges: outputs that would clobber inputs, interrupted and
full-disk writes, private files, spreadsheet formulas, damaged sessions and records, a
state directory the user may not read, closed pipes, and runs far too large.

Each finding of the issue "The edges" (research commands) is a test here; the ones
that need a big file are marked slow.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import resource
import shutil
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import msgspec
import pytest
from research_fixtures import Study, make_study

from kasparctl.cli import main
from kasparctl.config import SessionPlan
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo

ROOT = Path(__file__).resolve().parent.parent
KASPARCTL = [sys.executable, "-m", "kasparctl"]


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Study:
    return make_study(tmp_path_factory.mktemp("study"))


def copy_of(study: Study, tmp_path: Path) -> Path:
    return shutil.copytree(study.state_dir, tmp_path / "state")


def first_session(state_dir: Path) -> Path:
    return sorted((state_dir / "sessions").iterdir())[0]


def run(argv: list[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*KASPARCTL, *argv], capture_output=True, text=True, cwd=ROOT, timeout=300, **kwargs
    )


def no_traceback(stderr: str) -> None:
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr


# -- outputs never clobber inputs --------------------------------------------------------


def test_export_refuses_to_write_over_a_sessions_records(study: Study, tmp_path: Path, capsys) -> None:
    state = copy_of(study, tmp_path)
    records = first_session(state) / "records.jsonl"
    before = records.read_bytes()
    assert main(["export", "--state-dir", str(state), "--csv", str(records)]) == 1
    err = capsys.readouterr().err
    assert f"--csv {records}: inside the session directory" in err or "inside the sessions of" in err
    assert records.read_bytes() == before
    # Anywhere among the sessions, even a new file, is refused.
    assert main(["export", "--state-dir", str(state), "--csv", str(state / "sessions" / "t.csv")]) == 1
    assert not (state / "sessions" / "t.csv").exists()


def test_a_session_named_by_its_path_is_protected_too(study: Study, tmp_path: Path, capsys) -> None:
    copy = shutil.copytree(first_session(study.state_dir), tmp_path / "copied-session")
    assert main(["export", str(copy), "--csv", str(copy / "plan.json")]) == 1
    assert "inside the session directory" in capsys.readouterr().err
    assert json.loads((copy / "plan.json").read_text())["session"]


def test_events_may_not_be_the_trials_file(study: Study, tmp_path: Path, capsys) -> None:
    out = tmp_path / "same.csv"
    arguments = ["export", "--state-dir", str(study.state_dir), "--csv", str(out), "--events", str(out)]
    assert main(arguments) == 1
    assert "--events" in capsys.readouterr().err and not out.exists()
    # Through a symbolic link it is the same file.
    link = tmp_path / "link.csv"
    link.symlink_to(out)
    out.write_text("mine\n")
    assert main(["export", "--state-dir", str(study.state_dir), "--csv", str(out), "--events", str(link)]) == 1
    assert out.read_text() == "mine\n"


def test_an_output_may_not_be_an_input_file(study: Study, tmp_path: Path, capsys) -> None:
    participants = tmp_path / "participants.csv"
    participants.write_text("code,group\nP01,ASC\n")
    arguments = ["export", "--state-dir", str(study.state_dir), "--participants", str(participants)]
    assert main([*arguments, "--csv", str(participants)]) == 1
    assert "is the file --participants reads" in capsys.readouterr().err
    assert participants.read_text() == "code,group\nP01,ASC\n"


def test_report_refuses_to_write_among_the_sessions(study: Study, tmp_path: Path, capsys) -> None:
    state = copy_of(study, tmp_path)
    session = first_session(state)
    before = sorted(p.name for p in session.iterdir())
    assert main(["report", "--state-dir", str(state), "--out", str(session)]) == 1
    assert "inside" in capsys.readouterr().err
    assert sorted(p.name for p in session.iterdir()) == before


# -- whole or nothing, and private ------------------------------------------------------


def big_state(root: Path, megabytes: float) -> Path:
    """Sessions made by the scale bench's generator (a real game's records, repeated)."""
    spec = importlib.util.spec_from_file_location("bench_scale", ROOT / "bench" / "bench_research_scale.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    state: Path = module.make(root, megabytes, 1)
    return state


@pytest.mark.slow
def test_an_export_killed_midway_leaves_nothing_under_the_final_name(tmp_path: Path) -> None:
    state = big_state(tmp_path / "big", 40)
    out = tmp_path / "out"
    out.mkdir()
    final = out / "trials.csv"
    process = subprocess.Popen(
        [*KASPARCTL, "export", "--state-dir", str(state), "--csv", str(final)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        # Killed once the export is well under way: its temporary file holds rows.
        while time.monotonic() < deadline:
            partial = [p for p in out.iterdir() if p.name.startswith(".trials.csv.")]
            if partial and partial[0].stat().st_size > 1_000_000:
                break
            assert process.poll() is None, "the export ended before it could be killed"
            time.sleep(0.01)
        process.send_signal(signal.SIGKILL)
    finally:
        process.wait()
    assert not final.exists()
    # What is left is the hidden temporary file, never a CSV that looks whole.
    assert all(p.name.startswith(".trials.csv.") and p.name.endswith(".tmp") for p in out.iterdir())


def test_a_full_disk_leaves_no_csv_and_says_so(study: Study, tmp_path: Path) -> None:
    final = tmp_path / "trials.csv"
    final.write_text("the previous export\n")

    def small_disk() -> None:
        # Writing past 16 kB fails as a full disk does (EFBIG instead of ENOSPC).
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (16_000, 16_000))

    result = run(["export", "--state-dir", str(study.state_dir), "--csv", str(final)], preexec_fn=small_disk)
    assert result.returncode == 1
    assert "error: cannot write the CSV:" in result.stderr and "File too large" in result.stderr
    no_traceback(result.stderr)
    assert final.read_text() == "the previous export\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trials.csv"]


def test_outputs_are_private(study: Study, tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        trials, events, report = tmp_path / "t.csv", tmp_path / "e.csv", tmp_path / "report"
        assert main(["export", "--state-dir", str(study.state_dir), "--csv", str(trials), "--events", str(events)]) == 0
        assert main(["report", "--state-dir", str(study.state_dir), "--out", str(report)]) == 0
        assert main(["fit-teacher", "--state-dir", str(study.state_dir), "--out", str(tmp_path / "teacher.toml")]) == 0
    finally:
        os.umask(old)
    for path in (trials, events, tmp_path / "teacher.toml", *report.iterdir()):
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
    assert stat.S_IMODE(report.stat().st_mode) == 0o700


# -- spreadsheet formulas ---------------------------------------------------------------


def test_text_a_spreadsheet_would_evaluate_is_escaped(tmp_path: Path) -> None:
    plan = SessionPlan(group="=HYPERLINK(1)", children=("@Bob", "+Ann", "-Cy"))
    config = msgspec.structs.replace(demo_config(), sessions=(plan,))
    run_demo(config, DemoOptions(state_dir=tmp_path / "state", seed=3, out=io.StringIO()), fast=True)
    trials, events = tmp_path / "t.csv", tmp_path / "e.csv"
    assert main(["export", "--state-dir", str(tmp_path / "state"), "--csv", str(trials), "--events", str(events)]) == 0
    import csv

    rows = list(csv.DictReader(trials.open(newline="")))
    assert {r["group"] for r in rows} == {"'=HYPERLINK(1)"}
    assert {r["child"] for r in rows} == {"'@Bob", "'+Ann", "'-Cy"}
    # Numbers are numbers: a negative Q-value is not text and keeps its sign.
    assert any(r["reward"] == "-1.0" for r in rows)
    assert any(r["q_after_lion"].startswith("-") for r in rows)
    for row in csv.DictReader(events.open(newline="")):
        for value in row.values():
            assert not value.startswith(("=", "+", "@")) and not (value.startswith("-") and not _number(value)), row


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# -- damaged sessions and records --------------------------------------------------------


DAMAGED_PLANS = [
    (b"", "plan.json: empty (expected the session's plan as a JSON object)"),
    (b"[]", "plan.json: expected object, found array"),
    (b'{"group": "G9", "plan": {"children": "Amira"}}', "plan.json: $.plan.children: expected array, found str"),
    (b'{"group": "G9", "seed": "x"}', "plan.json: $.seed: expected int | null, found str"),
    (b'{"group": "G\xff"}', "plan.json: not UTF-8 text"),
    (b'{"group": "G9", "extra": ' + b"[" * 100_000, "plan.json: nested too deeply to be a plan"),
    (b'{"group": ', "plan.json: not JSON (Input data was truncated)"),
]


@pytest.mark.slow
def test_damaged_plans_are_listed_and_every_other_session_goes_on(study: Study, tmp_path: Path) -> None:
    # Every damage at once, each in its own copy of a session beside the whole study: one
    # damage must neither hide another nor stop the sessions that are whole.
    state = copy_of(study, tmp_path)
    original = first_session(state)
    expected = []
    for number, (content, reason) in enumerate(DAMAGED_PLANS):
        damaged = shutil.copytree(original, state / "sessions" / f"2099010{number}T000000-D")
        (damaged / "plan.json").write_bytes(content)
        expected.append(f"{damaged}/{reason}")
    listed = run(["sessions", "--state-dir", str(state), "--json"])
    assert listed.returncode == 0, listed.stderr
    no_traceback(listed.stderr)
    rows = json.loads(listed.stdout)
    assert sorted(r["reason"] for r in rows if r["status"] == "damaged") == sorted(expected)
    assert len(rows) == len(study.planned) + len(DAMAGED_PLANS)
    exported = run(["export", "--state-dir", str(state), "--csv", str(tmp_path / "t.csv")])
    assert exported.returncode == 0, exported.stderr
    for reason in expected:
        assert f"session left out, damaged: {reason}" in exported.stderr
    assert f"from {len(study.planned)} sessions" in exported.stderr
    reported = run(["report", "--state-dir", str(state), "--out", str(tmp_path / "r")])
    assert reported.returncode == 0, reported.stderr
    no_traceback(exported.stderr + reported.stderr)


def test_a_session_without_a_plan_is_listed_as_damaged(study: Study, tmp_path: Path, capsys) -> None:
    state = copy_of(study, tmp_path)
    # Records without their plan: a session that began, its plan.json lost since.
    (state / "sessions" / "20990101T000000-X").mkdir()
    (state / "sessions" / "20990101T000000-X" / "records.jsonl").write_text("")
    # An empty folder is what a crash left of a session being made: never started, not listed.
    (state / "sessions" / "20990101T000000-Y").mkdir()
    assert main(["sessions", "--state-dir", str(state)]) == 0
    listed = capsys.readouterr().out
    assert "damaged: " in listed and "000000-X" in listed and "000000-Y" not in listed


DAMAGED_RECORDS = [
    (b'{"kind": "trial", "seq": 5, "trial": "five"}', "not a valid record (Expected `int`, got `str` - at `$.trial`)"),
    (b'{"kind": "step", "seq": 5, "to": "\xff\xfe"}', "not a JSON record (not UTF-8)"),
    (b"[" * 100_000, "not a JSON record (nested too deeply)"),
    (b'{"kind": "session", "seq": 5, "event": "start", "plan": ' + b"[" * 5000 + b"]" * 5000 + b"}", None),
    (b'{"kind": "press", "seq": 5, "button": "green", "at": 1.0, "ignored": "' + b"x" * (17 << 20) + b'"}', "longer than"),
]


@pytest.mark.slow
def test_damaged_records_are_warnings_never_a_traceback(study: Study, tmp_path: Path) -> None:
    # Each damaged line as line 5 of a different session, all in one state directory.
    state = copy_of(study, tmp_path)
    sessions = sorted((state / "sessions").iterdir())
    assert len(sessions) >= len(DAMAGED_RECORDS)
    warnings = []
    for session, (line, why) in zip(sessions, DAMAGED_RECORDS, strict=False):
        records = session / "records.jsonl"
        lines = records.read_bytes().splitlines(keepends=True)
        lines.insert(4, line + b"\n")
        records.write_bytes(b"".join(lines))
        if why is not None:
            warnings.append(f"{records}: line 5: skipped, {why}")
    for argv in (
        ["sessions", "--state-dir", str(state)],
        ["export", "--state-dir", str(state), "--csv", str(tmp_path / "t.csv"), "--events", str(tmp_path / "e.csv")],
        ["report", "--state-dir", str(state), "--out", str(tmp_path / "r")],
    ):
        result = run(argv)
        assert result.returncode == 0, result.stderr
        no_traceback(result.stderr)
        for warning in warnings:
            assert warning in result.stderr, (argv[0], warning)


def test_a_state_directory_the_user_may_not_read_is_one_line(
    study: Study, tmp_path: Path, without_override: list[str]
) -> None:
    state = copy_of(study, tmp_path)
    os.chmod(state, 0o700)
    os.chmod(state / "sessions", 0o700)
    if os.geteuid() == 0:
        # Root reads anything; without the capabilities that let it, it is any other user.
        for path in [state, *state.rglob("*")]:
            os.chown(path, 65534, 65534)
    prefix = without_override
    for argv in (
        ["sessions", "--state-dir", str(state)],
        ["export", "--state-dir", str(state), "--csv", str(tmp_path / "t.csv")],
        ["report", "--state-dir", str(state), "--out", str(tmp_path / "r"), "--bootstrap", "100"],
    ):
        result = subprocess.run([*prefix, *KASPARCTL, *argv], capture_output=True, text=True, cwd=ROOT, timeout=120)
        assert result.returncode == 1, result.stderr
        no_traceback(result.stderr)
        lines = [line for line in result.stderr.splitlines() if line]
        assert len(lines) == 1 and "permission denied" in lines[0], result.stderr


# -- closed pipes --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["export", "--csv", "-"],
        ["sessions"],
        ["sessions", "--json"],
    ],
    ids=lambda a: " ".join(a),
)
def test_a_closed_pipe_exits_quietly(study: Study, argv: list[str]) -> None:
    command = " ".join([*KASPARCTL, argv[0], "--state-dir", str(study.state_dir), *argv[1:]])
    result = subprocess.run(
        ["bash", "-c", f"{command} | head -c 20 >/dev/null; echo ${{PIPESTATUS[0]}}"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert result.stdout.strip() == "0", result.stderr
    no_traceback(result.stderr)


def test_simulate_into_a_closed_pipe_exits_quietly() -> None:
    command = " ".join([*KASPARCTL, "simulate", "--groups", "3000", "--sweep", "alpha=0.1:1:0.1", "--seed", "1"])
    result = subprocess.run(
        ["bash", "-c", f"{command} | head -c 5 >/dev/null; echo ${{PIPESTATUS[0]}}"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert result.stdout.strip() == "0", result.stderr
    no_traceback(result.stderr)


# -- runs far too large ------------------------------------------------------------------------


def test_a_simulation_of_hours_is_refused_at_once_with_what_to_do() -> None:
    started = time.monotonic()
    result = run(["simulate", "--groups", "100000000"])
    assert result.returncode == 2  # a usage error
    assert time.monotonic() - started < 20
    assert "--groups: expected at most 1,000,000, found 100,000,000" in result.stderr
    assert "--power" in result.stderr
    sweep = run(["simulate", "--groups", "1000000", "--sweep", "alpha=0.1:1:0.1"])
    assert sweep.returncode == 2 and "expected at most 20,000,000" in sweep.stderr


# -- scale: bench/bench_research_scale.py measures 200 MB of records (sessions, export,
# report, sessions under a 700 MB address space) and simulate --groups 60000 against
# their targets; timings are not asserted here.
# ------------------------------------------------------------------------------------
