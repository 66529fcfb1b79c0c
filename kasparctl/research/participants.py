"""participants.csv: who the children are, kept apart from the sessions and joined only here.

A session's plan names its children by pseudonymous codes (`participants =
["P07", "P12", "P03"]`), the same code for a child in every session. What the
study knows about each child (diagnostic group, age, sex...) lives in one CSV
file with a `code` column and whatever other columns the study uses; the
research commands join it at export and report time (`--participants FILE`),
so the robot itself never holds it.

The file is checked whole before anything is written, and each error names
the file, the line, the column, what was expected and what was found.
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from hal.errors import KasparError
from kasparctl.config import CODE_PATTERN

CODE = re.compile(CODE_PATTERN)
COLUMN = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")
MAX_BYTES = 8 << 20
# Columns whose values must be numbers, and their plausible range.
NUMERIC_RANGES = {"age": (0.0, 120.0), "age_months": (0.0, 1440.0)}

Value = str | float | None


class ParticipantsError(KasparError):
    """participants.csv is unusable; the message names file, line, column, expected, found."""


@dataclass(frozen=True)
class Participants:
    """Each participant's attributes by code, and each column's kind ("number" or "category")."""

    path: Path | None = None
    columns: tuple[str, ...] = ()
    kinds: dict[str, str] = field(default_factory=dict)
    rows: dict[str, dict[str, Value]] = field(default_factory=dict)

    def attributes(self, code: str | None) -> dict[str, Value]:
        """A participant's attributes (None for each when the code is unknown or None)."""
        known = self.rows.get(code or "", {})
        return {column: known.get(column) for column in self.columns}

    def categories(self) -> list[str]:
        """The columns of categories (a diagnostic group, sex): what contrasts compare."""
        return [c for c in self.columns if self.kinds.get(c) == "category"]


NO_PARTICIPANTS = Participants()


def load_participants(path: Path) -> Participants:
    """Read and check participants.csv; ParticipantsError names what is wrong and where."""
    name = str(path)
    try:
        with path.open("rb") as stream:
            data = stream.read(MAX_BYTES + 1)
    except OSError as error:
        raise ParticipantsError(f"{name}: cannot read it: {error.strerror or error}") from None
    if len(data) > MAX_BYTES:
        raise ParticipantsError(f"{name}: larger than {MAX_BYTES} bytes, not a participants table")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data[: error.start].count(b"\n") + 1
        raise ParticipantsError(
            f"{name}: line {line}: expected UTF-8 text, found the byte 0x{data[error.start]:02x}"
        ) from None
    rows = list(_rows(name, text))
    if not rows:
        raise ParticipantsError(
            f"{name}: line 1: expected a header with a 'code' column, found nothing"
        )
    header_line, header = rows[0]
    columns = [cell.strip() for cell in header]
    for index, column in enumerate(columns, start=1):
        if not COLUMN.fullmatch(column):
            raise ParticipantsError(
                f"{name}: line {header_line}, column {index}: expected a column name (a letter, "
                f"then letters, digits or '_'), found {column!r}"
            )
    duplicates = sorted({c for c in columns if columns.count(c) > 1})
    if duplicates:
        raise ParticipantsError(
            f"{name}: line {header_line}: expected distinct column names, found "
            f"{', '.join(map(repr, duplicates))} more than once"
        )
    if "code" not in columns:
        raise ParticipantsError(
            f"{name}: line {header_line}: expected a 'code' column (the participants' codes), "
            f"found {', '.join(columns)}"
        )
    attributes = [c for c in columns if c != "code"]
    table: dict[str, dict[str, str]] = {}
    first_line: dict[str, int] = {}
    for line, cells in rows[1:]:
        if len(cells) != len(columns):
            raise ParticipantsError(
                f"{name}: line {line}: expected {len(columns)} fields ({', '.join(columns)}), "
                f"found {len(cells)}"
            )
        values = dict(zip(columns, (cell.strip() for cell in cells), strict=True))
        code = values["code"]
        if not CODE.fullmatch(code):
            raise ParticipantsError(
                f"{name}: line {line}, column code: expected a code (1 to 32 letters, digits, "
                f"'-' or '_', first a letter or digit), found {code!r}"
            )
        if code in table:
            raise ParticipantsError(
                f"{name}: line {line}, column code: expected each code once, found {code!r} "
                f"again (first on line {first_line[code]})"
            )
        table[code] = values
        first_line[code] = line
    kinds = {column: _kind(name, column, table, first_line) for column in attributes}
    return Participants(
        path=path,
        columns=tuple(attributes),
        kinds=kinds,
        rows={
            code: {c: _value(values[c], kinds[c]) for c in attributes}
            for code, values in table.items()
        },
    )


def _rows(name: str, text: str) -> list[tuple[int, list[str]]]:
    """Each non-blank row and the line it starts on."""
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    rows = []
    line = 1
    try:
        for cells in reader:
            if any(cell.strip() for cell in cells):
                rows.append((line, cells))
            line = reader.line_num + 1
    except csv.Error as error:
        raise ParticipantsError(f"{name}: line {reader.line_num}: not CSV ({error})") from None
    return rows


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _kind(name: str, column: str, table: dict[str, dict[str, str]], lines: dict[str, int]) -> str:
    """ "number" when the column's first value is a number (or it is a known numeric column)."""
    filled = [(code, values[column]) for code, values in table.items() if values[column]]
    numeric = column in NUMERIC_RANGES or (bool(filled) and _number(filled[0][1]) is not None)
    if not numeric:
        return "category"
    low, high = NUMERIC_RANGES.get(column, (-math.inf, math.inf))
    for code, text in filled:
        value = _number(text)
        if value is None or not low <= value <= high:
            expected = (
                f"a number from {low:g} to {high:g}" if column in NUMERIC_RANGES else "a number"
            )
            why = "" if column in NUMERIC_RANGES else " (the column's first value is one)"
            raise ParticipantsError(
                f"{name}: line {lines[code]}, column {column}: expected {expected}{why}, "
                f"found {text!r}"
            )
    return "number"


def _value(text: str, kind: str) -> Value:
    if not text:
        return None
    return _number(text) if kind == "number" else text
