"""`kasparctl servos`: being built (owned by the servos work in progress)."""

from __future__ import annotations

from typing import Any


def register(subparsers: Any) -> None:
    del subparsers
