"""The record format: records.jsonl (and events.jsonl), one record a line, and its torn tail.

Each line is one record of kasparctl.game.records as a JSON object, "kind"
naming its struct; this is the one place records become bytes and back, with
msgspec. A torn last line (a power cut in the middle of a write) is moved aside
to records.jsonl.torn and cut from the log, with a warning: kept, never parsed
as a record and never a crash. A line that is JSON but not a record is
reported with its file and line and left out; it never stops a reader.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.game.records import AnyRecord, Record
from kasparctl.game.storage import append_durably, fsync_directory, truncate

TORN_SUFFIX = ".torn"

_encoder = msgspec.json.Encoder()
# What decoding a file's bytes as JSON raises: msgspec's errors, and a byte that is not
# UTF-8 inside a string or a key (msgspec raises Python's own error for that).
UNDECODABLE = (msgspec.DecodeError, UnicodeDecodeError)


@dataclass(frozen=True, slots=True)
class JsonLines:
    """The JSON objects of a log, one per whole line, as plain data."""

    records: list[dict[str, Any]]
    # Human-readable reasons for anything not taken as a record.
    warnings: list[str] = field(default_factory=list)
    # The line number (from 1) of each record, in the same order.
    lines: list[int] = field(default_factory=list)
    # The warnings of lines left out in the middle (damage no crash makes), torn tail apart.
    damaged: list[str] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class RecordsRead:
    """The typed records of a log, and a warning (file and line) for each line left out."""

    records: list[AnyRecord]
    warnings: list[str] = field(default_factory=list)
    # The warnings of lines left out that are not a torn tail: JSON that is no record,
    # or a damaged line in the middle.
    damaged: list[str] = field(default_factory=list)


def read_json_lines(path: Path, repair: bool = False) -> JsonLines:
    """Every whole JSON object of a log. With `repair`, a torn tail is moved aside and cut.

    A torn tail is the last line when it lacks its newline or is not JSON: the
    only damage a crash between write and fsync can do to an append-only file.
    A damaged line in the middle is reported and skipped, and left in place.
    """
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return JsonLines([])
    lines = data.split(b"\n")
    tail = lines.pop()  # after the last newline: b"" when the file ends cleanly
    records: list[dict[str, Any]] = []
    numbers: list[int] = []
    warnings: list[str] = []
    damaged: list[str] = []
    good_end = 0
    position = 0
    for number, line in enumerate(lines, start=1):
        position += len(line) + 1
        try:
            record = msgspec.json.decode(line)
            if not isinstance(record, dict):
                raise msgspec.DecodeError("not a JSON object")
        except UNDECODABLE as error:
            if number == len(lines) and not tail:
                tail = line + b"\n"
                break
            warnings.append(f"{path}: line {number}: skipped, not a JSON record ({error})")
            damaged.append(warnings[-1])
            good_end = position
            continue
        records.append(record)
        numbers.append(number)
        good_end = position
    if tail:
        where = f"moved to {path.name}{TORN_SUFFIX}" if repair else "left in place, not read"
        warnings.append(
            f"{path}: the last line was torn ({len(tail)} bytes, a crash during a write); {where}"
        )
        if repair:
            _move_torn_tail(path, tail, good_end)
    return JsonLines(records, warnings, numbers, damaged)


def read_records(path: Path, repair: bool = False) -> RecordsRead:
    """Every record of a log, typed; torn and damaged lines as read_json_lines says.

    A line that is JSON but no record this code knows (an unknown kind, a field
    missing or of the wrong type) is left out with a warning naming the file and
    the line, never a crash: a reader goes on with the records it can read.
    """
    lines = read_json_lines(path, repair)
    records: list[AnyRecord] = []
    warnings = list(lines.warnings)
    damaged = list(lines.damaged)
    for number, plain in zip(lines.lines, lines.records, strict=True):
        try:
            records.append(decode_record(plain))
        except msgspec.ValidationError as error:
            warnings.append(f"{path}: line {number}: skipped, not a valid record ({error})")
            damaged.append(warnings[-1])
    return RecordsRead(records, warnings, damaged)


def decode_record(plain: dict[str, Any]) -> AnyRecord:
    """One record from its JSON object; msgspec.ValidationError when it is none."""
    record: AnyRecord = msgspec.convert(plain, type=AnyRecord)
    return record


def record_to_plain(record: AnyRecord) -> dict[str, Any]:
    """One record as its JSON object (plain data), "kind" included, absent fields left out."""
    plain: dict[str, Any] = msgspec.to_builtins(record)
    return plain


def encode_record(record: Record) -> bytes:
    """One record (of any kind) as its line of records.jsonl, without the newline."""
    return _encoder.encode(record)


def _move_torn_tail(path: Path, tail: bytes, good_end: int) -> None:
    torn = path.with_name(path.name + TORN_SUFFIX)
    append_durably(torn, tail if tail.endswith(b"\n") else tail + b"\n")
    # Only after the bytes are safe elsewhere is the log cut back to its last whole line.
    truncate(path, good_end)
    fsync_directory(path.parent)


def line_seq(plain: dict[str, Any]) -> int:
    """A line's `seq` (its place in the log), or 0 where it has none that is a number."""
    seq = plain.get("seq", 0)
    return seq if isinstance(seq, int) and not isinstance(seq, bool) else 0

