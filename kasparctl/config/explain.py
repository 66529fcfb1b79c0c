"""msgspec's validation errors in the words of kaspar.toml: a key path, expected, found.

msgspec says "Expected `int` >= 1 - at `$.game.children_per_group`"; a person
editing the file needs "game.children_per_group: expected 1 to 6, found 0".
The path is followed through the parsed TOML to the value that failed and
through the schema (kasparctl.config.schema) to the type declared there, whose
msgspec.Meta limits give the words of what was expected.
"""

from __future__ import annotations

import re
import types
import typing
from typing import Annotated, Any, Literal

import msgspec

from kasparctl.config.schema import Config

_PATH_SEGMENT = re.compile(r"\.([A-Za-z_][\w-]*)|\[(\d+|\.\.\.)\]")
# msgspec's words for a value outside a field's msgspec.Meta limits.
_CONSTRAINT = re.compile(
    r"Expected `\w+` (?:(?P<length>of length )|(?P<regex>matching regex )|[<>]=? )"
)


def explain_validation_error(text: str, raw: dict[str, Any]) -> tuple[str, str]:
    """Turn msgspec's "message - at `$.a.b[0]`" into a key path and a readable message."""
    message, _, where = text.rpartition(" - at ")
    if not message:
        message, where = text, ""
    segments = [name or f"[{index}]" for name, index in _PATH_SEGMENT.findall(where.strip("`$"))]
    segments, value = _follow(segments, raw)
    field_type = _type_at(segments)
    unknown = re.fullmatch(r"Object contains unknown field `(.+)`", message)
    if unknown:
        segments.append(unknown.group(1))
        allowed = _field_names(field_type)
        message = (
            f"unknown key; expected one of: {', '.join(allowed)}" if allowed else "unknown key"
        )
    missing = re.fullmatch(r"Object missing required field `(.+)`", message)
    if missing:
        segments.append(missing.group(1))
        message = "required key is missing"
    bad_choice = re.fullmatch(r"Invalid enum value (.+)", message)
    if bad_choice and typing.get_origin(_bare(field_type)) is Literal:
        choices = ", ".join(repr(choice) for choice in typing.get_args(_bare(field_type)))
        message = f"expected one of {choices}, found {bad_choice.group(1)}"
    got = re.fullmatch(r"Expected `(.+)`, got `(.+)`", message)
    if got:
        # TOML has no null: a key that may be left out is not "bool | null" to its reader.
        message = f"expected {got.group(1).removesuffix(' | null')}, found {got.group(2)}"
    constraint = _CONSTRAINT.match(message)
    if constraint:
        message = _explain_constraint(constraint, field_type, value)
    key = "".join(s if s.startswith("[") else f".{s}" for s in segments).lstrip(".")
    return key or "(top level)", message


def _follow(segments: list[str], raw: Any) -> tuple[list[str], Any]:
    """The failing value, found by following the path through the parsed TOML.

    msgspec writes a table of tables' key as [...]; the entry that fails is named.
    The value is None where the path leads nowhere (TOML itself has no null).
    """
    named: list[str] = []
    for segment in segments:
        if segment == "[...]" and isinstance(raw, dict):
            entry_type = _type_at([*named, "[...]"])
            segment = next(
                (key for key, value in raw.items() if not _converts(value, entry_type)), "[...]"
            )
        named.append(segment)
        if isinstance(raw, dict):
            raw = raw.get(segment)
        elif isinstance(raw, list) and segment.strip("[]").isdigit():
            index = int(segment.strip("[]"))
            raw = raw[index] if index < len(raw) else None
        else:
            raw = None
    return named, raw


def _converts(value: Any, target_type: Any) -> bool:
    try:
        msgspec.convert(value, type=target_type)
    except msgspec.ValidationError:
        return False
    return True


