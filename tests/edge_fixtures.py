"""What the tests of the edges need from the machine: root for real mounts, a small tmpfs.

A real full file system and a real read-only mount need root. Without CI=true a test
that needs them is skipped only where this machine cannot give them (not root, no
mount); with CI=true that is a failure, as the boot test does.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from capabilities import in_ci


def mount_problem() -> str | None:
    """Why this machine cannot mount a tmpfs for a test, or None."""
    if os.geteuid() != 0:
        return "not root"
    return None


@pytest.fixture
def root() -> None:
    """The test mounts file systems: root is needed."""
    if problem := mount_problem():
        if in_ci():
            pytest.fail(f"this test must run in CI, but: {problem}")
        pytest.skip(f"needs real mounts: {problem}")


@contextlib.contextmanager
def small_tmpfs(where: Path, size: str = "256k") -> Iterator[Path]:
    """A tmpfs of `size` mounted at `where` (made if needed), unmounted at the end."""
    where.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0700", "tmpfs", str(where)],
                   check=True)  # fmt: skip
    try:
        yield where
    finally:
        subprocess.run(["umount", "--lazy", str(where)], check=False)


def fill(directory: Path) -> Path:
    """Fill the file system of `directory` to the last byte; the filler file's path."""
    filler = directory / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        for size in (1 << 16, 4096, 1):
            with contextlib.suppress(OSError):
                while True:
                    os.write(fd, b"\0" * size)
    finally:
        os.close(fd)
    return filler
