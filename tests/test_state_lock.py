"""One writer per state directory: the second one is refused with the holder's PID."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from kasparctl.game.lock import StateDirBusy, StateDirLock, lock_holder

HOLDER = """
import sys, time
from pathlib import Path
from kasparctl.game.lock import StateDirLock
lock = StateDirLock(Path(sys.argv[1]))
lock.acquire()
print("held", flush=True)
sys.stdin.read()
"""


def test_a_second_writer_is_refused_naming_the_directory_and_the_pid(tmp_path: Path) -> None:
    state = tmp_path / "state"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(state)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        with pytest.raises(StateDirBusy) as refused:
            StateDirLock(state).acquire()
        assert refused.value.holder == holder.pid
        assert str(state) in str(refused.value) and str(holder.pid) in str(refused.value)
    finally:
        holder.communicate("")
    # Gone with its process: the next writer gets it.
    with StateDirLock(state) as lock:
        assert lock.held


def test_the_lock_dies_with_a_killed_holder(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(tmp_path)], stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, text=True,
    )
    assert holder.stdout is not None and holder.stdout.readline() == "held\n"
    holder.kill()
    holder.wait()
    with StateDirLock(tmp_path) as lock:
        assert lock.held


def test_the_holder_is_read_from_proc_locks_lines(tmp_path: Path) -> None:
    fd = os.open(tmp_path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        status = os.fstat(fd)
        device = f"{os.major(status.st_dev):02x}:{os.minor(status.st_dev):02x}:{status.st_ino}"
        locks = tmp_path / "locks"
        locks.write_text(
            "1: POSIX  ADVISORY  WRITE 10 00:01:5 0 EOF\n"
            f"2: FLOCK  ADVISORY  WRITE 4242 {device} 0 EOF\n"
            f"2: -> FLOCK  ADVISORY  WRITE 77 {device} 0 EOF\n"
        )
        assert lock_holder(fd, locks) == 4242
        locks.write_text("garbage\n3: FLOCK ADVISORY WRITE x y:z 0 EOF\n")
        assert lock_holder(fd, locks) is None
        assert lock_holder(fd, tmp_path / "missing") is None
    finally:
        os.close(fd)
