"""Where the research commands write, and how: never over an input, never half a file.

- An output may not lie among a state directory's sessions (their plans and
  records) or inside a session directory being read, may not be an input file (the
  configuration, participants.csv), and may not be another output of the same
  command (`--events` naming the `--csv` file).
- Every file is written to a temporary file in its own directory, fsynced and
  renamed over the final name: an export killed or out of disk space leaves
  the old file or none, never a well-formed half. The temporary file is
  removed on any error; only SIGKILL or a power cut can leave one behind,
  named `.NAME.*.tmp`, never NAME.
- Files are 0600 and new directories 0700, as the robot's own records: what
  is exported is the children's data.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TextIO

from hal.errors import KasparError

PRIVATE_DIR = 0o700


class OutputError(KasparError):
    """An output that would overwrite an input or another output, or cannot be written."""


def _resolved(path: Path) -> Path:
    """The absolute path with symbolic links followed, also for a file not yet made."""
    return Path(os.path.realpath(path))


def _inside(path: Path, directory: Path) -> bool:
    return path == directory or directory in path.parents


def check_outputs(
    outputs: Sequence[tuple[str, str]],
    state_dirs: Sequence[Path],
    session_dirs: Sequence[Path],
    input_files: Sequence[tuple[str, str | Path]] = (),
) -> None:
    """Refuse outputs that would clobber an input or each other; OutputError says which.

    `outputs` are (option, path) pairs; "-" (stdout) is always allowed.
    """
    seen: dict[Path, str] = {}
    protected = [(_resolved(d / "sessions"), f"the sessions of {d}") for d in state_dirs]
    protected += [(_resolved(d), f"the session directory {d}") for d in session_dirs]
    inputs = {_resolved(Path(path)): option for option, path in input_files}
    for option, text in outputs:
        if text == "-":
            continue
        path = _resolved(Path(text))
        for directory, what in protected:
            if _inside(path, directory):
                raise OutputError(
                    f"{option} {text}: inside {what}; the research commands never write "
                    "among the records they read (choose a path outside it)"
                )
        if path in inputs:
            raise OutputError(f"{option} {text}: is the file {inputs[path]} reads")
        if path in seen:
            raise OutputError(f"{option} {text}: is also the {seen[path]} output")
        seen[path] = option


def _fsync_directory(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_file(path: Path) -> Iterator[io.BufferedWriter]:
    """A binary stream whose bytes appear at `path` (0600) only once the block completes."""
    directory = path.parent if str(path.parent) else Path(".")
    try:
        fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as error:
        # The person named the file, not its temporary twin.
        raise OSError(error.errno, error.strerror, str(path)) from error
    try:
        with os.fdopen(fd, "wb") as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise
    _fsync_directory(directory)


@contextlib.contextmanager
def text_output(target: str) -> Iterator[TextIO]:
    """A UTF-8 text stream to a file (atomically, as atomic_file) or to stdout for "-"."""
    if target == "-":
        yield sys.stdout
        sys.stdout.flush()
        return
    with atomic_file(Path(target)) as binary:
        text = io.TextIOWrapper(binary, encoding="utf-8", newline="")
        try:
            yield text
            text.flush()
        finally:
            # The binary stream belongs to atomic_file, which closes it.
            text.detach()


def write_bytes(path: Path, data: bytes) -> None:
    """`data` at `path`, atomically and private."""
    with atomic_file(path) as stream:
        stream.write(data)


def private_directory(path: Path) -> None:
    """Make `path` (0700, with any missing parents) unless it exists; OutputError if it cannot."""
    try:
        path.mkdir(mode=PRIVATE_DIR, parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError(f"{path}: cannot make the directory: {error.strerror or error}") from None
    if not path.is_dir():
        raise OutputError(f"{path}: not a directory")


def closed_pipe() -> int:
    """Exit quietly after the reader of stdout went away (`kasparctl export --csv - | head`).

    stdout is pointed at /dev/null so the interpreter's last flush cannot fail
    again (which would print a traceback and exit 120).
    """
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    finally:
        os.close(devnull)
    return 0
