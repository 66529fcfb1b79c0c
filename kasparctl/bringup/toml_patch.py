"""Surgical edits of TOML text: change exactly the keys asked, keep everything else as written.

The standard library reads TOML but does not write it, and a rewrite would lose
the comments that explain a robot's configuration. These functions change the
value text of single-line `key = value` entries in place (keeping indentation
and a trailing comment), insert a missing key after the last key of its table,
and remove keys; every other line is untouched. Only what bring-up edits is
supported: `[[servos.joints]]` entries found by their `name`, and top-level
`[pose]` tables of a poses file. Anything else raises TomlPatchError naming it.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass

from hal.errors import KasparError

TomlValue = float | int | tuple[float, float]

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\[\]]+?)\s*(\]\]?)\s*(#.*)?$")
# A `#` inside a quoted value would be taken for a comment: only numbers and arrays of
# numbers are rewritten, and a name is read back with tomllib.
_KEY = re.compile(
    r"^(?P<indent>\s*)(?P<key>[A-Za-z0-9_-]+)\s*=\s*(?P<value>.*?)(?P<comment>\s*#.*)?$"
)
BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


class TomlPatchError(KasparError):
    """An edit that cannot be made surgically; the message names the table and key."""


@dataclass(frozen=True, slots=True)
class _Table:
    header: str  # "servos.joints" or "happy"
    array: bool  # [[...]] rather than [...]
    start: int  # index of the header line
    end: int  # index after the table's last line


def format_value(value: TomlValue) -> str:
    """A value as kasparctl writes it: floats with one decimal, ints bare, pairs as arrays."""
    if isinstance(value, tuple):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    if isinstance(value, bool):
        raise TomlPatchError("booleans are not written by bring-up")
    if isinstance(value, int):
        return str(value)
    if not math.isfinite(value):
        raise TomlPatchError(f"{value} cannot be written to TOML")
    text = f"{value:.1f}"
    return "0.0" if text == "-0.0" else text


def _tables(lines: list[str]) -> list[_Table]:
    starts = []
    for index, line in enumerate(lines):
        match = _HEADER.match(line)
        if match and not line.lstrip().startswith("#"):
            starts.append((index, match.group(2).strip(), match.group(1) == "[["))
    tables = []
    for position, (index, header, array) in enumerate(starts):
        end = starts[position + 1][0] if position + 1 < len(starts) else len(lines)
        tables.append(_Table(header, array, index, end))
    return tables


def _keys(lines: list[str], table: _Table) -> dict[str, int]:
    """Key -> line index within the table; a value that continues on the next line is refused."""
    found = {}
    for index in range(table.start + 1, table.end):
        match = _KEY.match(lines[index])
        if not match or lines[index].lstrip().startswith("#"):
            continue
        value = match.group("value")
        if value.count("[") != value.count("]") or value.count("{") != value.count("}"):
            raise TomlPatchError(
                f"[{table.header}] key {match.group('key')!r} spans several lines: "
                "edit it by hand, or write it on one line"
            )
        found[match.group("key")] = index
    return found


def _name_of(lines: list[str], table: _Table) -> str | None:
    index = _keys(lines, table).get("name")
    if index is None:
        return None
    try:
        parsed = tomllib.loads(lines[index].strip())
    except tomllib.TOMLDecodeError:
        return None
    name = parsed.get("name")
    return name if isinstance(name, str) else None


def _set_keys(
    lines: list[str], table: _Table, values: Mapping[str, TomlValue | None]
) -> list[str]:
    """The table's lines with `values` set (None removes the key); other lines unchanged."""
    keys = _keys(lines, table)
    out = list(lines)
    removed: set[int] = set()
    missing = []
    for key, value in values.items():
        index = keys.get(key)
        if value is None:
            if index is not None:
                removed.add(index)
            continue
        if index is None:
            missing.append(f"{key} = {format_value(value)}")
            continue
        match = _KEY.match(lines[index])
        assert match is not None
        out[index] = (
            f"{match.group('indent')}{key} = {format_value(value)}{match.group('comment') or ''}"
        )
    if missing:
        # After the table's last key line, so blank lines and comments that lead the next
        # table stay where they are.
        last_key = max((i for i in keys.values() if i not in removed), default=table.start)
        indent = ""
        if keys:
            first = _KEY.match(lines[min(keys.values())])
            indent = first.group("indent") if first else ""
        out[last_key + 1 : last_key + 1] = [indent + line for line in missing]
        removed = {i if i <= last_key else i + len(missing) for i in removed}
    return [line for i, line in enumerate(out) if i not in removed]


def _check(text: str, where: str) -> dict[str, object]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise TomlPatchError(f"{where}: the edited text is not valid TOML: {error}") from error


def set_joint_keys(text: str, joint: str, values: Mapping[str, TomlValue | None]) -> str:
    """Set keys of the `[[servos.joints]]` entry whose name is `joint`; the rest as written.

    TomlPatchError if there is no such entry (or more than one), or a key to change
    is written over several lines.
    """
    _check(text, "before editing")
    lines = text.splitlines(keepends=False)
    matches = [
        t for t in _tables(lines)
        if t.array and t.header == "servos.joints" and _name_of(lines, t) == joint
    ]
    if len(matches) != 1:
        found = "no" if not matches else f"{len(matches)}"
        raise TomlPatchError(f"{found} [[servos.joints]] table with name = {joint!r}")
    table = matches[0]
    edited = _set_keys(lines, table, values)
    result = "\n".join(edited) + ("\n" if text.endswith("\n") else "")
    _verify_joint(result, joint, values)
    return result


