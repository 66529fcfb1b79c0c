"""The project's one progress bar, on a terminal, for long exports, reports and simulations.

tqdm is optional (the `progress` extra): without it, or when stderr is not a
terminal (a pipe, a log, a test), or when the items are few, the items pass
through untouched.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator, Sized
from typing import TextIO, TypeVar

T = TypeVar("T")

# Below this many items a bar only flickers.
MINIMUM_ITEMS = 20


def progress(
    items: Iterable[T],
    what: str,
    unit: str = "item",
    stream: TextIO | None = None,
    *,
    total: int | None = None,
    minimum: int = MINIMUM_ITEMS,
) -> Iterator[T]:
    """The items, with a bar on `stream` (stderr) when it is a terminal and they are many.

    `total` is how many there are when `items` cannot say (a generator); below
    `minimum` items there is no bar.
    """
    stream = stream or sys.stderr
    if total is None and isinstance(items, Sized):
        total = len(items)
    if not stream.isatty() or (total is not None and total < minimum):
        return iter(items)
    try:
        from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type hints
    except ImportError:
        return iter(items)
    return iter(tqdm(items, desc=what, total=total, unit=unit, file=stream, leave=False))
