"""Security of the running service and of what it leaves on disk.

- `kasparctl run --sim` listens on nothing: no TCP listener, no bound UDP or raw
  socket, no listening or bound-receiving unix socket (it only talks to systemd
  through NOTIFY_SOCKET, as a client);
- the state directory, the sessions and every file in them are private (0700/0600);
- records hold no personal data beyond the plan's first names.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from service_fixtures import (
    DEMO_CONFIG,
    PHRASES,
    RunningService,
    running_service,
    spoken,
    status_is,
)

from kasparctl.cli import main

PLAN_NAMES = ("Sam", "Alex", "Kim")

pytestmark = pytest.mark.skipif(
    not Path("/proc/self/net/unix").exists(), reason="needs Linux /proc/net"
)

# -- the sockets of a process, from /proc ----------------------------------------------

TCP_LISTEN = "0A"
UNIX_ACCEPTCON = 0x10000  # __SO_ACCEPTCON: a listening unix socket
UNIX_DGRAM = 2


def _socket_inodes(pid: int) -> set[int]:
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue  # closed meanwhile
        if match := re.fullmatch(r"socket:\[(\d+)\]", target):
            inodes.add(int(match.group(1)))
    return inodes


def _descendants(pid: int) -> list[int]:
    """The process and every process below it (a voice or a helper it may start)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            parents[int(entry.name)] = int(fields[1])
    found, frontier = [pid], [pid]
    while frontier:
        parent = frontier.pop()
        children = [child for child, ppid in parents.items() if ppid == parent]
        found += children
        frontier += children
    return found


def _inet_table(pid: int, name: str) -> list[dict[str, Any]]:
    path = Path(f"/proc/{pid}/net/{name}")
    if not path.exists():
        return []  # e.g. no IPv6 in this kernel
    rows = []
    for line in path.read_text().splitlines()[1:]:
        fields = line.split()
        rows.append(
            {"table": name, "local": fields[1], "remote": fields[2], "state": fields[3],
             "inode": int(fields[9])}
        )  # fmt: skip
    return rows


def _unix_table(pid: int) -> list[dict[str, Any]]:
    rows = []
    for line in Path(f"/proc/{pid}/net/unix").read_text().splitlines()[1:]:
        fields = line.split()
        rows.append(
            {"table": "unix", "flags": int(fields[3], 16), "type": int(fields[4], 16),
             "inode": int(fields[6]), "path": fields[7] if len(fields) > 7 else ""}
        )  # fmt: skip
    return rows


def listening_sockets(pid: int) -> list[dict[str, Any]]:
    """Every socket of `pid` (and its children) that could accept or receive from others."""
    problems = []
    for process in _descendants(pid):
        try:
            inodes = _socket_inodes(process)
        except OSError:
            continue  # exited meanwhile
        for name in ("tcp", "tcp6"):
            for row in _inet_table(process, name):
                if row["inode"] in inodes and row["state"] == TCP_LISTEN:
                    problems.append(row | {"pid": process})
        # A UDP or raw socket shows up once bound (or connected, which binds it).
        for name in ("udp", "udp6", "udplite", "udplite6", "raw", "raw6"):
            for row in _inet_table(process, name):
                if row["inode"] in inodes:
                    problems.append(row | {"pid": process})
        for row in _unix_table(process):
            if row["inode"] not in inodes:
                continue
            listening = row["flags"] & UNIX_ACCEPTCON
            receiving = row["type"] == UNIX_DGRAM and row["path"]
            if listening or receiving:
                problems.append(row | {"pid": process})
    return problems


@pytest.fixture
def service(tmp_path: Path) -> Iterator[RunningService]:
    with running_service(tmp_path) as running:
        yield running


@pytest.mark.slow  # the service in real time, into its first step
def test_the_running_service_listens_on_nothing(service: RunningService) -> None:
    process = service.process
    service.notify.wait_for("READY=1")
    assert listening_sockets(process.pid) == []

    # And with a session under way (the researcher's long green starts it), its
    # first step's voice and motion running: Kaspar greets the children.
    service.press("G")
    service.notify.wait_for_status(status_is("step 1: placing the bags"), since=service.notify.mark())
    service.stderr.wait_for(lambda line: spoken(line, PHRASES["session"]["greeting"]))
    assert process.poll() is None
    assert listening_sockets(process.pid) == []

    assert service.stop(signal.SIGTERM) == 0


def test_the_socket_check_sees_a_listener(tmp_path: Path) -> None:
    # The check itself must not be blind: this process's own listeners are found.
    with (
        socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp,
        socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as unix,
    ):
        tcp.bind(("127.0.0.1", 0))
        tcp.listen()
        udp.bind(("127.0.0.1", 0))
        unix.bind(str(tmp_path / "listen.sock"))
        unix.listen()
        found = {row["table"] for row in listening_sockets(os.getpid())}
    assert {"tcp", "udp", "unix"} <= found, found


# -- the state on disk -----------------------------------------------------------------


