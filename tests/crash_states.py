"""A power cut at every point of a game: the states a POSIX file system may leave, read back.

1. Record: a whole demo game (names or pilot, on the simulated robot) runs with
   kasparctl.game.storage's `os` replaced by a recorder, so every operation the
   storage room makes (mkdir, create, write, ftruncate, fsync, rename, unlink,
   rmdir) is kept in order, with its bytes. A daemon's event-log record comes
   first, so events.jsonl is in it too. What the game was promised is marked on
   the way: a record is promised once the fsync after its write returned, a
   session once Session.create returned.
2. Model: the operations are replayed on a model file system of inodes. A file
   holds the bytes written and the bytes last fsynced; a directory its entries
   and the entries last fsynced, with the entry changes since (a rename is one).
3. Crash: after any operation, each file not fsynced since its last change may
   hold what was fsynced, everything written, a torn prefix of what was appended
   (cut at several bytes) or zeros in its place; each directory not fsynced since
   its last change holds what was fsynced with any ordered subset of the changes
   since applied (every subset up to SUBSETS_UP_TO changes, else every prefix).
   Every combination is built on disk (sampled, with a fixed seed, beyond
   COMBINATIONS_PER_POINT), identical states once.
4. Read: on each state `kasparctl sessions --json`, `kasparctl export` and
   resume_or_abandon (what the daemon and the demo do at start) run, and the
   state is held to: every promised record still there (before and after the
   resume), every promised session listed, no session listed or exported as
   damaged, no session abandoned, every reader exits 0.

tests/test_power_cut.py runs a sample of crash points; bench/bench_power_cut.py
runs them all and prints the figures.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import itertools
import json
import os
import random
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import kasparctl.game.storage as storage
from kasparctl import cli
from kasparctl.game.jsonl import read_records
from kasparctl.game.records import HalEvent, HalRecord
from kasparctl.game.resume import resume_or_abandon
from kasparctl.game.session import EVENTS_FILE, RECORDS_FILE, EventLog, Session
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo, with_variant

SUBSETS_UP_TO = 4
COMBINATIONS_PER_POINT = 48
TORN_CUTS = 3
LOGS = (RECORDS_FILE, EVENTS_FILE)

Op = tuple[Any, ...]


# -- 1. recording ---------------------------------------------------------------------


class RecordingOs:
    """The `os` module as kasparctl.game.storage sees it, every change kept as an Op."""

    def __init__(self, root: Path, left_out: tuple[str, str] | None = None) -> None:
        """Record the changes under `root` (paths kept relative to it). `left_out` is a
        function of the storage room and a directory (relative to `root`): that
        function's fsyncs of that directory are not recorded, as if it made none (to
        show that a crash then loses what was promised)."""
        self._root = str(root)
        self._left_out = left_out
        self.ops: list[Op] = []
        self._fds: dict[int, tuple[str, int]] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(os, name)

    def _rel(self, path: Any) -> str:
        return os.path.relpath(os.fspath(path), self._root)

    def open(self, path: Any, flags: int, mode: int = 0o777) -> int:
        existed = os.path.lexists(path)
        fd = os.open(path, flags, mode)
        rel = self._rel(path)
        if not flags & os.O_DIRECTORY:
            if not existed and flags & os.O_CREAT:
                self.ops.append(("create", rel))
            elif flags & os.O_TRUNC:
                self.ops.append(("trunc", rel, 0))
        self._fds[fd] = (rel, flags)
        return fd

    def close(self, fd: int) -> None:
        self._fds.pop(fd, None)
        os.close(fd)

    def write(self, fd: int, data: Any) -> int:
        rel, flags = self._fds[fd]
        offset = os.fstat(fd).st_size if flags & os.O_APPEND else os.lseek(fd, 0, os.SEEK_CUR)
        written = os.write(fd, data)
        self.ops.append(("write", rel, offset, bytes(data[:written])))
        return written

    def ftruncate(self, fd: int, size: int) -> None:
        os.ftruncate(fd, size)
        self.ops.append(("trunc", self._fds[fd][0], size))

    def fsync(self, fd: int) -> None:
        os.fsync(fd)
        rel, flags = self._fds[fd]
        if flags & os.O_DIRECTORY and self._left_out is not None:
            # storage.fsync_directory's caller: the step that made the entry.
            caller = sys._getframe(2).f_code.co_name
            if (caller, rel) == self._left_out:
                return
        self.ops.append(("fsync", rel))

    def replace(self, source: Any, target: Any) -> None:
        os.replace(source, target)
        self.ops.append(("rename", self._rel(source), self._rel(target)))

    def rename(self, source: Any, target: Any) -> None:
        os.rename(source, target)
        self.ops.append(("rename", self._rel(source), self._rel(target)))

    def mkdir(self, path: Any, mode: int = 0o777) -> None:
        os.mkdir(path, mode)
        self.ops.append(("mkdir", self._rel(path)))

    def unlink(self, path: Any) -> None:
        os.unlink(path)
        self.ops.append(("unlink", self._rel(path)))

    def rmdir(self, path: Any) -> None:
        os.rmdir(path)
        self.ops.append(("rmdir", self._rel(path)))


@contextlib.contextmanager
def recording(root: Path, left_out: tuple[str, str] | None = None) -> Iterator[RecordingOs]:
    """Every change the storage room makes under `root`, and each session promised
    (`left_out`: RecordingOs's)."""
    recorder = RecordingOs(root, left_out)
    real_create = Session.create.__func__  # type: ignore[attr-defined]

    def create(cls: type[Session], *args: Any, **kwargs: Any) -> Session:
        session = real_create(cls, *args, **kwargs)
        recorder.ops.append(("promise", session.id))
        return session

    storage.os = recorder  # type: ignore[assignment]
    Session.create = classmethod(create)  # type: ignore[method-assign,assignment]
    try:
        yield recorder
    finally:
        storage.os = os
        Session.create = classmethod(real_create)  # type: ignore[method-assign,assignment]


def record_game(variant: str, seed: int = 1) -> list[Op]:
    """The storage operations of one whole demo game of `variant`, from an empty disk."""
    with tempfile.TemporaryDirectory() as temporary:
        root = Path(temporary)
        state_dir = root / "state"
        config = with_variant(demo_config(), variant)
        with recording(root) as recorder:
            # What a daemon writes before a session: the event log exists as on the robot.
            EventLog(state_dir).record(HalRecord(event=HalEvent.KEYFOB_BACK, device="sim"), 0.0)
            options = DemoOptions(state_dir=state_dir, seed=seed, out=io.StringIO())
            with contextlib.redirect_stdout(io.StringIO()):  # the demo's log lines
                result = run_demo(config, options, fast=True)
        assert result.finished, result
        return recorder.ops


def record_small(left_out: tuple[str, str] | None = None) -> list[Op]:
    """The storage operations of the smallest life: a session made, two records and a
    snapshot in it, then an event-log record (`left_out`: RecordingOs's)."""
    from kasparctl.config import GameSettings
    from kasparctl.game.records import StepRecord
    from kasparctl.game.state import GameState
    from kasparctl.learning.learner import LearnerParams

    with tempfile.TemporaryDirectory() as temporary:
        root = Path(temporary)
        state_dir = root / "state"
        with recording(root, left_out) as recorder:
            session = Session.create(state_dir, {"group": "A1"})
            session.record(StepRecord(to="placing"), 1.0)
            session.record(StepRecord(to="teaching"), 2.0)
            session.save_state(GameState.new(GameSettings(), LearnerParams(), seed=1))
            session.close()
            EventLog(state_dir).record(HalRecord(event=HalEvent.KEYFOB_BACK, device="sim"), 3.0)
        return recorder.ops


def strictest_losses(ops: Sequence[Op]) -> list[str]:
    """What the strictest crash state (only what was fsynced, only the directory entries
    fsynced) lacks of what was promised, at every crash point; no reader is run."""
    model = Model()
    losses: list[str] = []
    for index in range(len(ops) + 1):
        tree = model._tree({})
        for session in sorted(model.promised_sessions):
            if f"state/sessions/{session}/plan.json" not in tree:
                losses.append(f"after op {index}: session {session} has no plan.json")
        for owner, seq in sorted(model.promised_records):
            path = (
                f"state/{EVENTS_FILE}"
                if owner == "events"
                else f"state/sessions/{owner}/{RECORDS_FILE}"
            )
            data = tree.get(path) or b""
            if f'"seq":{seq},'.encode() not in data:
                losses.append(f"after op {index}: record {seq} of {owner} lost")
        if index < len(ops):
            model.apply(ops[index])
    return losses


# -- 2. the model ------------------------------------------------------------------------


@dataclass(eq=False)
class File:
    """A file: the bytes written, and those fsynced."""

    data: bytearray = field(default_factory=bytearray)
    synced: bytes = b""


@dataclass(eq=False)
class Folder:
    """A directory: its entries, those fsynced, and the changes since (each a list of
    (name, node or None) made in one step)."""

    entries: dict[str, Node] = field(default_factory=dict)
    synced: dict[str, Node] = field(default_factory=dict)
    pending: list[list[tuple[str, Node | None]]] = field(default_factory=list)


Node = File | Folder


class Model:
    """The operations replayed; what has been promised so far."""

    def __init__(self) -> None:
        """An empty, durable root (the state directory's parent)."""
        self.root = Folder()
        self.promised_records: set[tuple[str, int]] = set()
        self.promised_sessions: set[str] = set()

    def _folder(self, parts: Sequence[str]) -> Folder:
        folder = self.root
        for part in parts:
            node = folder.entries.get(part)
            if node is None:
                # Made outside the storage room (the lock makes the state directory): a
                # new entry like any, durable only once its parent is fsynced.
                node = Folder()
                self._change(folder, [(part, node)])
            assert isinstance(node, Folder), parts
            folder = node
        return folder

    def _at(self, path: str) -> tuple[Folder, str]:
        parts = path.split("/")
        return self._folder(parts[:-1]), parts[-1]

    def _file(self, path: str) -> File:
        folder, name = self._at(path)
        node = folder.entries[name]
        assert isinstance(node, File), path
        return node

    @staticmethod
    def _change(folder: Folder, effects: list[tuple[str, Node | None]]) -> None:
        for name, node in effects:
            if node is None:
                folder.entries.pop(name, None)
            else:
                folder.entries[name] = node
        folder.pending.append(effects)

    def apply(self, op: Op) -> None:
        """One operation, as the kernel would see it."""
        kind = op[0]
        if kind == "promise":
            self.promised_sessions.add(op[1])
        elif kind == "mkdir":
            folder, name = self._at(op[1])
            self._change(folder, [(name, Folder())])
        elif kind == "create":
            folder, name = self._at(op[1])
            self._change(folder, [(name, File())])
        elif kind == "trunc":
            file = self._file(op[1])
            del file.data[op[2] :]
            file.data.extend(b"\0" * (op[2] - len(file.data)))
        elif kind == "write":
            file = self._file(op[1])
            offset, data = op[2], op[3]
            file.data.extend(b"\0" * max(0, offset - len(file.data)))
            file.data[offset : offset + len(data)] = data
        elif kind == "fsync":
            self._fsync(op[1])
        elif kind == "rename":
            source, name = self._at(op[1])
            target, new_name = self._at(op[2])
            node = source.entries[name]
            if source is target:
                self._change(source, [(name, None), (new_name, node)])
            else:
                self._change(target, [(new_name, node)])
                self._change(source, [(name, None)])
        elif kind in ("unlink", "rmdir"):
            folder, name = self._at(op[1])
            self._change(folder, [(name, None)])
        else:
            raise ValueError(f"unknown operation {op!r}")

    def _fsync(self, path: str) -> None:
        parts = path.split("/") if path != "." else []
        node: Node = self._folder(parts) if not parts else self._node(parts)
        if isinstance(node, Folder):
            node.synced, node.pending = dict(node.entries), []
            return
        node.synced = bytes(node.data)
        if parts[-1] in LOGS:
            owner = "events" if parts[-1] == EVENTS_FILE else parts[-2]
            for line in node.synced.split(b"\n")[:-1]:
                with contextlib.suppress(ValueError, TypeError):
                    seq = json.loads(line).get("seq")
                    if isinstance(seq, int):
                        self.promised_records.add((owner, seq))

    def _node(self, parts: Sequence[str]) -> Node:
        folder = self._folder(parts[:-1])
        return folder.entries[parts[-1]]

    # -- 3. the states a crash may leave -----------------------------------------------

    def crash_states(self, rng: random.Random) -> Iterator[dict[str, bytes | None]]:
        """Each state a power cut now may leave, as {path: bytes, or None for a directory}."""
        folders, files = self._dirty()
        choices: list[list[Any]] = [_folder_choices(f) for f in folders] + [
            _file_choices(f, rng) for f in files
        ]
        everything = list(itertools.product(*(range(len(c)) for c in choices)))
        if len(everything) > COMBINATIONS_PER_POINT:
            extremes = [tuple(0 for _ in choices), tuple(len(c) - 1 for c in choices)]
            everything = extremes + rng.sample(everything, COMBINATIONS_PER_POINT - 2)
        seen: set[str] = set()
        for picked in everything:
            chosen: dict[int, Any] = {}
            for node, options, index in zip([*folders, *files], choices, picked, strict=True):
                chosen[id(node)] = options[index]
            tree = self._tree(chosen)
            digest = hashlib.sha256(repr(sorted(tree.items())).encode()).hexdigest()
            if digest not in seen:
                seen.add(digest)
                yield tree

    def _dirty(self) -> tuple[list[Folder], list[File]]:
        folders: list[Folder] = []
        files: list[File] = []
        seen: set[int] = set()

        def walk(folder: Folder) -> None:
            if id(folder) in seen:
                return
            seen.add(id(folder))
            if folder.pending:
                folders.append(folder)
            for node in {**folder.synced, **folder.entries}.values():
                if isinstance(node, Folder):
                    walk(node)
                elif id(node) not in seen:
                    seen.add(id(node))
                    if bytes(node.data) != node.synced:
                        files.append(node)

        walk(self.root)
        return folders, files

    def _tree(self, chosen: dict[int, Any]) -> dict[str, bytes | None]:
        tree: dict[str, bytes | None] = {}

        def walk(folder: Folder, prefix: str) -> None:
            entries = chosen.get(id(folder), folder.synced)
            for name, node in entries.items():
                path = f"{prefix}{name}"
                if isinstance(node, Folder):
                    tree[path] = None
                    walk(node, path + "/")
                else:
                    tree[path] = chosen.get(id(node), node.synced)

        walk(self.root, "")
        return tree


def _folder_choices(folder: Folder) -> list[dict[str, Node]]:
    pending = folder.pending
    if len(pending) <= SUBSETS_UP_TO:
        subsets = [
            [change for change, kept in zip(pending, mask, strict=True) if kept]
            for mask in itertools.product((False, True), repeat=len(pending))
        ]
    else:
        subsets = [pending[:n] for n in range(len(pending) + 1)]
    outcomes = []
    for subset in subsets:
        entries = dict(folder.synced)
        for change in subset:
            for name, node in change:
                if node is None:
                    entries.pop(name, None)
                else:
                    entries[name] = node
        outcomes.append(entries)
    return outcomes


def _file_choices(file: File, rng: random.Random) -> list[bytes]:
    written, synced = bytes(file.data), file.synced
    outcomes = [synced]
    if written.startswith(synced):
        appended = written[len(synced) :]
        cuts: list[int] = []
        if len(appended) > 2:
            cuts = sorted({1, len(appended) - 1, rng.randrange(1, len(appended))})
        outcomes += [synced + appended[:cut] for cut in cuts[:TORN_CUTS]]
        outcomes.append(synced + b"\0" * len(appended))
    else:
        outcomes += [written[:cut] for cut in sorted({0, len(written) // 2})]
    outcomes.append(written)
    return outcomes


# -- 4. reading each state back -----------------------------------------------------------


@dataclass
class Figures:
    """What the exploration found, over every state explored."""

    crash_points: int = 0
    states: int = 0
    promised_records: int = 0
    records_lost: int = 0
    sessions_lost: int = 0
    damaged_reported: int = 0
    abandoned: int = 0
    failures: int = 0
    examples: list[str] = field(default_factory=list)

    def add(self, other: Figures) -> None:
        """Another game's figures added to these."""
        for name in (
            "crash_points",
            "states",
            "promised_records",
            "records_lost",
            "sessions_lost",
            "damaged_reported",
            "abandoned",
            "failures",
        ):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.examples += other.examples

    @property
    def clean(self) -> bool:
        """Nothing promised was lost and no reader went wrong."""
        return not (
            self.records_lost
            or self.sessions_lost
            or self.damaged_reported
            or self.abandoned
            or self.failures
        )


def _build(tree: dict[str, bytes | None], root: Path) -> None:
    for path, data in sorted(tree.items()):
        target = root / path
        if data is None:
            target.mkdir(mode=0o700)
        else:
            target.write_bytes(data)
            target.chmod(0o600)


def _cli(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, out.getvalue(), err.getvalue()


def _present(state_dir: Path, promised: set[tuple[str, int]]) -> set[tuple[str, int]]:
    found: set[tuple[str, int]] = set()
    for owner in {owner for owner, _ in promised}:
        path = (
            state_dir / EVENTS_FILE
            if owner == "events"
            else state_dir / "sessions" / owner / RECORDS_FILE
        )
        found |= {(owner, record.seq) for record in read_records(path).records}
    return found


def check_state(
    tree: dict[str, bytes | None],
    promised_records: set[tuple[str, int]],
    promised_sessions: set[str],
    variant: str,
    figures: Figures,
    where: str,
) -> None:
    """Build `tree` on disk, run the readers on it, and count what went wrong."""
    config = with_variant(demo_config(), variant)
    with tempfile.TemporaryDirectory() as temporary:
        root = Path(temporary)
        _build(tree, root)
        state_dir = root / "state"
        figures.states += 1

        def wrong(what: str, counter: str, by: int = 1) -> None:
            setattr(figures, counter, getattr(figures, counter) + by)
            if len(figures.examples) < 10:
                figures.examples.append(f"{where}: {what}")

        # A crash before the state directory's entry was durable leaves none: nothing
        # was promised then (the records below say if something was), and the
        # readers rightly say there is no state directory.
        there = state_dir.is_dir()
        code, out, err = _cli(["sessions", "--json", "--state-dir", str(state_dir)])
        listed: list[dict[str, Any]] = json.loads(out) if code == 0 and out.startswith("[") else []
        if code != 0 and there:
            wrong(f"sessions exited {code}: {err.strip()}", "failures")
        damaged = [row for row in listed if row.get("status") == "damaged"]
        if damaged:
            wrong(f"sessions lists {damaged}", "damaged_reported", len(damaged))
        names = {row["session_name"] for row in listed if row.get("status") != "damaged"}
        if lost := promised_sessions - names:
            wrong(f"sessions lost {sorted(lost)}", "sessions_lost", len(lost))
        csv = root / "trials.csv"
        code, out, err = _cli(["export", "--state-dir", str(state_dir), "--csv", str(csv)])
        if code != 0 and there:
            wrong(f"export exited {code}: {err.strip()}", "failures")
        elif "damaged" in err:
            wrong(f"export says {err.strip()}", "damaged_reported")
        figures.promised_records += len(promised_records)
        if lost_records := promised_records - _present(state_dir, promised_records):
            wrong(f"records lost {sorted(lost_records)[:5]}", "records_lost", len(lost_records))
        try:
            with contextlib.redirect_stdout(io.StringIO()):
                outcome = resume_or_abandon(state_dir, config.game, config.profile)
        except Exception as error:  # any exception is a reader going wrong: count it
            wrong(f"resume raised {error!r}", "failures")
            return
        if outcome.resumable is not None:
            outcome.resumable.session.close()
        if outcome.abandoned:
            wrong(f"abandoned {outcome.abandoned}", "abandoned", len(outcome.abandoned))
        if lost_records := promised_records - _present(state_dir, promised_records):
            wrong(f"records lost by the resume {sorted(lost_records)[:5]}", "records_lost")


def explore(
    ops: Sequence[Op],
    variant: str,
    points: Sequence[int] | None = None,
    seed: int = 28,
    on_point: Callable[[int], None] | None = None,
) -> Figures:
    """Crash after each operation numbered in `points` (every one: None), read each state."""
    rng = random.Random(seed)
    wanted = set(range(len(ops) + 1)) if points is None else set(points)
    model = Model()
    figures = Figures()
    for index in range(len(ops) + 1):
        if index in wanted:
            figures.crash_points += 1
            for tree in model.crash_states(rng):
                check_state(
                    tree,
                    set(model.promised_records),
                    set(model.promised_sessions),
                    variant,
                    figures,
                    f"{variant} after op {index}",
                )
            if on_point is not None:
                on_point(index)
        if index < len(ops):
            model.apply(ops[index])
    return figures


def sample_points(ops: Sequence[Op], count: int, early: int = 30, seed: int = 28) -> list[int]:
    """Every crash point among the first `early` (the state directory, the session and its
    first records made: where the directory entries are new), and `count` more (a fixed
    seed)."""
    first = list(range(min(early, len(ops) + 1)))
    rest = range(len(first), len(ops) + 1)
    return sorted({*first, *random.Random(seed).sample(rest, min(count, len(rest)))})