def _verify_joint(text: str, joint: str, values: Mapping[str, TomlValue | None]) -> None:
    parsed = _check(text, f"joint {joint!r}")
    servos = parsed.get("servos")
    entries = servos.get("joints", []) if isinstance(servos, dict) else []
    (entry,) = [e for e in entries if isinstance(e, dict) and e.get("name") == joint]
    for key, value in values.items():
        written = entry.get(key)
        expected = list(value) if isinstance(value, tuple) else value
        if value is not None and written != _rounded(expected):
            raise TomlPatchError(f"joint {joint!r}: {key} reads back as {written!r}")


def _rounded(value: object) -> object:
    if isinstance(value, float):
        return float(format_value(value))
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def set_table(text: str, name: str, values: Mapping[str, float]) -> str:
    """Make top-level table `[name]` hold exactly `values` (keys kept in place, comments kept).

    Appends the table at the end when it is missing. TomlPatchError for a name or
    key that is not a bare TOML key.
    """
    for key in (name, *values):
        if not BARE_KEY.match(key):
            raise TomlPatchError(f"{key!r} is not a plain name (letters, digits, _ and -)")
    _check(text, "before editing")
    lines = text.splitlines(keepends=False)
    matches = [t for t in _tables(lines) if not t.array and t.header == name]
    if not matches:
        body = [f"{key} = {format_value(value)}" for key, value in values.items()]
        prefix = lines + ([""] if lines and lines[-1].strip() else [])
        result = "\n".join([*prefix, f"[{name}]", *body]) + "\n"
    else:
        table = matches[0]
        old = set(_keys(lines, table))
        changes: dict[str, TomlValue | None] = {key: None for key in old - set(values)}
        changes.update(values)
        edited = _set_keys(lines, table, changes)
        result = "\n".join(edited) + ("\n" if text.endswith("\n") or not text else "")
    parsed = _check(result, f"[{name}]")
    table_values = parsed.get(name)
    if not isinstance(table_values, dict) or set(table_values) != set(values):
        raise TomlPatchError(f"[{name}] does not read back with exactly its keys")
    return result


TextValue = str | int


def _text_value(value: TextValue) -> str:
    if isinstance(value, bool):
        raise TomlPatchError("booleans are not written by bring-up")
    if isinstance(value, int):
        return str(value)
    if "#" in value or any(ord(c) < 0x20 for c in value):
        # The line patcher would take a `#` for a comment when it edits the line again.
        raise TomlPatchError(f"{value!r}: a '#' or a control character is not written")
    return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'


def set_text_keys(
    text: str, name: str, values: Mapping[str, TextValue | None], *, exact: bool = False
) -> str:
    """Set string or integer keys of table `[name]` (dotted names too: "researcher.keys");
    None removes a key; `exact` removes the keys not in `values` as well. The table is
    appended at the end when it is missing; everything else stays as written.

    TomlPatchError for a key that is not a bare TOML key, a value written over several
    lines, or a result that does not read back.
    """
    parts = name.split(".")
    for key in (*parts, *values):
        if not BARE_KEY.match(key):
            raise TomlPatchError(f"{key!r} is not a plain name (letters, digits, _ and -)")
    _check(text, "before editing")
    lines = text.splitlines(keepends=False)
    matches = [t for t in _tables(lines) if not t.array and t.header == name]
    given = {key: value for key, value in values.items() if value is not None}
    if not matches:
        body = [f"{key} = {_text_value(value)}" for key, value in given.items()]
        prefix = lines + ([""] if lines and lines[-1].strip() else [])
        result = "\n".join([*prefix, f"[{name}]", *body]) + "\n"
    else:
        table = matches[0]
        present = _keys(lines, table)
        changes: dict[str, str | None] = {}
        if exact:
            changes.update({key: None for key in set(present) - set(values)})
        changes.update({k: None if v is None else _text_value(v) for k, v in values.items()})
        result = "\n".join(_set_raw(lines, table, changes)) + "\n"
    parsed: object = _check(result, f"[{name}]")
    for part in parts:
        parsed = parsed.get(part) if isinstance(parsed, dict) else None
    if not isinstance(parsed, dict):
        raise TomlPatchError(f"[{name}] does not read back as a table")
    for key, value in values.items():
        if parsed.get(key) != value:
            raise TomlPatchError(f"[{name}] {key} reads back as {parsed.get(key)!r}")
    if exact and set(parsed) != set(given):
        raise TomlPatchError(f"[{name}] does not read back with exactly its keys")
    return result


def _set_raw(lines: list[str], table: _Table, values: Mapping[str, str | None]) -> list[str]:
    """As _set_keys, for values already written as TOML text."""
    keys = _keys(lines, table)
    out = list(lines)
    removed = {keys[key] for key, value in values.items() if value is None and key in keys}
    missing = []
    for key, value in values.items():
        if value is None:
            continue
        index = keys.get(key)
        if index is None:
            missing.append(f"{key} = {value}")
            continue
        match = _KEY.match(lines[index])
        assert match is not None
        out[index] = f"{match.group('indent')}{key} = {value}{match.group('comment') or ''}"
    if missing:
        last_key = max((i for i in keys.values() if i not in removed), default=table.start)
        out[last_key + 1 : last_key + 1] = missing
        removed = {i if i <= last_key else i + len(missing) for i in removed}
    return [line for i, line in enumerate(out) if i not in removed]
