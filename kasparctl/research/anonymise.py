"""First names out of exported text: "child N" instead, N the child's place in the plan.

Children's first names are the only personal data a session holds (the plan
may list them so Kaspar can say "Amira, your turn"); the group code is a
pseudonym already. Names are replaced wherever they appear as a whole word,
also inside spoken lines and hardware messages, not only in the child column.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any


class Pseudonyms:
    """Replaces each first name by its pseudonym, as a whole word."""

    def __init__(self, names: Mapping[str, str]) -> None:
        """`names`: each first name and its pseudonym."""
        self._names = dict(names)
        # Longest first, so "Anna-Lena" is replaced before "Anna".
        ordered = sorted(self._names, key=len, reverse=True)
        self._pattern = (
            re.compile(r"(?<!\w)(" + "|".join(re.escape(n) for n in ordered) + r")(?!\w)")
            if ordered
            else None
        )

    def text(self, value: str) -> str:
        """`value` with every name replaced."""
        if self._pattern is None:
            return value
        return self._pattern.sub(lambda match: self._names[match.group(1)], value)

    def value(self, value: Any) -> Any:
        """`value` with every name replaced, recursively through lists and dicts."""
        if isinstance(value, str):
            return self.text(value)
        if isinstance(value, list | tuple):
            return [self.value(item) for item in value]
        if isinstance(value, dict):
            return {self.text(str(key)): self.value(item) for key, item in value.items()}
        return value


NO_PSEUDONYMS = Pseudonyms({})