def _demo(state_dir: Path, capsys: pytest.CaptureFixture[str], *extra: str) -> dict[str, Any]:
    code = main(["demo", "--fast", "--seed", "1", "--state-dir", str(state_dir), "--json", *extra])
    output = capsys.readouterr().out
    assert code == 0, output
    summary: dict[str, Any] = json.loads(output.strip().splitlines()[-1])
    assert summary["finished"] is True
    return summary


def test_state_directory_and_session_files_are_private(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    state_dir = tmp_path / "state"
    old_umask = os.umask(0o022)  # a usual, permissive umask: the service must not rely on it
    try:
        _demo(state_dir, capsys)
    finally:
        os.umask(old_umask)
    sessions = state_dir / "sessions"
    session_dirs = list(sessions.iterdir())
    assert session_dirs
    for directory in [state_dir, sessions, *session_dirs]:
        mode = stat.S_IMODE(directory.stat().st_mode)
        assert mode == 0o700, (directory, oct(mode))
    files = [path for directory in session_dirs for path in directory.iterdir()]
    assert {path.name for path in files} >= {"plan.json", "records.jsonl", "state.json"}
    for path in files:
        assert path.is_file(), path
        mode = stat.S_IMODE(path.stat().st_mode)
        assert mode == 0o600, (path, oct(mode))


# -- personal data -----------------------------------------------------------------------

# Keys that would carry more about a child than the plan's first names.
PERSONAL_KEY = re.compile(
    r"(^|_)(name|names|first_?name|last_?name|surname|full_?name|birth|birthday|dob|age|"
    r"address|email|e_?mail|phone|gender|sex|diagnosis|school|class|photo|face|voice_?print)($|_)",
    re.IGNORECASE,
)
FIRST_NAME_LIKE = re.compile(r"[A-Z][a-z]+")


def _walk(value: Any, path: str = "") -> Iterator[tuple[str, str | None, Any]]:
    """(path, key, value) for every value inside a record, nested."""
    if isinstance(value, dict):
        for key, inner in value.items():
            yield f"{path}.{key}", str(key), inner
            yield from _walk(inner, f"{path}.{key}")
    elif isinstance(value, list):
        for index, inner in enumerate(value):
            yield f"{path}[{index}]", None, inner
            yield from _walk(inner, f"{path}[{index}]")


def test_records_hold_no_personal_data_beyond_the_plan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = DEMO_CONFIG.read_text(encoding="utf-8")
    names_line = "children = [" + ", ".join(f'"{name}"' for name in PLAN_NAMES) + "]"
    config_text, count = re.subn(
        r"(?m)^(\[\[sessions\]\]\n(?:[^\[\n].*\n)*)", rf"\g<1>{names_line}\n", text
    )
    assert count == 1
    config = tmp_path / "kaspar.toml"
    config.write_text(config_text, encoding="utf-8")
    state_dir = tmp_path / "state"
    _demo(state_dir, capsys, "--config", str(config))

    (session_dir,) = (state_dir / "sessions").iterdir()
    plan = json.loads((session_dir / "plan.json").read_text())
    assert tuple(plan["plan"]["children"]) == PLAN_NAMES
    records = [
        json.loads(line) for line in (session_dir / "records.jsonl").read_text().splitlines()
    ]
    trials = [record for record in records if record["kind"] == "trial"]
    assert trials
    # The names are used: each trial says whose turn it was, by the plan's name.
    assert {trial["child"] for trial in trials} == set(PLAN_NAMES)

    documents = [("plan.json", plan)] + [
        (f"records.jsonl line {number}", record) for number, record in enumerate(records, 1)
    ]
    for where, document in documents:
        for path, key, value in _walk(document):
            if path.endswith(".robot.name"):
                assert value == "Kaspar"  # the robot's own name ([robot] name), nobody's
                continue
            if key is not None and key != "children":
                assert not PERSONAL_KEY.search(key), f"{where}: personal key {path}"
            if key is not None and "child" in key and isinstance(value, str):
                assert value in PLAN_NAMES, f"{where}: {path} = {value!r} is not a planned name"
            # A string value that is a single capitalised word is taken for a name.
            if isinstance(value, str) and FIRST_NAME_LIKE.fullmatch(value):
                assert value in PLAN_NAMES, f"{where}: {path} = {value!r} looks like a name"
    # The plan keeps the names it was given and nothing else about the children
    # (their pseudonymous participant codes, if planned: attributes live elsewhere).
    assert set(plan["plan"]) <= {
        "group",
        "number",
        "script",
        "profile",
        "speak_uncertainty",
        "uncertainty",
        "alive",
        "children",
        "participants",
        "group_size",
        "answer_key",
        # With one keyfob per child: the rule for a press out of turn, no child's data.
        "answer_out_of_turn",
        # The session's own settings (docs/configuration.md): the game's, not a child's.
        "toys",
        "locations",
        "correct_answers_to_learn",
        "max_trials_per_target",
        "prompt_after_s",
        "step_prompt_after_s",
        "reactions",
        "speed_scale",
        "language",
        "voice",
    }
