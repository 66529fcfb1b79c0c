"""Records read back one line at a time, in constant memory, whatever the file holds.

The research commands read session logs they did not write and cannot trust:
copied off a robot, torn by a power cut, damaged on disk, or hand-edited. So
this reader never holds a whole file, never raises on what a line contains
(broken JSON, invalid UTF-8, nesting deep enough to exhaust the stack, a line
of a gigabyte), and says what it left out the way kasparctl.game.session's
reader does: the file and the line.

It reads exactly what kasparctl.game.session.read_records reads (the tests
hold the two together): a line without its newline at the end of the file,
or a last line that is not JSON, is a torn tail, left in place and not read
(repairing is the robot's job when it resumes); any other line that is not a
record is skipped with a warning.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import msgspec

from kasparctl.game.records import AnyRecord, TrialRecord

# A record is a few kilobytes; a line far longer is damage, skipped without being held.
MAX_LINE_BYTES = 16 << 20
CHUNK_BYTES = 1 << 20
# Warnings kept per file: a file of a million damaged lines says so in one more line.
MAX_WARNINGS = 20

_decoder = msgspec.json.Decoder(AnyRecord)
_plain = msgspec.json.Decoder()

Warn = Callable[[str], None]


@dataclass
class Warnings:
    """The warnings of one file: the first MAX_WARNINGS in full, and how many more."""

    path: Path
    kept: list[str] = field(default_factory=list)
    more: int = 0

    def add(self, message: str) -> None:
        """Keep a warning about the file, or count it once MAX_WARNINGS are kept."""
        if len(self.kept) < MAX_WARNINGS:
            self.kept.append(message)
        else:
            self.more += 1

    def lines(self) -> list[str]:
        """The kept warnings, and one line for those only counted."""
        if not self.more:
            return list(self.kept)
        return [*self.kept, f"{self.path}: {self.more} more lines skipped (not listed)"]


def _lines(path: Path, warn: Warn) -> Iterator[tuple[int, bytes, bool]]:
    """(line number, bytes, ended by a newline) for every line; over-long lines are dropped."""
    number = 0
    pending = b""
    skipping = False  # inside a line already longer than MAX_LINE_BYTES
    with path.open("rb") as stream:
        while chunk := stream.read(CHUNK_BYTES):
            parts = chunk.split(b"\n")
            for part in parts[:-1]:
                number += 1
                if skipping or len(pending) + len(part) > MAX_LINE_BYTES:
                    warn(f"{path}: line {number}: skipped, longer than {MAX_LINE_BYTES} bytes")
                else:
                    yield number, pending + part, True
                pending, skipping = b"", False
            last = parts[-1]
            if skipping:
                continue
            if len(pending) + len(last) > MAX_LINE_BYTES:
                pending, skipping = b"", True
            else:
                pending += last
    if skipping:
        warn(f"{path}: line {number + 1}: skipped, longer than {MAX_LINE_BYTES} bytes")
    elif pending:
        yield number + 1, pending, False


def is_utf8(data: bytes) -> bool:
    """Whether `data` is UTF-8 text: msgspec has reported bad bytes as a UnicodeDecodeError
    and, in later releases, as a DecodeError, so a failed decode asks this directly."""
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def _why_not_json(line: bytes) -> str | None:
    """Why a line is not a JSON object, or None if it is one."""
    try:
        value = _plain.decode(line)
    except msgspec.DecodeError as error:
        return str(error) if is_utf8(line) else "not UTF-8"
    except UnicodeDecodeError:
        return "not UTF-8"
    except RecursionError:
        return "nested too deeply"
    return None if isinstance(value, dict) else "not a JSON object"


def _inconsistent(record: AnyRecord) -> str | None:
    """Why a well-typed record cannot be what the game wrote, or None."""
    if not isinstance(record, TrialRecord):
        return None
    width = len(record.probabilities)
    if width == 0 or len(record.q_before) != width or len(record.q_after) != width:
        return (
            f"per-toy lists of {width}, {len(record.q_before)} and {len(record.q_after)} "
            "values, expected one length of at least 1"
        )
    if not 0 <= record.choice_index < width:
        return f"choice_index {record.choice_index}, expected 0 to {width - 1}"
    if record.target_index < 0 or record.child_index < 0:
        return f"target_index {record.target_index}, child_index {record.child_index}: negative"
    numbers = (record.entropy, record.reaction_time, record.reward, *record.q_after)
    if not all(math.isfinite(value) for value in numbers):
        return "a number that is not finite"
    return None


def _decode(line: bytes) -> tuple[AnyRecord | None, str | None, bool]:
    """(record, None, _) for a record; (None, why, is_json) for a line that is none."""
    try:
        record = _decoder.decode(line)
        why = _inconsistent(record)
        return (record, None, True) if why is None else (None, why, True)
    except msgspec.ValidationError as error:
        why = _why_not_json(line)
        return None, (str(error) if why is None else why), why is None
    except msgspec.DecodeError as error:
        return None, (str(error) if is_utf8(line) else "not UTF-8"), False
    except UnicodeDecodeError:
        # Valid JSON around bytes that are no UTF-8 text.
        return None, "not UTF-8", False
    except RecursionError:
        return None, "nested too deeply", False


def iter_records(path: Path, warn: Warn) -> Iterator[AnyRecord]:
    """Every record of a log, in order; each line that is none goes to `warn` (file and line).

    A missing file has no records. OSError (permission, a disk error) propagates:
    the caller names the file.
    """
    if not path.exists():
        return
    # A line that is not JSON is torn only if it is the file's last: decided one line later.
    held: tuple[int, bytes, str] | None = None
    for number, line, ended in _lines(path, warn):
        if held is not None:
            warn(f"{path}: line {held[0]}: skipped, not a JSON record ({held[2]})")
            held = None
        if not ended:
            warn(
                f"{path}: the last line was torn ({len(line)} bytes, a crash during a write); "
                "left in place, not read"
            )
            return
        record, why, is_json = _decode(line)
        if record is not None:
            yield record
        elif is_json:
            warn(f"{path}: line {number}: skipped, not a valid record ({why})")
        else:
            held = (number, line, str(why))
    if held is not None:
        warn(
            f"{path}: the last line was torn ({len(held[1]) + 1} bytes, a crash during a "
            "write); left in place, not read"
        )