def _type_at(segments: list[str]) -> Any:
    """The declared type at a key path, with its Annotated limits kept."""
    current: Any = Config
    for segment in segments:
        bare = _bare(current)
        if isinstance(bare, type) and issubclass(bare, msgspec.Struct):
            # A field may have another name in the file than in Python (exclude_learned).
            names = {f.encode_name: f.name for f in msgspec.structs.fields(bare)}
            hints = typing.get_type_hints(bare, include_extras=True)
            current = hints.get(names.get(segment, segment))
        elif typing.get_origin(bare) in (tuple, list, dict):
            current = typing.get_args(bare)[-1 if typing.get_origin(bare) is dict else 0]
        if typing.get_origin(current) in (typing.Union, types.UnionType):
            current = next(a for a in typing.get_args(current) if a is not type(None))
    return current


def _bare(annotated: Any) -> Any:
    """A type without its Annotated limits."""
    while typing.get_origin(annotated) is Annotated:
        annotated = typing.get_args(annotated)[0]
    return annotated


def _field_names(struct_type: Any) -> list[str]:
    struct_type = _bare(struct_type)
    if isinstance(struct_type, type) and issubclass(struct_type, msgspec.Struct):
        return [f.encode_name for f in msgspec.structs.fields(struct_type)]
    return []


def _explain_constraint(constraint: re.Match[str], field_type: Any, value: Any) -> str:
    """Word a failed msgspec.Meta limit as "expected 1 to 6, found 9", from the field's limits."""
    limits = _Limits.of(field_type)
    if constraint["length"]:
        expected = limits.expected or limits.length()
        found = None if value is None else str(len(value))
    else:
        expected = limits.expected or limits.value(pattern=bool(constraint["regex"]))
        found = _describe(value, _bare(field_type))
    return f"expected {expected}" if found is None else f"expected {expected}, found {found}"


class _Limits(msgspec.Struct, frozen=True, kw_only=True):
    """The msgspec.Meta limits of one field, merged, with the words to say them."""

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    min_length: int | None = None
    max_length: int | None = None
    pattern: str | None = None
    expected: str | None = None
    unit: str = ""
    item: str = "item"

    @classmethod
    def of(cls, field_type: Any) -> _Limits:
        """The limits in a type's Annotated metadata; Annotated may be nested."""
        limits: dict[str, Any] = {"item": "character"} if _bare(field_type) is str else {}
        while typing.get_origin(field_type) is Annotated:
            field_type, *metadata = typing.get_args(field_type)
            for meta in metadata:
                if isinstance(meta, msgspec.Meta):
                    limits.update(
                        (name, getattr(meta, name))
                        for name in cls.__struct_fields__
                        if getattr(meta, name, None) is not None
                    )
                    limits.update(meta.extra or {})
        return cls(**{name: limits[name] for name in cls.__struct_fields__ if name in limits})

    def value(self, pattern: bool) -> str:
        """A number's range ("0 to 10 s", ">= 1"), or a text's pattern."""
        if pattern:
            return f"text matching {self.pattern!r}"
        if self.ge is not None and self.le is not None:
            bounds = f"{_number(self.ge)} to {_number(self.le)}"
        else:
            signs = {">=": self.ge, ">": self.gt, "<=": self.le, "<": self.lt}
            bounds = " and ".join(
                f"{sign} {_number(bound)}" for sign, bound in signs.items() if bound is not None
            )
        return f"{bounds} {self.unit}".rstrip()

    def length(self) -> str:
        """A sequence's size: "at least 2 names", "1 to 3 delays", "at most 1 item"."""
        low, high = self.min_length, self.max_length
        if high is None:
            count, last = f"at least {low}", low
        elif low is None:
            count, last = f"at most {high}", high
        else:
            count, last = (f"{low} to {high}" if low < high else f"exactly {high}"), high
        return f"{count} {self.item}{'' if last == 1 else 's'}"


def _number(value: float) -> str:
    """A limit as a person writes it: 10.0 is "10", 0.5 stays "0.5"."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return str(value)


def _describe(value: Any, field_type: Any) -> str | None:
    """A found value as the messages show it: a number as is, text quoted, blank named."""
    if value is None:
        return None
    if isinstance(value, str):
        return repr(value) if value.strip() else "an empty string"
    if field_type is float and isinstance(value, int) and not isinstance(value, bool):
        return str(float(value))  # TOML's 5 read into a float field is 5.0
    return str(value)
